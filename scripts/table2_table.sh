#!/usr/bin/env bash
# Prints Table II (paper §9) from `morphmap batch` summaries of its five jobs (scripts/table2_jobs.sh): the paper's
# row above ours, our total the median of the runs' map seconds with their range, the ratio of total times, and the
# maps' CPU seconds of the runs after the first. reproduce_table2.sh runs the batches and calls this.
#   usage: scripts/table2_table.sh RUNS FIRST_SUMMARY.csv [SUMMARY.csv...]
#   FIRST_SUMMARY.csv is the run with the Gauss-Seidel comparison (its other columns are printed); the others are the
#   timing runs. RUNS is only quoted in the explanation.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 RUNS FIRST_SUMMARY.csv [SUMMARY.csv...]" >&2
  exit 2
fi
runs="$1"
shift
case "$runs" in '' | *[!0-9]* | 0) echo "$0: RUNS must be a positive integer, not '$runs'" >&2; exit 2 ;; esac
for f in "$@"; do
  [ -f "$f" ] || { echo "$0: $f: no such file" >&2; exit 2; }
done

# Paper rows: job|morph|tets|steps|diffusion iters|secs|conv|implicit iters|secs|conv|label prop iters|secs.
paper='sphere-torus|Sphere to Torus|219998|10|469|24|0.00001|2|11|0.0|5|3
sphere-bunny|Sphere to Bunny|416747|6|535|46|0.00001|3|16|0.000037|7|10
splitting-sphere|Splitting Sphere|858006|10|824|159|0.00001|3|21|0.000010|6|13
sphere-buddha|Sphere to Buddha|1360634|10|93|61|0.00012|-|-|-|6|25
cow-horse|Cow to Horse|1692940|10|7|41|0.00250|-|-|-|10|50'

echo
if ((runs > 1)); then timed="runs 2 to $runs; median [range]"; else timed="none with RUNS = 1"; fi
echo "Table II: paper (2 GHz AMD PC) above ours ($(nproc) cores, $(uname -m)). Paper total = the seconds its row lists"
echo "(diffusion + implicit + label propagation); ours = the map end to end with the converged default solve (load, morph,"
echo "extraction, solve, transport, outputs: report.json's total; the process's start and exit, about 0.1 s, are outside"
echo "it), the Gauss-Seidel comparison not included: the median of $runs runs (their range in brackets); ratio = paper /"
echo "that median. Maps' CPU s: the CPU seconds (user and system, the whole process) of the maps timed without the"
echo "comparison ($timed), and the system (kernel) part of them: the same work in every run, so a larger figure"
echo "means a slower machine, not more work (the system part is nearly all first touches of memory, which cost about 20"
echo "times more when the host has taken the pages back). The other columns are the first run's; the last is its whole"
echo "job with the comparison diffusion, wall and CPU seconds (on a shared machine wall >> CPU / cores)."
echo
echo "| morph | who | tets | steps | diffusion (iters, s, conv) | implicit/direct (iters, s, residual) | label prop (passes, s) | total s [range] | ratio | maps' CPU s | with GS: wall s, CPU s |"
echo "|---|---|--:|--:|---|---|---|--:|--:|--:|---|"
awk -F',' -v paper="$paper" -v first="$1" '
  # Runs a[job, 1..m] sorted in place (insertion sort: a handful of runs), their median and " [min–max]" when m > 1.
  function sort_runs(a, job, m,    i, j, x) {
    for (i = 2; i <= m; ++i)
      for (j = i; j > 1 && a[job, j - 1] > a[job, j]; --j) { x = a[job, j]; a[job, j] = a[job, j - 1]; a[job, j - 1] = x }
  }
  function median(a, job, m) { return m % 2 ? a[job, (m + 1) / 2] : (a[job, m / 2] + a[job, m / 2 + 1]) / 2 }
  function spread(a, job, m) { return m > 1 ? sprintf(" [%.2f–%.2f]", a[job, 1], a[job, m]) : "" }
  # "median [min–max]" of runs a[job, 1..m], m > 0 (sorts them).
  function figure(a, job, m) { sort_runs(a, job, m); return sprintf("%.2f", median(a, job, m)) spread(a, job, m) }
  BEGIN {
    n = split(paper, lines, "\n")
    for (i = 1; i <= n; ++i) { split(lines[i], f, "|"); order[i] = f[1]; row[f[1]] = lines[i] }
  }
  FNR == 1 { split("", col); for (c = 1; c <= NF; ++c) col[$c] = c; next }
  FILENAME == first { seen[$1] = 1; for (c = 1; c <= NF; ++c) v[$1, c] = $c }
  $col["status"] == "ok" { times[$1, ++count[$1]] = $col["map_seconds"] + 0 }
  FILENAME != first && $col["status"] == "ok" {
    cpus[$1, ++cpu_count[$1]] = $col["cpu_seconds"] + 0
    # Summaries from before 2026-12-07 (20:06 UTC) have no system column.
    if ("system_cpu_seconds" in col && $col["system_cpu_seconds"] != "") syss[$1, ++sys_count[$1]] = $col["system_cpu_seconds"] + 0
  }
  END {
    for (i = 1; i <= n; ++i) {
      job = order[i]; split(row[job], p, "|")
      ptotal = p[6] + (p[9] == "-" ? 0 : p[9]) + p[12]
      implicit = p[8] == "-" ? "–" : p[8] ", " p[9] ", " p[10]
      printf "| %s | paper | %s | %s | %s, %s, %s | %s | %s, %s | %d | | | |\n", p[2], p[3], p[4], p[5], p[6], p[7], implicit, p[11], p[12], ptotal
      if (!(job in seen)) { printf "| | ours | not run | | | | | | | | |\n"; continue }
      if (v[job, col["status"]] != "ok") { printf "| | ours | %s: %s | | | | | | | | |\n", v[job, col["status"]], v[job, col["error"]]; continue }
      m = count[job]
      sort_runs(times, job, m)
      t = median(times, job, m)
      range = spread(times, job, m)
      cpu = cpu_count[job] == 0 ? "–" : figure(cpus, job, cpu_count[job])
      if (sys_count[job] > 0) cpu = cpu ", sys " figure(syss, job, sys_count[job])
      printf "| | ours | %s | %s | %s, %.2f, %.2g | %s %s, %.2f, %.2g | %s, %.2f | %.2f%s | %.1f× | %s | %.2f, %.2f |\n",
        v[job, col["tets"]], v[job, col["time_steps"]],
        v[job, col["diffusion_iterations"]] (v[job, col["diffusion_iterations"]] >= 20000 ? " (cap)" : ""),
        v[job, col["diffusion_seconds"]], v[job, col["diffusion_conv"]],
        v[job, col["solve_backend"]], v[job, col["solve_iterations"]], v[job, col["solve_seconds"]], v[job, col["solve_residual"]],
        (v[job, col["label_passes"]] == "" ? "trace" : v[job, col["label_passes"]]), v[job, col["label_seconds"]], t, range, ptotal / t, cpu, v[job, col["total_seconds"]], v[job, col["cpu_seconds"]]
    }
  }' "$@"
