#!/usr/bin/env python3
"""Prints the side-by-side table of a bench_solve JSON run (medians): every backend on every system.

usage: scripts/solver_table.py BENCH.json   (from morphmap_bench --benchmark_filter='BM_Solve|BM_SpMV'
       --benchmark_repetitions=3 --benchmark_format=json --benchmark_out=BENCH.json)
"""
import json
import sys

BACKENDS = ["cg-amg", "cg", "cg-ic", "cholmod", "auto", "ldlt", "gauss-seidel", "gauss-seidel-mean"]


def seconds(b):
    scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[b["time_unit"]]
    return b["real_time"] * scale


def main(path):
    runs = json.load(open(path))["benchmarks"]
    median, skipped, systems = {}, set(), []
    for b in runs:
        name = b["run_name"].replace("/iterations:1/real_time", "").replace("/real_time", "")
        if b.get("error_occurred"):
            skipped.add(name)
        elif b.get("aggregate_name") == "median":
            median[name] = b
        parts = name.split("/")
        if parts[0] == "BM_Solve" and "/".join(parts[1:3]) not in systems:
            systems.append("/".join(parts[1:3]))
    morphs = ["sphere-torus", "sphere-bunny", "cow-horse"]
    systems.sort(key=lambda name: (morphs.index(name.split("/")[0]) if name.split("/")[0] in morphs else 9,
                                   float(name.split("/")[1].rstrip("M"))))
    print("| system | tets | unknowns | " + " | ".join(BACKENDS) + " | GS ÷ cg-amg | GS-mean ÷ cg-amg | ldlt ÷ cg-amg |")
    print("|---|--:|--:|" + "---|" * len(BACKENDS) + "--:|--:|--:|")
    for system in systems:
        cells, tets, unknowns = [], "", ""
        base = median.get("BM_Solve/%s/cg-amg" % system)
        for backend in BACKENDS:
            key = "BM_Solve/%s/%s" % (system, backend)
            if key in median:
                b = median[key]
                tets, unknowns = "%.2f M" % (b["tets"] / 1e6), "%d" % b["unknowns"]
                cells.append("%.3g s, %d it., %.0e" % (seconds(b), b["iterations"], b["residual"]))
            else:
                cells.append("skipped" if key in skipped else "–")

        def ratio(backend):
            key = "BM_Solve/%s/%s" % (system, backend)
            return "%.1f×" % (seconds(median[key]) / seconds(base)) if key in median and base else "–"

        print("| %s | %s | %s | %s | %s | %s | %s |" % (system, tets, unknowns, " | ".join(cells), ratio("gauss-seidel"),
                                                     ratio("gauss-seidel-mean"), ratio("ldlt")))
    print()
    for name, b in sorted(median.items()):
        if name.startswith("BM_SpMV"):  # the counter is already in GB/s
            print("%s: %.1f GB/s (%.0f MB per product)" % (name, b["GBps"], b["bytes_per_spmv"] / 1e6))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
