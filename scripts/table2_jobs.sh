#!/usr/bin/env bash
# The paper's five Table II morphs as `morphmap batch` jobs (one JSON object per line, comma-separated), shared by
# reproduce_table2.sh and compare_binaries.sh so that both time the same maps. Sourced; needs $models (an absolute
# path holding bunny_closed.obj, happy_buddha_100k.obj, cow.off and horse.obj).
# --voxels chosen (measured) so that the tet counts land near the paper's: 0.22, 0.42, 0.86, 1.36, 1.69 million.
# The change thresholds are each row's own in Table II (1e-5, 1.2e-4 for the Buddha, 2.5e-3 for cow -> horse): they
# stop the Gauss-Seidel comparison (`compare-solvers`) and change nothing in the map's own converged solve.
# The fold repair (on by default since 2026-12-06) is off: Table II times the paper's pipeline, which has no such
# stage (README, "Batch runs and Table II"; the repair adds 0.2-0.6 s to these jobs and 1.3 s to cow -> horse).
# shellcheck disable=SC2154  # $models: set by the script that sources this one
table2_jobs() {
  cat <<JOBS
    {"name": "sphere-torus", "source": "sphere", "target": "torus", "voxels": 13, "fold-repair": "off"},
    {"name": "sphere-bunny", "source": "sphere", "target": "$models/bunny_closed.obj", "voxels": 20, "time-steps": 6, "fold-repair": "off"},
    {"name": "splitting-sphere", "source": "sphere", "target": "two-spheres", "voxels": 25, "fold-repair": "off"},
    {"name": "sphere-buddha", "source": "sphere", "target": "$models/happy_buddha_100k.obj", "voxels": 32, "change-threshold": 0.00012, "fold-repair": "off"},
    {"name": "cow-horse", "source": "$models/cow.off", "target": "$models/horse.obj", "voxels": 63, "align": "bbox", "change-threshold": 0.0025, "fold-repair": "off"}
JOBS
}
