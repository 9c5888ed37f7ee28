#!/usr/bin/env bash
# One run of "The free-flight bias at other shots" (README.md): from the project's root,
#   xargs -P2 -L1 reports/screen/shots-jobs.sh < LIST
# with LIST lines `SHOT V0 T_OVER_D END_US FF_US|full EPS KAPPA SEED`; runs go into
# ${OUT:-runs/screen-shots}/SHOT/ at ${PARTICLES:-100000} particles, read by
# `python3 reports/screen/shots.py DIR`.
set -u
shot=$1; v=$2; td=$3; end=$4; ff=$5; e=$6; k=$7; s=$8
d=${OUT:-runs/screen-shots}/$shot/e${e}_k${k}_s${s}_ff${ff}
mkdir -p "$(dirname "$d")"; [ -f "$d/summary.json" ] && exit 0
extra=()
[ "$ff" != full ] && extra=(--set "run.free_flight_after_s=${ff}e-6")
${HVI:-target/release/hvi-study} run studies/scenes/calibration.toml --quiet --threads 1 --out "$d" \
  --set resolution.particles=${PARTICLES:-100000} --set scene.v0_m_s="$v" --set scene.t_over_d="$td" \
  --set run.end_time_s="${end}e-6" --set material.eps_j="$e" --set material.kappa_n_m="$k" \
  --set run.seed="$s" "${extra[@]}" > "$d.log" 2>&1
echo "$shot $e $k $s $ff rc=$?"
