#!/usr/bin/env python3
"""Free flight from 4, 6, 8 us against the full run, per point and resolution.

    python3 early.py RUNS_DIR [REFERENCE_CSV]

RUNS_DIR holds n<particles>/<run>/summary.json, one `hvi-study run` each (see README.md,
"The free-flight bias at the screen's time"); the full runs at 2.7e5 come from
REFERENCE_CSV (default: ../time-to-answer/runs.csv). Writes RUNS_DIR/runs.csv (every run)
and prints each free-flight run's differences from its point's full run, in per cent."""
import csv, glob, json, os, sys
here = os.path.abspath(sys.argv[1])
repo_here = os.path.dirname(os.path.abspath(__file__))
rows = []
for f in sorted(glob.glob(os.path.join(here, "n*/*/summary.json"))):
    s = json.load(open(f))
    sc = s["scene"]
    c = s.get("cloud") or {}
    ff = sc["run"].get("free_flight_after_s")
    rows.append(dict(
        particles=s["particles"], eps_j=sc["material"]["eps_j"], kappa_n_m=sc["material"]["kappa_n_m"],
        seed=sc["run"]["seed"], free_flight_after_s=ff if ff is not None else "",
        steps=s["steps"], wall_seconds_1_thread=round(s["wall_seconds"], 1),
        length_ratio=c.get("length_ratio"), front_velocity_ratio=c.get("front_velocity_ratio"),
        fragmentation=c.get("fragmentation"),
        largest_fragment_mass_fraction=c.get("largest_fragment_mass_fraction"),
        mean_fragment_diameter_m=c.get("mean_fragment_diameter_m")))
# Full runs at 2.7e5 from reports/time-to-answer (the same engine, bit-identical).
ref = os.path.join(repo_here, "../time-to-answer/runs.csv")
if len(sys.argv) > 2:
    ref = sys.argv[2]
full = {}
for r in csv.DictReader(open(ref)):
    if r["symmetry"] == "full" and r["seed"] == "1" and r["free_flight_after_s"] in ("", "8e-6"):
        key = (int(r["particles"]), float(r["eps_j"]), float(r["kappa_n_m"]), r["free_flight_after_s"] and 8e-6 or None)
        full[key] = r
out = os.path.join(here, "runs.csv")
with open(out, "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
    w.writeheader()
    w.writerows(rows)
for r in rows:
    key = (r["particles"], r["eps_j"], r["kappa_n_m"], r["free_flight_after_s"] or None)
    full.setdefault(key, {k: str(v) for k, v in r.items()})
obs = ["length_ratio", "front_velocity_ratio", "fragmentation", "largest_fragment_mass_fraction", "mean_fragment_diameter_m"]
print("particles eps kappa ff_us steps(full) dR% dva% dF% dlargest% dmean%")
for key in sorted(full, key=lambda k: (k[0], k[1], k[2], k[3] or 1)):
    n, e, k, ff = key
    if ff is None:
        continue
    base = full.get((n, e, k, None))
    if base is None:
        continue
    r = full[key]
    d = [100 * (float(r[o]) / float(base[o]) - 1) for o in obs]
    print(f"{n} {e} {k:.3g} {ff*1e6:.0f} {r['steps']}({base['steps']}) " + " ".join(f"{x:+.2f}" for x in d))
