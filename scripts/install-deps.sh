#!/usr/bin/env bash
# Installs prtfarm's build dependencies and the real data packages its demo and tests use.
# Debian 12 packages only. Idempotent: does nothing when everything is already installed.
# Works as root and as a normal user with sudo.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git python3
  libembree-dev libopenmpi-dev openmpi-bin libopenexr-dev libflann-dev liblz4-dev libdraco-dev
  libzstd-dev libeigen3-dev libtbb-dev libgtest-dev libgmock-dev libbenchmark-dev
  libcli11-dev libtomlplusplus-dev libspdlog-dev nlohmann-json3-dev libxxhash-dev
  libpng-dev libsdl2-dev
  clang libclang-rt-14-dev gnuplot-nox xvfb
  libcgal-demo blender-data
  slurm-wlm munge
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO="sudo"
  else
    echo "install-deps: need root or sudo to install: ${missing[*]}" >&2
    exit 1
  fi
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
