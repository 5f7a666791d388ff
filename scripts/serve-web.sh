#!/usr/bin/env bash
# Serves the web page (docs/web.md) on localhost with the demo pack and an environment map:
# builds the page if needed (scripts/build-web.sh), puts the demo pack (demo-out/default.prtpack,
# from scripts/demo.sh) and sunrise.hdr / city.hdr (Blender's maps as Radiance .hdr, written by
# prt-env-hdr) under site/data/, prints the URL and runs python3 -m http.server until Ctrl-C.
#   scripts/serve-web.sh [PORT]     (default 8000; PRT_WEB_PACK=... serves another pack)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
PORT="${1:-${PRT_WEB_PORT:-8000}}"
SITE="${PRT_WASM_BUILD_DIR:-$ROOT/build-wasm}/site"
PACK="${PRT_WEB_PACK:-${PRT_DEMO_OUT:-$ROOT/demo-out}/default.prtpack}"

"$ROOT/scripts/build-web.sh"
mkdir -p "$SITE/data"
if [ ! -x "$BUILD_DIR/viewer/prt-env-hdr" ]; then
  configure_and_build
fi
for env in sunrise city; do
  if [ ! -f "$SITE/data/$env.hdr" ]; then
    "$BUILD_DIR/viewer/prt-env-hdr" "$BUILD_DIR/data/envmaps/$env.exr" "$SITE/data/$env.hdr"
  fi
done
if [ -f "$PACK" ]; then
  ln -sf "$(cd "$(dirname "$PACK")" && pwd)/$(basename "$PACK")" "$SITE/data/default.prtpack"
  QUERY="?pack=data/default.prtpack&env=data/sunrise.hdr&exposure=0.45"
else
  echo "serve-web: no pack at $PACK (scripts/demo.sh makes it): open one from the page" >&2
  QUERY=""
fi
echo
echo "Serving $SITE"
echo "  open http://localhost:$PORT/index.html$QUERY"
echo "  (city: env=data/city.hdr&exposure=0.25; Ctrl-C stops)"
cd "$SITE"
exec python3 -m http.server "$PORT" --bind 127.0.0.1
