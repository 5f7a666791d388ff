#!/bin/sh
# The web_page test (docs/web.md "The test"): builds the page if needed (scripts/build-web.sh,
# a no-op when it is up to date), then web/test/page_test.mjs drives /usr/bin/chromium over it
# with the fixture's pack (tests/web_page_pack.sh). Fails, never skips, when Chromium, node, the
# npm packages or Emscripten are missing: scripts/install-deps.sh installs them.
#   web_page_test.sh SOURCE_DIR FIXTURE_WORK OUT_DIR IMAGE_PACK PRT_VIEW
set -eu
src=$1 work=$2 out=$3 image_pack=$4 view=$5
missing=""
[ -x /usr/bin/chromium ] || missing="$missing chromium"
command -v node >/dev/null 2>&1 || missing="$missing node"
command -v emcc >/dev/null 2>&1 || missing="$missing emscripten"
[ -d "$src/web/node_modules/puppeteer-core" ] || missing="$missing web/node_modules (npm ci)"
if [ -n "$missing" ]; then
  echo "web_page: missing:$missing — run scripts/install-deps.sh" >&2
  exit 1
fi
"$src/scripts/build-web.sh" >"$out.build.log" 2>&1 || {
  tail -30 "$out.build.log" >&2
  echo "web_page: scripts/build-web.sh failed (log: $out.build.log)" >&2
  exit 1
}
site="${PRT_WASM_BUILD_DIR:-$src/build-wasm}/site"
exec node "$src/web/test/page_test.mjs" --site "$site" --pack "$work/web_bunny.prtpack" \
  --env "$work/sunrise.hdr" --reference "$work/prt-view.png" --exposure 0.45 \
  --corrupt "$work/corrupt.prtpack" --bad-env "$work/truncated.hdr" --image-pack "$image_pack" \
  --image-reference "$work/prt-view-image.png" --glossy-pack "$work/web_glossy.prtpack" \
  --glossy-reference "$work/prt-view-glossy.png" --terms-pack "$work/web_terms.prtpack" \
  --terms-reference "$work/prt-view-terms.png" --prt-view "$view" --out-dir "$out"
