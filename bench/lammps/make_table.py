#!/usr/bin/env python3
"""Write the LAMMPS `bond_style table` file for hvi's one-sided cohesive spring.

    E(r) = 0.5 * kappa * (r - r_eq)^2   for r > r_eq
    E(r) = 0                             for r <= r_eq
    F(r) = -dE/dr

(MODEL.md section 3, eq. 4). The contact repulsion between bonded pairs is NOT in
this table: it comes from `pair_style lj/cut` with `special_bonds lj 1 1 1`, as in hvi.

The table is evenly spaced and r_eq is placed exactly on a node, so that LAMMPS's
`bond_style table linear N` (use the same N as here) reproduces the force exactly
(the force is piecewise linear with its only kink at r_eq) and the energy to within
kappa*dr^2/8 per bond (linear interpolation of a parabola). LAMMPS re-samples the file
with a cubic spline onto N evenly spaced points between the first and last r of the
file; with the same N those points are the file's own nodes, so the spline adds nothing.

The table must cover every bond length that can occur: LAMMPS aborts with
"Bond length < table inner cutoff" or "> table outer cutoff" otherwise. Bonds longer
than rcut exist for a few steps in LAMMPS because fix bond/break breaks at most one bond
per atom per step, so the upper end is well beyond rcut (default 2.5 sigma).

Usage:
  make_table.py --r-eq R --kappa K --rcut RC --sigma S [--n 4001] [--lo 0.3] [--hi 2.5]
                [--keyword HVI_BOND] [--out hvi_bond.table]
All lengths in metres, kappa in N/m; --lo/--hi in units of sigma. stdlib only.
"""
import argparse
import sys


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--r-eq", type=float, required=True, help="zero-force distance r_eq, m")
    p.add_argument("--kappa", type=float, required=True, help="spring constant, N/m")
    p.add_argument("--rcut", type=float, required=True, help="break distance, m (checked to lie inside the table)")
    p.add_argument("--sigma", type=float, required=True, help="particle diameter sigma, m (table range unit)")
    p.add_argument("--n", type=int, default=4001, help="number of table points (use the same N in bond_style table linear N)")
    p.add_argument("--lo", type=float, default=0.3, help="inner end of the table, in sigma (hvi aborts below 0.35 sigma)")
    p.add_argument("--hi", type=float, default=2.5, help="outer end of the table, in sigma")
    p.add_argument("--keyword", default="HVI_BOND", help="section keyword in the table file")
    p.add_argument("--out", default="-", help="output file ('-' = stdout)")
    a = p.parse_args(argv)

    if not (a.sigma > 0 and a.r_eq > 0 and a.kappa > 0):
        p.error("sigma, r_eq and kappa must be positive")
    if a.n < 3:
        p.error("--n must be at least 3")
    lo, hi = a.lo * a.sigma, a.hi * a.sigma
    if not (lo < a.r_eq < a.rcut < hi):
        p.error(f"need lo < r_eq < rcut < hi, got {lo!r} {a.r_eq!r} {a.rcut!r} {hi!r}")

    # Even spacing with r_eq exactly on node i_eq.
    dr = (hi - lo) / (a.n - 1)
    i_eq = int(round((a.r_eq - lo) / dr))
    lo = a.r_eq - i_eq * dr
    rs = [a.r_eq + (i - i_eq) * dr for i in range(a.n)]
    rs[i_eq] = a.r_eq
    if rs[-1] <= a.rcut:
        p.error("table does not reach beyond rcut; raise --hi")

    lines = [
        "# hvi one-sided harmonic bond: E = 0.5*kappa*(r-r_eq)^2 for r > r_eq, else 0 (SI units)",
        f"# r_eq = {a.r_eq!r} m, kappa = {a.kappa!r} N/m, rcut = {a.rcut!r} m, sigma = {a.sigma!r} m",
        f"# {a.n} points, dr = {dr!r} m, r_eq is node {i_eq + 1}; use: bond_style table linear {a.n}",
        "",
        a.keyword,
        f"N {a.n} FP 0.0 {-a.kappa!r} EQ {a.r_eq!r}",
        "",
    ]
    for i, r in enumerate(rs):
        x = r - a.r_eq
        if i <= i_eq:
            e, f = 0.0, 0.0
        else:
            e, f = 0.5 * a.kappa * x * x, -a.kappa * x
        lines.append(f"{i + 1} {r:.17e} {e:.17e} {f:.17e}")
    text = "\n".join(lines) + "\n"
    if a.out == "-":
        sys.stdout.write(text)
    else:
        with open(a.out, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
