#!/usr/bin/env bash
# Installs every Debian package morphmap needs to build, test and benchmark. Idempotent and quick
# when everything is present (no apt-get update then).
set -euo pipefail
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"

# The one list of packages, as a literal apt-get line; "$@" adds -s (simulate) for the check below.
install_packages() {
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-upgrade "$@" \
    build-essential cmake ninja-build pkg-config \
    libeigen3-dev libsuitesparse-dev libopenblas0-pthread libopenblas-dev \
    libtbb-dev libopenvdb-dev libboost-iostreams-dev \
    libcgal-dev libgmp-dev libmpfr-dev \
    libgtest-dev libgmock-dev libbenchmark-dev \
    libcli11-dev nlohmann-json3-dev libstb-dev libtinyobjloader-dev libembree-dev \
    jq python3
}

# A simulated install lists what is missing ("Inst" lines); it fails on a fresh machine without package lists.
if ! plan=$(install_packages -s 2>&1) || grep -q '^Inst ' <<<"$plan"; then
  echo "setup: installing the build dependencies"
  $SUDO apt-get update -qq
  install_packages >/dev/null
fi
