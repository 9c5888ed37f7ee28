#!/usr/bin/env bash
# Nightly reproduction of the paper: `hvi-study reproduce --tier paper`, keeping the previous
# night's report and listing what changed since (verdicts and deciding numbers).
#
# cron, every night at 01:00 (the script finds the repository from its own path):
#   0 1 * * * nice -n 19 /path/to/hvi/scripts/nightly.sh >> /path/to/hvi/runs/nightly.log 2>&1
# To follow a branch, pull first:
#   0 1 * * * cd /path/to/hvi && git pull --ff-only && nice -n 19 scripts/nightly.sh >> runs/nightly.log 2>&1
#
# Environment (all optional):
#   HVI_NIGHTLY_DIR  where the reports go (default reports/nightly)
#   HVI_TIER         the tier (default paper; quick for a smoke test)
#   HVI_THREADS      worker threads (default every core)
#
# Layout: $HVI_NIGHTLY_DIR/history.jsonl (one record per night: commit, date, wall times,
# every verdict and deciding number; kept across nights), $HVI_NIGHTLY_DIR/latest (tonight's
# report: index.html with every number's history, report.md, reproduce.json, figures; it is
# rewritten after every stage, so it shows how far the night got), $HVI_NIGHTLY_DIR/previous
# (the night before), $HVI_NIGHTLY_DIR/nightly.lock. The runs are kept in the study store
# (runs/reproduce/<tier>, by fingerprint): a night simulates only what is missing. The paper
# tier's first complete pass takes hours on two cores (report.md states the estimate and the
# measured time; it fits in one night); should it overrun, it spreads over several nights:
# while a night's reproduction still runs, the next one is skipped. Once complete, a night redraws every figure from the stored runs in minutes, and
# re-simulates only what a change of the engine version invalidates.
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${HVI_NIGHTLY_DIR:-reports/nightly}
tier=${HVI_TIER:-paper}
mkdir -p "$dir"
exec 9>"$dir/nightly.lock"
if ! flock -n 9; then
    echo "$(date -Is) nightly: the previous reproduction is still running; skipped"
    exit 0
fi
echo "$(date -Is) nightly: building"
cargo build --release -p hvi-study
if [ -f "$dir/latest/reproduce.json" ]; then
    rm -rf "$dir/previous"
    mv "$dir/latest" "$dir/previous"
fi
args=(reproduce --tier "$tier" --out "$dir/latest" --history "$dir/history.jsonl")
if [ -f "$dir/previous/reproduce.json" ]; then
    args+=(--previous "$dir/previous")
fi
if [ -n "${HVI_THREADS:-}" ]; then
    args+=(--threads "$HVI_THREADS")
fi
echo "$(date -Is) nightly: hvi-study ${args[*]}"
target/release/hvi-study "${args[@]}"
echo "$(date -Is) nightly: done: $dir/latest/index.html"
