#!/usr/bin/env bash
# The calibration at the paper's resolution (tier `paper` of studies/calibration.toml, 2.7e5
# particles) under the project's default reading, to convergence, and its report.
#
#   scripts/calibration-paper.sh [REPORT]        # default: reports/calibration-paper
#
# Runs `hvi-study calibrate studies/calibration.toml --tier paper` (the study's search
# settings: surrogate search, batches of 2 points at seeds 1 and 2, at most 8 batches) into a
# store, then copies what it wrote (calibration.md/json, evaluations.csv, results, the three
# maps with the confidence region) into REPORT with a README stating the conditions. Hours on
# two cores: stopped at any point, the same command resumes, every finished run reused.
# Extra arguments after REPORT go to calibrate (e.g. --slurm --time 2:00:00).
# Environment: HVI_STUDY (binary, default target/release/hvi-study), HVI_STORE (the store,
# default runs/calibration-paper; one holding the paper tier's grid, e.g. reproduce's, is
# reused: link its runs/ in).
set -euo pipefail
cd "$(dirname "$0")/.."
report=${1:-reports/calibration-paper}
shift || true
bin=${HVI_STUDY:-target/release/hvi-study}
store=${HVI_STORE:-runs/calibration-paper}
[ -x "$bin" ] || cargo build --release -p hvi-study
mkdir -p "$report" "$store"
start=$(date +%s)
"$bin" calibrate studies/calibration.toml --tier paper --out "$store" "$@"
end=$(date +%s)
for f in calibration.json calibration.md evaluations.csv results.csv results.json \
    map_R.png map_R.svg map_va.png map_va.svg map_objective.png map_objective.svg snapshots.png; do
    [ -f "$store/$f" ] && cp "$store/$f" "$report/$f"
done
python3 - "$report" "$((end - start))" "$("$bin" --version)" "$(nproc)" <<'PY'
import json, os, sys
report, wall, version, cores = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
c = json.load(open(os.path.join(report, "calibration.json")))
best, paper = c["best"], c["paper"]
region = (c.get("region") or {}).get("intervals", {})
rows = json.load(open(os.path.join(report, "results.json")))
def span(k):
    vals = sorted({r[k] for r in rows if isinstance(r.get(k), (int, float))})
    return f"{k.split('.')[-1]} {', '.join(f'{v:.3g}' for v in vals)}"
grid = "; ".join(span(k) for k in best["params"])
edge = (c.get("region") or {}).get("at_boundary", {})
lines = [
    "# The calibration at the paper's resolution",
    "",
    f"Written by `scripts/calibration-paper.sh` with {version} on {cores} cores; "
    f"`hvi-study calibrate studies/calibration.toml --tier paper`: {c.get('particles') or 'n/a'} "
    f"particles per run, the study's {len(rows)}-point grid ({grid}), the default reading (R and va from the 0.9 quantile, "
    "Lr read side-on as the film records it: docs/model-decisions.md), the calibration shot's targets "
    "(experiments_data/calibration-shot.toml). This invocation's wall time: "
    f"{wall} s (runs already in the store are not counted).",
    "",
    f"**{'CONVERGED' if c['converged'] else 'NOT CONVERGED'}**: {c['termination']}",
    "",
    f"Runs: {c['runs_made']} simulated by the last invocation; every evaluation in "
    "`evaluations.csv`, the full account in `calibration.md`.",
    "",
    "Boxes searched (a side the answer touches moves out a decade, up to `calibrate.max_extensions`):",
    "",
    *[f"- box {k}: {', '.join(f'{key} in [{lo:.3g}, {hi:.3g}]' for key, (lo, hi) in b['bounds'].items())}: {b['termination']}"
      for k, b in enumerate(c.get("boxes") or [])],
    "",
    "| parameter | calibrated | interval | at the box's edge | the paper's fit | calibrated / paper |",
    "|---|---|---|---|---|---|",
]
for k, v in best["params"].items():
    iv = region.get(k)
    ivs = f"[{iv[0]:.3g}, {iv[1]:.3g}]" if iv else "n/a"
    e = edge.get(k)
    es = "n/a" if e is None else ("yes" if e else "no")
    p = c["ratio_to_paper"].get(k)
    lines.append(f"| `{k}` | {v:.4g} | {ivs} | {es} | {paper['params'].get(k, float('nan')):.4g} | "
                 f"{'n/a' if p is None else f'{p:.3g}'} |")
lines += [
    "",
    f"Objective J: {best['objective']:.4g} at the calibrated point (seed means), "
    f"{c['best_grid']['objective']:.4g} at the best grid point, {paper['objective']:.4g} at the "
    "paper's fit (eps = 0.01 J, kappa = 4.56e6 N/m) at the same resolution.",
    "",
    "Maps: `map_objective.png` (J over the searched box, the search's points and the confidence region), "
    "`map_R.png`, `map_va.png`.",
]
open(os.path.join(report, "README.md"), "w").write("\n".join(lines) + "\n")
print(os.path.join(report, "README.md"))
PY
