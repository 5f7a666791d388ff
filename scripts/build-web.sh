#!/usr/bin/env bash
# Builds the web page (docs/web.md) into build-wasm/site: prt_runtime.wasm + .js from runtime/
# with Debian's Emscripten, the page (web/index.html, web/js/) and three.js from web/node_modules.
# Idempotent: configures build-wasm once, rebuilds only what changed, copies the page again.
# Needs what scripts/install-deps.sh installs (emscripten, the draco and libzstd source packages
# in build-wasm/src, `npm ci` in web/).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
WASM_DIR="${PRT_WASM_BUILD_DIR:-$ROOT/build-wasm}"
SITE="$WASM_DIR/site"

for tool in emcmake emcc; do
  command -v "$tool" >/dev/null 2>&1 || {
    echo "build-web: $tool not found (scripts/install-deps.sh installs emscripten)" >&2
    exit 1
  }
done
[ -f "$ROOT/web/node_modules/three/build/three.module.js" ] || {
  echo "build-web: web/node_modules/three missing (scripts/install-deps.sh runs npm ci in web/)" >&2
  exit 1
}

# Emscripten's JS optimiser needs acorn: Debian's node-acorn (a dependency of emscripten) lives in
# /usr/share/nodejs, which a node not from Debian does not search by itself.
export NODE_PATH="/usr/share/nodejs${NODE_PATH:+:$NODE_PATH}"
if [ ! -f "$WASM_DIR/CMakeCache.txt" ]; then
  emcmake cmake -S "$ROOT/web/wasm" -B "$WASM_DIR" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release \
    -DPRT_WASM_DEPS_DIR="$WASM_DIR/src"
fi
cmake --build "$WASM_DIR" -j "$JOBS"

# The site: the page, its scripts, the module and three.js (nothing fetched from elsewhere).
mkdir -p "$SITE/js" "$SITE/three"
cp "$ROOT/web/index.html" "$ROOT/web/style.css" "$SITE/"
cp "$ROOT"/web/js/*.js "$SITE/js/"
cp "$WASM_DIR/prt_runtime.js" "$WASM_DIR/prt_runtime.wasm" "$SITE/js/"
cp "$ROOT/web/node_modules/three/build/three.module.js" \
  "$ROOT/web/node_modules/three/build/three.core.js" "$SITE/three/"
echo "build-web: $SITE"
