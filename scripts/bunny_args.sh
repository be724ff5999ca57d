# shellcheck shell=bash disable=SC2034  # sourced: the variables it sets are the caller's
# Sourced by the sphere -> bunny scripts (study_bunny.sh, reproduce_table1.sh) with "$@" and a default output
# folder name: checks MODELS_DIR, needs jq, and sets models, repo, out (created) and bin (MORPHMAP or the build).
default_out=$1
shift
if [ $# -lt 1 ] || [ ! -f "$1/bunny_closed.obj" ]; then
  echo "usage: $0 MODELS_DIR [OUT_DIR]  (MODELS_DIR holds bunny_closed.obj)" >&2
  exit 2
fi
command -v jq >/dev/null || { echo "$0: needs jq (scripts/setup.sh installs it)" >&2; exit 2; }
models="$(cd "$1" && pwd)"
repo="$(cd "$(dirname "$0")/.." && pwd)"
out="${2:-$repo/out/$default_out}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
bin="${MORPHMAP:-$repo/build/morphmap}"
[ -x "$bin" ] || { bash "$repo/scripts/build.sh" morphmap >&2; bin="$repo/build/morphmap"; }
