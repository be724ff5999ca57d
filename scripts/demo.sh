#!/usr/bin/env bash
# Installs dependencies, builds, and maps the built-in textured sphere onto the built-in torus.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/build.sh morphmap
out="${1:-out/demo}"
./build/morphmap demo -o "$out"
echo "demo outputs in $out:"
ls "$out"
