#!/usr/bin/env python3
"""Every run of a calibration's store: point, seed, steps, wall, what the screen measured.

    python3 reports/screen/runs.py STUDY_DIR > runs.csv
"""
import csv
import json
import pathlib
import sys

out = csv.writer(sys.stdout)
out.writerow(["eps_j", "kappa_n_m", "seed", "screened", "screen_length_ratio", "steps",
              "wall_seconds", "length_ratio", "front_velocity_ratio", "fragmentation",
              "largest_fragment_mass_fraction", "mean_fragment_diameter_m", "dir"])
rows = []
for d in sorted(pathlib.Path(sys.argv[1], "runs").iterdir()):
    f = d / "summary.json"
    if not f.is_file():
        continue
    s = json.loads(f.read_text())
    m = s["scene"]["material"]
    c = s.get("cloud") or {}
    screen = s.get("screen") or {}
    rows.append([m["eps_j"], m["kappa_n_m"], s["scene"]["run"]["seed"],
                 {True: 1, False: 0}.get(screen.get("free_flight"), ""),
                 screen.get("length_ratio", ""), s["steps"], round(s["wall_seconds"], 1),
                 c.get("length_ratio"), c.get("front_velocity_ratio"), c.get("fragmentation"),
                 c.get("largest_fragment_mass_fraction"), c.get("mean_fragment_diameter_m"),
                 d.name])
for r in sorted(rows, key=lambda r: (r[0], r[1], r[2])):
    out.writerow(r)
