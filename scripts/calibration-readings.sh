#!/usr/bin/env bash
# R under each reading of the experiment's film, measured again on a stored calibration grid
# (no new run): the particle quantiles with the width as a cylindrical radius and as seen
# side-on (the default reading, `analysis.width`), and the synthetic shadowgraph's silhouette at several optical
# depths. For each reading: R at every grid point, its slope per decade of eps at each kappa,
# and the eps where R meets the experiment's 1.55 (interpolated in log eps).
#
#   scripts/calibration-readings.sh STORE [REPORT]   # REPORT default: reports/calibration-resolution
#
# STORE is a study directory of studies/calibration.toml whose runs kept their state
# (analysis.keep_state, the default), e.g. the --out of `hvi-study sweep` or `calibrate`.
# Writes REPORT/readings-<tier>.csv and prints the Markdown tables.
# Environment: HVI_STUDY (binary, default target/release/hvi-study), HVI_DEPTHS (the optical
# depths, default "1 3 10").
set -euo pipefail
cd "$(dirname "$0")/.."
store=${1:?usage: scripts/calibration-readings.sh STORE [REPORT]}
report=${2:-reports/calibration-resolution}
bin=${HVI_STUDY:-target/release/hvi-study}
depths=${HVI_DEPTHS:-1 3 10}
[ -x "$bin" ] || cargo build --release -p hvi-study
mkdir -p "$report"
tier=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["tier"])' "$store/plan.json")
tables=()
"$bin" reanalyse "$store" --table readings-quantile --quiet
tables+=("quantile")
for d in $depths; do
    "$bin" reanalyse "$store" --table "readings-tau$d" --set "analysis.shadowgraph_optical_depth=$d" --quiet
    tables+=("tau$d")
done
python3 - "$store" "$report/readings-$tier.csv" "${tables[@]}" <<'EOF'
import csv, math, sys
store, out, names = sys.argv[1], sys.argv[2], sys.argv[3:]
TARGET = 1.55  # experiments_data/calibration-shot.toml, length_ratio
rows = {}
readings = []
for n in names:
    with open(f"{store}/readings-{n}.csv") as f:
        for r in csv.DictReader(f):
            key = (float(r["material.eps_j"]), float(r["material.kappa_n_m"]), r.get("run.seed", ""))
            cols = {}
            if n == "quantile":
                cols["cylindrical"] = r["length_ratio_cylindrical"]
                cols["side"] = r["length_ratio_side"]
            else:
                cols[f"silhouette {n}"] = r["length_ratio_silhouette"]
            for k, v in cols.items():
                rows.setdefault(key, {})[k] = float(v) if v not in ("", None) else math.nan
                if k not in readings:
                    readings.append(k)
keys = sorted(rows)
with open(out, "w", newline="") as f:
    w = csv.writer(f)
    w.writerow(["eps_j", "kappa_n_m", "seed"] + [f"R {r}" for r in readings])
    for k in keys:
        w.writerow([k[0], k[1], k[2]] + [rows[k].get(r, math.nan) for r in readings])
print(f"R at each grid point ({store}):\n")
print("| eps (J) | kappa (N/m) | " + " | ".join(f"R, {r}" for r in readings) + " |")
print("|---|---|" + "---|" * len(readings))
for k in keys:
    print(f"| {k[0]:g} | {k[1]:.3g} | " + " | ".join(f"{rows[k].get(r, math.nan):.3f}" for r in readings) + " |")
# Slope of R per decade of eps and the eps that meets the target, per kappa and reading.
print(f"\nPer kappa: R's slope per decade of eps (least squares over the grid's eps), and the eps where R meets {TARGET} (interpolated in log10 eps between the grid points that bracket it; '<' or '>' when R stays on one side):\n")
print("| kappa (N/m) | reading | slope of R per decade | eps at R = 1.55 (J) |")
print("|---|---|---|---|")
kappas = sorted({k[1] for k in keys})
for kap in kappas:
    for r in readings:
        pts = sorted((math.log10(k[0]), rows[k][r]) for k in keys if k[1] == kap and not math.isnan(rows[k].get(r, math.nan)))
        if len(pts) < 2:
            continue
        n = len(pts)
        mx = sum(p[0] for p in pts) / n
        my = sum(p[1] for p in pts) / n
        sxx = sum((p[0] - mx) ** 2 for p in pts)
        slope = sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx if sxx > 0 else math.nan
        hit = None
        for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
            if (y0 - TARGET) * (y1 - TARGET) <= 0 and y1 != y0:
                hit = 10 ** (x0 + (TARGET - y0) * (x1 - x0) / (y1 - y0))
                break
        if hit is None:
            side = ">" if all(p[1] < TARGET for p in pts) and slope > 0 else "<" if all(p[1] > TARGET for p in pts) and slope > 0 else "none in"
            lo, hi = 10 ** pts[0][0], 10 ** pts[-1][0]
            txt = f"{side} [{lo:g}, {hi:g}]"
        else:
            txt = f"{hit:.3g}"
        print(f"| {kap:.3g} | {r} | {slope:+.3f} | {txt} |")
EOF
