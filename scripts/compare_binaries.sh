#!/usr/bin/env bash
# Times two morphmap binaries against each other on the Table II morphs, the way every before/after figure in the
# README is measured: the machines are shared and noisy (a run after a few idle seconds is 10-20% slower than one
# straight after another), so single runs of each binary say little. The two binaries run alternately, each round
# the whole batch of jobs with one binary then the other (the order swapped every round), and the script prints
# every stage's median and range per binary from report.json's `seconds`, the process's CPU seconds (the same work
# costs the same CPU time unless the machine slows it), the solver's iterations and the tracer's
# rate evaluations, and how far the new binary's labels are from the old one's (bitwise the same, or the median
# and largest distance in units of the labels' bounding-box diagonal).
#   usage: scripts/compare_binaries.sh MODELS_DIR OLD_BINARY NEW_BINARY [ROUNDS] [JOB...]
#   ROUNDS defaults to 3; JOBs are names from table2_jobs.sh (sphere-torus, sphere-bunny, splitting-sphere,
#   sphere-buddha, cow-horse), all five by default. Outputs go to a temporary folder, removed at the end, or to
#   $COMPARE_OUT when that is set (kept; its old-<k> and new-<k> folders are replaced). $COMPARE_IDLE=S sleeps S
#   seconds before every batch, so that (with one JOB) every run starts on memory the host has taken back, as a run
#   after an idle spell does (docs/performance_log.md, 2026-12-03 (late night): 0.3 s of cow -> horse); without it
#   the runs follow each other and mostly reuse the memory the previous one freed.
# Build the old binary from a commit in a separate worktree, e.g.
#   git worktree add /tmp/old HEAD~1 && cmake -S /tmp/old -B /tmp/old/build -G Ninja && ninja -C /tmp/old/build morphmap
set -euo pipefail
usage="usage: $0 MODELS_DIR OLD_BINARY NEW_BINARY [ROUNDS] [JOB...]"
if [ $# -lt 3 ]; then
  echo "$usage" >&2
  exit 2
fi
[ -d "$1" ] || { echo "$0: $1: not a folder" >&2; exit 2; }
models="$(cd "$1" && pwd)"
for b in "$2" "$3"; do
  [ -x "$b" ] || { echo "$0: $b: not an executable" >&2; exit 2; }
done
old="$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"
new="$(cd "$(dirname "$3")" && pwd)/$(basename "$3")"
rounds="${4:-3}"
case "$rounds" in '' | *[!0-9]* | 0) echo "$0: ROUNDS must be a positive integer, not '$rounds'" >&2; exit 2 ;; esac
idle="${COMPARE_IDLE:-0}"
case "$idle" in '' | *[!0-9]*) echo "$0: COMPARE_IDLE must be a whole number of seconds, not '$idle'" >&2; exit 2 ;; esac
shift $(($# < 4 ? $# : 4))
repo="$(cd "$(dirname "$0")/.." && pwd)"
# shellcheck source=scripts/table2_jobs.sh
source "$repo/scripts/table2_jobs.sh"

if [ -n "${COMPARE_OUT:-}" ]; then
  out="$COMPARE_OUT"
  mkdir -p "$out"
  out="$(cd "$out" && pwd)"
else
  out="$(mktemp -d)"
  trap 'rm -rf "$out"' EXIT
fi

# The manifest: the chosen jobs (all by default), with Table II's 10 time steps and no comparison solves.
table2_jobs | python3 -c '
import json, sys
jobs = json.loads("[" + sys.stdin.read() + "]")
wanted = sys.argv[2:]
names = [j["name"] for j in jobs]
for w in wanted:
    if w not in names:
        print("compare_binaries.sh: no job %r (jobs: %s)" % (w, " ".join(names)), file=sys.stderr)
        sys.exit(2)
jobs = [j for j in jobs if not wanted or j["name"] in wanted]
json.dump({"defaults": {"time-steps": 10}, "jobs": jobs}, open(sys.argv[1], "w"), indent=1)
' "$out/manifest.json" "$@"

status=0
for ((round = 1; round <= rounds; ++round)); do
  order="old new"
  [ $((round % 2)) -eq 0 ] && order="new old"
  for tag in $order; do
    bin="$old"
    [ "$tag" = new ] && bin="$new"
    [ -t 2 ] && printf '\rround %d of %d: %s binary   ' "$round" "$rounds" "$tag" >&2
    # A fresh folder: batch would skip (resume) a job whose folder holds a complete report from an earlier run.
    rm -rf "${out:?}/$tag-$round"
    [ "$idle" -gt 0 ] && sleep "$idle"
    "$bin" batch "$out/manifest.json" -o "$out/$tag-$round" >/dev/null || status=$?
  done
done
[ -t 2 ] && printf '\r%40s\r' '' >&2

python3 - "$out" "$rounds" "$old" "$new" <<'EOF'
import json, math, os, statistics, sys

out, rounds, old_bin, new_bin = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
jobs = [j["name"] for j in json.load(open(os.path.join(out, "manifest.json")))["jobs"]]

def report(tag, r, job):
    path = os.path.join(out, f"{tag}-{r}", job, "report.json")
    return json.load(open(path)) if os.path.exists(path) else None

def labels(tag, r, job):
    path = os.path.join(out, f"{tag}-{r}", job, "labels.txt")
    return open(path, "rb").read() if os.path.exists(path) else None

def fmt(values):
    if not values:
        return "–"
    m = statistics.median(values)
    return f"{m:.3f} [{min(values):.3f}–{max(values):.3f}]" if len(values) > 1 else f"{m:.3f}"

print(f"old: {old_bin}\nnew: {new_bin}\n{rounds} rounds, alternating; seconds from report.json (median [range])\n")
for job in jobs:
    reports = {tag: [x for x in (report(tag, r, job) for r in range(1, rounds + 1)) if x] for tag in ("old", "new")}
    print(f"## {job}")
    if not reports["old"] or not reports["new"]:
        print("failed: see", os.path.join(out, "<old|new>-<round>", job, "map.log"), "\n")
        continue
    stages = ["total"] + sorted({k for tag in reports for x in reports[tag] for k in x["seconds"] if k != "total"})
    print("| stage | old s | new s | new / old |\n|---|--:|--:|--:|")
    for stage in stages:
        o = [x["seconds"].get(stage, 0.0) for x in reports["old"]]
        n = [x["seconds"].get(stage, 0.0) for x in reports["new"]]
        if max(statistics.median(o), statistics.median(n)) < 0.01:
            continue
        ratio = statistics.median(n) / statistics.median(o) if statistics.median(o) > 0 else float("nan")
        print(f"| {stage} | {fmt(o)} | {fmt(n)} | {ratio:.3f} |")
    # The process's CPU seconds (user and system): the same work gives the same figure unless the machine slows it,
    # so a stage that is slower with a higher CPU figure on both sides says more about the machine than the code. Then
    # their system part (binaries from before 2026-12-07 20:06 UTC do not report it): first touches of memory, mostly.
    for name, key in (("CPU s (process)", "cpu_seconds"), ("system CPU s", "system_cpu_seconds")):
        o = [x[key] for x in reports["old"] if key in x]
        n = [x[key] for x in reports["new"] if key in x]
        if o and n and statistics.median(o) > 0:
            print(f"| {name} | {fmt(o)} | {fmt(n)} | {statistics.median(n) / statistics.median(o):.3f} |")
    for name, get in (("solver iterations", lambda x: x.get("solver", {}).get("iterations")),
                      ("trace rate evaluations", lambda x: x.get("trace", {}).get("rate_evaluations")),
                      ("peak memory MB", lambda x: (x.get("peak_memory_bytes") or 0) / 2**20)):
        o, n = get(reports["old"][0]), get(reports["new"][0])
        if o is not None or n is not None:
            print(f"| {name} | {o if not isinstance(o, float) else round(o)} | {n if not isinstance(n, float) else round(n)} | |")
    a, b = labels("old", 1, job), labels("new", 1, job)
    if a is None or b is None:
        print("\nlabels: not written by both")
    elif a == b:
        print("\nlabels: bitwise the same")
    else:
        pa = [tuple(map(float, l.split())) for l in a.decode().splitlines()]
        pb = [tuple(map(float, l.split())) for l in b.decode().splitlines()]
        if len(pa) != len(pb):
            print(f"\nlabels: {len(pa)} rows (old) against {len(pb)} (new)")
        else:
            lo = [min(p[i] for p in pa) for i in range(3)]
            hi = [max(p[i] for p in pa) for i in range(3)]
            diag = math.dist(lo, hi) or 1.0
            d = sorted(math.dist(p, q) / diag for p, q in zip(pa, pb))
            print(f"\nlabels: moved by a median {d[len(d) // 2]:.2e}, 99th percentile {d[int(0.99 * (len(d) - 1))]:.2e}, "
                  f"max {d[-1]:.2e} of their box diagonal; {sum(v > 1e-3 for v in d)} of {len(d)} by more than 1e-3")
    print()
EOF
exit "$status"
