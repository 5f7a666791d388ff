#!/usr/bin/env bash
# Installs prtfarm's build dependencies and the real data packages its demo and tests use.
# Debian 12 packages, plus for the web page (docs/web.md): the Debian source packages of Draco
# and zstd (compiled to WebAssembly) in build-wasm/src, and web/'s npm packages at the versions
# pinned in web/package-lock.json (`npm ci`). Idempotent: does nothing when everything is already
# there. Works as root and as a normal user with sudo.
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
  emscripten dpkg-dev chromium nodejs npm
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

# A node that did not come from Debian (NodeSource's, say) is fine: it already provides npm.
if command -v node >/dev/null 2>&1 && command -v npm >/dev/null 2>&1; then
  kept=()
  for p in "${missing[@]}"; do [ "$p" = nodejs ] || [ "$p" = npm ] || kept+=("$p"); done
  missing=("${kept[@]}")
fi

SUDO=""
need_root() {
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
      SUDO="sudo"
    else
      echo "install-deps: need root or sudo to $1" >&2
      exit 1
    fi
  fi
}

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages already installed"
else
  need_root "install: ${missing[*]}"
  echo "install-deps: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# ---- The web page's sources (docs/web.md) ------------------------------------------------------
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SRC="${PRT_WASM_BUILD_DIR:-$ROOT/build-wasm}/src"
have_source() { compgen -G "$SRC/$1-*/" >/dev/null; }
if ! have_source draco || ! have_source libzstd; then
  # deb-src lines derived from the deb ones (deb822 .sources or a one-line sources.list).
  if ! apt-get source --print-uris draco >/dev/null 2>&1; then
    need_root "enable deb-src"
    if [ -f /etc/apt/sources.list.d/debian.sources ]; then
      sed -e 's/^Types: deb$/Types: deb-src/' /etc/apt/sources.list.d/debian.sources |
        $SUDO tee /etc/apt/sources.list.d/prtfarm-deb-src.sources >/dev/null
    elif [ -f /etc/apt/sources.list ]; then
      sed -n 's/^deb /deb-src /p' /etc/apt/sources.list |
        $SUDO tee /etc/apt/sources.list.d/prtfarm-deb-src.list >/dev/null
    fi
    $SUDO apt-get update -qq
  fi
  mkdir -p "$SRC"
  (
    cd "$SRC"
    have_source draco || apt-get source -qq draco
    # The security archive may list a libzstd whose source is not on the mirror: fall back to
    # bookworm's own version, which is the same 1.5.4 code.
    have_source libzstd || apt-get source -qq libzstd ||
      apt-get source -qq "libzstd=$(apt-cache showsrc libzstd | sed -n 's/^Version: //p' | sort -V | head -1)"
  )
fi

# ---- The web page's npm packages, as pinned in web/package-lock.json -----------------------------
# npm writes node_modules/.package-lock.json on every install: older than the lock, or missing,
# means web/package-lock.json changed since (or nothing was installed).
if [ ! -f "$ROOT/web/node_modules/.package-lock.json" ] ||
   [ "$ROOT/web/package-lock.json" -nt "$ROOT/web/node_modules/.package-lock.json" ]; then
  echo "install-deps: npm ci in web/"
  (cd "$ROOT/web" && npm ci --no-audit --no-fund --loglevel=error)
fi
