#!/bin/bash
# Fig. 4's colliding plates with geometric sizing at several particle counts and thermal
# amplitudes: when the bonds first take up tension (bond energy above 2.5 % of the initial
# kinetic energy), i.e. when the lattice instability that parts the energy curves sets in.
# Prints a markdown table; reports/sizing-instability/README.md holds its output.
#
#   scripts/sizing-instability.sh [COUNTS] [AMPLITUDES]    # defaults below; about 5 min on 2 cores
#
# The scene is reproduce::sizing::plates_scene (the sizing test's): a 1 mm flyer at 300 m/s on
# a 2 mm target, both 4 mm square, the paper's best-fit material, 10x the automatic step,
# 0.8 us after first contact.
set -euo pipefail
cd "$(dirname "$0")/.."
COUNTS=${1:-"486 1500 4800 15309 48000 150000 500000"}
AMPS=${2:-"1e-2 1e-3 1e-4 1e-6"}
BIN=${HVI_STUDY:-target/release/hvi-study}
[ -x "$BIN" ] || cargo build --release -p hvi-study >&2
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cat > "$WORK/plates.toml" <<'TOML'
[scene]
kind = "flyer_plate"
flyer_thickness_m = 1e-3
target_thickness_m = 2e-3
width_m = 4e-3
v0_m_s = 300.0

[resolution]
particles = 486

[material]
eps_j = 0.01
kappa_n_m = 4.56e6

[run]
end_time_s = 0.8e-6
dt_factor = 10.0
energy_every = 10

[analysis]
cloud = false
track_every = 0
render_times_s = []
TOML
# onset CSV: the first tau_s at which bond_j exceeds 2.5 % of the first row's kinetic_j.
onset() {
  awk -F, 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
           NR==2{k0=$c["kinetic_j"]}
           $c["bond_j"]>0.025*k0{printf "%.3f", $c["tau_s"]*1e6; found=1; exit}
           END{if(!found) printf "none by 0.8"}' "$1"
}
printf '| particles |'; for a in $AMPS; do printf ' thermal %s v0 |' "$a"; done; echo
printf '|---|'; for a in $AMPS; do printf -- '---|'; done; echo
for n in $COUNTS; do
  row=""
  for a in $AMPS; do
    out="$WORK/n$n-$a"
    "$BIN" run "$WORK/plates.toml" --set resolution.particles="$n" --set run.thermal_ratio="$a" \
      --out "$out" --fresh > /dev/null 2>&1
    row="$row $(onset "$out/energy.csv") |"
  done
  actual=$(grep -o '"particles": [0-9]*' "$out/summary.json" | head -1 | grep -o '[0-9]*$')
  echo "| $actual |$row"
done
