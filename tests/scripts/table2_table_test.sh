#!/usr/bin/env bash
# scripts/table2_table.sh on hand-made batch summaries: the median and range of the runs' map seconds, the ratio to the
# paper's total, the maps' CPU seconds of the runs after the first, a failed job, a job never run, and a missing file.
# The expected figures are worked out by hand from the summaries below.
set -euo pipefail
repo="$(cd "$(dirname "$0")/../.." && pwd)"
dir="$(mktemp -d)"
trap 'rm -rf "$dir"' EXIT
header=job,status,tets,time_steps,diffusion_iterations,diffusion_seconds,diffusion_conv,solve_backend,solve_iterations,solve_seconds,solve_residual,label_passes,label_seconds,map_seconds,total_seconds,cpu_seconds,system_cpu_seconds,peak_memory_bytes,warnings,error
cat >"$dir/first.csv" <<CSV
$header
sphere-torus,ok,229380,10,11447,4.1,1e-05,cg-amg,21,0.04,6.5e-09,,0.03,0.25,4.5,4.75,0.3,92221440,,
sphere-bunny,failed,,,,,,,,,,,,,,,,,,boom
sphere-buddha,ok,1439691,10,20000,60.5,0.086,cg-amg,30,0.32,7.2e-09,,0.2,1.3,62,63.5,0.5,276000000,,
cow-horse,ok,1664949,10,20000,76.5,0.024,cg-amg,29,0.35,9.2e-09,,0.66,2.0,80.5,82.25,0.6,311000000,,
CSV
cat >"$dir/second.csv" <<CSV
$header
sphere-buddha,ok,1439691,10,,,,cg-amg,30,0.32,7.2e-09,,0.2,1.1,1.1,2.4,0.2,276000000,,
cow-horse,ok,1664949,10,,,,cg-amg,29,0.35,9.2e-09,,0.66,1.8,1.8,3.6,0.4,311000000,,
CSV
cat >"$dir/third.csv" <<CSV
$header
sphere-buddha,ok,1439691,10,,,,cg-amg,30,0.32,7.2e-09,,0.2,1.2,1.2,2.2,0.1,276000000,,
cow-horse,ok,1664949,10,,,,cg-amg,29,0.35,9.2e-09,,0.66,1.9,1.9,3.5,0.3,311000000,,
CSV
out="$(bash "$repo/scripts/table2_table.sh" 3 "$dir/first.csv" "$dir/second.csv" "$dir/third.csv")"
fail=0
expect() {
  if ! grep -qF -- "$1" <<<"$out"; then
    echo "missing: $1"
    fail=1
  fi
}
# cow -> horse: maps 2.0, 1.8, 1.9 s -> 1.90 [1.80-2.00]; 91 / 1.9 = 47.9; CPU of runs 2-3: 3.6, 3.5 -> 3.55 [3.50-3.60],
# their system part 0.4, 0.3 -> 0.35 [0.30-0.40].
expect "| | ours | 1664949 | 10 | 20000 (cap), 76.50, 0.024 | cg-amg 29, 0.35, 9.2e-09 | trace, 0.66 | 1.90 [1.80–2.00] | 47.9× | 3.55 [3.50–3.60], sys 0.35 [0.30–0.40] | 80.50, 82.25 |"
# the Buddha: 1.3, 1.1, 1.2 -> 1.20 [1.10-1.30]; 86 / 1.2 = 71.7; CPU 2.4, 2.2 -> 2.30 [2.20-2.40], system 0.2, 0.1.
expect "| 1.20 [1.10–1.30] | 71.7× | 2.30 [2.20–2.40], sys 0.15 [0.10–0.20] | 62.00, 63.50 |"
# sphere -> torus ran once: no range, 38 / 0.25 = 152, no CPU of a timing run.
expect "| 0.25 | 152.0× | – | 4.50, 4.75 |"
expect "| | ours | failed: boom |"
expect "| Splitting Sphere | paper | 858006 | 10 | 824, 159, 0.00001 | 3, 21, 0.000010 | 6, 13 | 193 | | | |"
expect "| | ours | not run |"
expect "(runs 2 to 3; median [range])"
# A missing summary is an error (status 2) naming the file.
if bash "$repo/scripts/table2_table.sh" 3 "$dir/none.csv" >/dev/null 2>"$dir/err"; then
  echo "a missing summary was accepted"
  fail=1
elif ! grep -qF "$dir/none.csv: no such file" "$dir/err"; then
  echo "the error does not name the file: $(cat "$dir/err")"
  fail=1
fi
if bash "$repo/scripts/table2_table.sh" x "$dir/first.csv" >/dev/null 2>&1; then
  echo "RUNS x was accepted"
  fail=1
fi
if [ "$fail" -ne 0 ]; then
  echo "$out"
  exit 1
fi
echo "table2_table: all expectations met"
