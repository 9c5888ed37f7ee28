#!/usr/bin/env bash
# Runs to converge: the calibration's surrogate search (ego) against Nelder-Mead on the same
# targets and grid (studies/calibration.toml), at one tier. Writes a Markdown table.
#
#   scripts/calibration-methods.sh [TIER] [OUT]     # default: quick, reports/calibration-methods
#
# The variants share one study store, so the grid runs once; "runs" below counts every run a
# method needed (the grid's 12 included), whether it came from the store or not. The methods:
#   nelder-mead      calibrate.method = nelder-mead (one seed, max_iters of the study)
#   ego, 1 seed      the surrogate search at seed 1 (noise = calibrate.noise_floor)
#   ego, 2 seeds     the surrogate search at seeds 1 and 2 (the study's setting)
# Environment: HVI_STUDY (binary, default target/release/hvi-study), HVI_THREADS (default 2).
set -euo pipefail
cd "$(dirname "$0")/.."
tier=${1:-quick}
report=${2:-reports/calibration-methods}
bin=${HVI_STUDY:-target/release/hvi-study}
threads=${HVI_THREADS:-2}
store=${HVI_STORE:-runs/calibration-methods/$tier}
[ -x "$bin" ] || cargo build --release -p hvi-study
mkdir -p "$report" "$store"
rows=()
for variant in "nelder-mead" "ego-1" "ego-1,2"; do
    case "$variant" in
        nelder-mead) args=(--method nelder-mead) ;;
        ego-*) args=(--method ego --seeds "${variant#ego-}") ;;
    esac
    echo "calibration-methods: $variant at tier $tier" >&2
    start=$(date +%s)
    "$bin" calibrate studies/calibration.toml --tier "$tier" --out "$store" \
        --threads "$threads" --quiet "${args[@]}" >/dev/null
    end=$(date +%s)
    cp "$store/calibration.json" "$report/$tier-$variant.json"
    rows+=("$(python3 - "$report/$tier-$variant.json" "$variant" "$((end - start))" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
variant, wall = sys.argv[2], sys.argv[3]
grid = 12
runs = grid
for e in c["refinement"]:
    if e.get("dir") is None:
        continue
    seeds = e.get("seeds") or [1]
    n = len(seeds)
    if e["stage"] == "grid-seeds" and 1 in seeds:
        n -= 1  # the seed-1 run is the grid's
    runs += n
dirs = {e["dir"] for e in c["refinement"] if e.get("dir") and e["stage"] == "refine"}
if c["method"] == "nelder-mead":
    runs = grid + len(dirs)
best = c["best"]
p = best["params"]
region = c.get("region") or {}
iv = region.get("intervals", {})
def interval(k):
    if k not in iv:
        return "n/a"
    lo, hi = iv[k]
    return f"[{lo:.3g}, {hi:.3g}]"
print(f"| {variant} | {runs} | {'yes' if c['converged'] else 'no'} | "
      f"{p.get('material.eps_j', float('nan')):.3g} | {p.get('material.kappa_n_m', float('nan')):.3g} | "
      f"{best['objective']:.4g} ({'mean of ' + str(len(best['seeds'])) + ' seeds' if len(best.get('seeds') or []) > 1 else 'one seed'}) | "
      f"{interval('material.eps_j')} | {interval('material.kappa_n_m')} | {wall} s | {c['termination']} |")
PY
)")
done
{
    echo "# Calibration methods at tier \`$tier\`"
    echo
    echo "Written by \`scripts/calibration-methods.sh $tier\` ($(date -u +%Y-%m-%d), $("$bin" --version), $(nproc) cores, $threads threads). The calibration study's 12-point grid and targets; runs counted whether simulated now or taken from the shared store (the grid's 12 included); wall time is this invocation's and depends on what the store already held. J is the objective of the chosen point as its method scores it: one seed for Nelder-Mead and ego at one seed, the seed-mean observables for ego at two seeds."
    echo
    echo "| method | runs | converged | eps (J) | kappa (N/m) | J at the chosen point | eps interval | kappa interval | wall | why it stopped |"
    echo "|---|---|---|---|---|---|---|---|---|---|"
    printf '%s\n' "${rows[@]}"
} >"$report/$tier.md"
echo "$report/$tier.md"
