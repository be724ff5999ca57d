#!/usr/bin/env bash
# Reproduces Table II of the paper (§9, execution statistics) with `morphmap batch`: its five morphs at tet counts
# near the paper's, the map solved by the default backend (converged) and the paper's Gauss-Seidel diffusion run
# on the same system for the diffusion column. Prints a Markdown table, the paper's row above ours, with the ratio of total times.
# The machines are shared and noisy: the batch runs RUNS times (the first with the Gauss-Seidel comparison, the others
# the maps alone, in OUT_DIR/timing-<k>), so every row is timed RUNS times interleaved with the others, and the
# table's total is the median map time, its range beside it.
#   usage: scripts/reproduce_table2.sh MODELS_DIR [OUT_DIR] [RUNS]   (OUT_DIR defaults to out/table2, RUNS to 3;
#   rerunning resumes)
set -euo pipefail
if [ $# -lt 1 ] || [ ! -d "$1" ]; then
  echo "usage: $0 MODELS_DIR [OUT_DIR] [RUNS]  (MODELS_DIR holds bunny_closed.obj, happy_buddha_100k.obj, cow.off, horse.obj)" >&2
  exit 2
fi
models="$(cd "$1" && pwd)"
repo="$(cd "$(dirname "$0")/.." && pwd)"
out="${2:-$repo/out/table2}"
runs="${3:-3}"
case "$runs" in '' | *[!0-9]* | 0) echo "$0: RUNS must be a positive integer, not '$runs'" >&2; exit 2 ;; esac
mkdir -p "$out"
out="$(cd "$out" && pwd)"
for f in bunny_closed.obj happy_buddha_100k.obj cow.off horse.obj; do
  [ -f "$models/$f" ] || { echo "$0: $models/$f: no such file" >&2; exit 2; }
done
[ -x "$repo/build/morphmap" ] || bash "$repo/scripts/build.sh" morphmap >&2

# The five jobs (their voxels, time steps and the Gauss-Seidel comparison's thresholds) are in table2_jobs.sh. The
# Gauss-Seidel comparison stops at each row's own threshold, measured as the paper does (the total change of s in a
# sweep), or at 20000 sweeps (marked "cap").
# shellcheck source=scripts/table2_jobs.sh
source "$repo/scripts/table2_jobs.sh"
jobs=$(table2_jobs)
printf '{"defaults": {"time-steps": 10, "compare-solvers": ["gauss-seidel"]},\n "jobs": [\n%s\n ]}\n' "$jobs" \
  >"$out/manifest.json"
status=0
"$repo/build/morphmap" batch "$out/manifest.json" -o "$out" || status=$?
summaries="$out/summary.csv"
for ((run = 2; run <= runs; ++run)); do
  mkdir -p "$out/timing-$run"
  printf '{"defaults": {"time-steps": 10},\n "jobs": [\n%s\n ]}\n' "$jobs" >"$out/timing-$run/manifest.json"
  "$repo/build/morphmap" batch "$out/timing-$run/manifest.json" -o "$out/timing-$run" || status=$?
  if [ -f "$out/timing-$run/summary.csv" ]; then summaries="$summaries $out/timing-$run/summary.csv"; fi
done

# shellcheck disable=SC2086  # $summaries: one word per run's summary.csv (paths under OUT_DIR)
bash "$repo/scripts/table2_table.sh" "$runs" $summaries || status=$?
echo
echo "Per-job outputs and report.json in $out; summary.csv and summary.md there too."
exit "$status"
