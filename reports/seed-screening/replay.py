#!/usr/bin/env python3
"""Replays `calibrate.seeds_within_decades` on a finished calibration run at every seed.

    python3 reports/seed-screening/replay.py reports/calibration-paper/calibration.json [DECADES]

For each stage in turn (the grid at the seeds, each extended box, each search batch) it
applies the rule of hvi_calibrate::ego::run_points_screened to the runs the calibration made:
a point keeps its further seeds when its first seed's J is within DECADES (default 1) of the
lowest J so far (the seed means of the stages before, and the stage's own first seeds). It
prints the points that would have run at one seed, and the pooled noise of log10 J over the
points kept at every seed beside the pool over all of them (hvi_analysis::surrogate::
seed_mean_noise). It does not re-run the search: a screened calibration's model sees one-seed
values at the points it screens out, so its later proposals may differ.
"""
import json
import math
import sys


def log_j(j):
    return math.log10(max(j, 1e-6))


def noise(groups):
    ss, dof, seeds = 0.0, 0, 0
    for g in groups:
        if len(g) > 1:
            m = sum(g) / len(g)
            ss += sum((v - m) ** 2 for v in g)
            dof += len(g) - 1
            seeds = max(seeds, len(g))
    return math.sqrt(ss / dof) / math.sqrt(seeds) if dof else float("nan")


def main():
    c = json.load(open(sys.argv[1]))
    decades = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    evals = [e for e in c["refinement"] if len(e["seed_objectives"]) > 1]
    stages = []
    for e in evals:
        if not stages or stages[-1] != e["stage"]:
            stages.append(e["stage"])
    lowest, one, kept = math.inf, [], []
    for stage in stages:
        of = [e for e in evals if e["stage"] == stage]
        cut = log_j(min([lowest] + [e["seed_objectives"][0] for e in of])) + decades
        for e in of:
            (kept if log_j(e["seed_objectives"][0]) <= cut else one).append(e)
        lowest = min([lowest] + [e["objective"] for e in of])
    seeds = max(len(e["seed_objectives"]) for e in evals)
    print(f"{len(evals)} points after the grid at {seeds} seeds; within {decades} decade(s):")
    print(f"  {len(one)} would run at one seed ({len(one) * (seeds - 1)} runs fewer):")
    for e in one:
        p = ", ".join(f"{k.split('.')[-1]}={v:.4g}" for k, v in e["params"].items())
        js = ", ".join(f"{j:.4g}" for j in e["seed_objectives"])
        print(f"    {e['stage']}: {p}  J per seed {js}")
    groups = lambda es: [[log_j(j) for j in e["seed_objectives"]] for e in es]
    print(f"  noise of log10 J: {noise(groups(kept)):.4f} over the {len(kept)} points kept at every seed, "
          f"{noise(groups(evals)):.4f} over all {len(evals)}")


if __name__ == "__main__":
    main()
