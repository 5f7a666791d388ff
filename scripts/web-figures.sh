#!/usr/bin/env bash
# The web page's figures (docs/web.md, "Figures"): the WebAssembly runtime in headless Chromium
# against the native C API on one thread, on the demo pack under sunrise.hdr.
#   in the page (web/test/page_test.mjs --measure): exact relight, a PBI frame at the default
#     budget (100 terms), set_rotation_y with the full map and with preview, page load → first
#     frame, bytes downloaded, fps and the split of a frame while the page's loop rotates the
#     environment (prtPage.spin), while it only draws, and while puppeteer drags;
#   native (build/bench/prt-runtime-bench, the same pack and .hdr): the same relights and the
#     rotation's lighting per frame.
# Usage: scripts/web-figures.sh [PACK] (default demo-out/default.prtpack, from scripts/demo.sh).
# PRT_WEB_SCREENSHOT=path also saves the page after the drag (docs/images/web-runtime.png).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
PACK="${1:-${PRT_DEMO_OUT:-$ROOT/demo-out}/default.prtpack}"
[ -f "$PACK" ] || { echo "web-figures: no pack at $PACK (scripts/demo.sh makes it)" >&2; exit 1; }
configure_and_build >/dev/null
"$ROOT/scripts/build-web.sh" >/dev/null
SITE="${PRT_WASM_BUILD_DIR:-$ROOT/build-wasm}/site"
mkdir -p "$SITE/data"
ENV="$SITE/data/sunrise.hdr"
[ -f "$ENV" ] || "$BUILD_DIR/viewer/prt-env-hdr" "$BUILD_DIR/data/envmaps/sunrise.exr" "$ENV" >/dev/null
OUT="${PRT_BENCH_OUT:-$ROOT/bench-out}/web"
mkdir -p "$OUT"

echo "== the page in headless Chromium (WebAssembly, one thread): $PACK =="
node "$ROOT/web/test/page_test.mjs" --site "$SITE" --pack "$PACK" --env "$ENV" --exposure 0.45 \
  --out-dir "$OUT" --measure ${PRT_WEB_SCREENSHOT:+--screenshot "$PRT_WEB_SCREENSHOT"} |
  grep -v '^ok ' >"$OUT/page.json"
node -e '
const s = JSON.parse(require("fs").readFileSync(process.argv[1], "utf8"));
const f = (x, d = 1) => x.toFixed(d);
console.log(`samples ${s.samples}, n = ${s.n}, budget ${s.budget} terms`);
const r = s.relightMs;
console.log(`relight, median of ${s.frames} frames under a rotating map (as prt-runtime-bench):`);
console.log(`  exact ${f(r[0], 2)} ms, PBI-30 ${f(r[30], 2)} ms, PBI-100 ${f(r[100], 2)} ms, PBI-300 ${f(r[300], 2)} ms`);
console.log(`set_rotation_y           ${f(s.rotateFullMs)} ms full map, ${f(s.rotatePreviewMs)} ms with preview`);
const byWidth = Object.entries(s.rotateByMapWidthMs).sort((x, y) => y[0] - x[0])
    .map(([w, ms]) => `${w} × ${w / 2} ${f(ms)} ms`).join(", ");
console.log(`set_rotation_y by map    ${byWidth} (no preview)`);
console.log(`load → first frame       ${f(s.loadToFirstFrameMs, 0)} ms (open ${f(s.openMs, 0)} ms)`);
const L = s.load, at = (x) => f(x, 0);
console.log(`  milestones (ms)        script ${at(L.scriptStart)}, wasm ready ${at(L.moduleReady)}, fetched ${at(L.fetched)}, map parsed ${at(L.mapParsed)}, pack opened ${at(L.opened)}, view ${at(L.viewReady)}, map set ${at(L.environmentSet)}, first frame ${at(L.firstFrame)}`);
console.log(`downloaded               ${f(s.bytesDownloaded / 1e6, 2)} MB`);
console.log(`drag (${s.dragFrames} frames)       ${f(s.dragFps)} fps; median frame ${f(s.dragFrameMedianMs)} ms = rotate ${f(s.dragRotateMedianMs)} + relight ${f(s.dragRelightMedianMs)} + draw ${f(s.dragDrawMedianMs)} ms`);
const sp = s.spin, sd = s.spinDrawOnly;
console.log(`page loop rotating       ${f(sp.fps)} fps (${sp.frames} frames; median rotate ${f(sp.rotateMs, 2)} + relight ${f(sp.relightMs, 2)} + draw ${f(sp.drawMs, 2)} ms)`);
console.log(`  drawing alone          ${f(sd.fps)} fps (no relight; draw ${f(sd.drawMs, 2)} ms); an empty animation frame loop ${f(s.rafOnlyFps)} fps`);
console.log(`memory                   ${f(s.memoryBytes / 1048576)} MiB in the handle, ${f(s.wasmHeapBytes / 1048576, 0)} MiB wasm heap`);
' "$OUT/page.json"
echo
echo "== native: prt-runtime-bench (the C API, same pack and .hdr) =="
"$BUILD_DIR/bench/prt-runtime-bench" "$PACK" "$ENV" 2>/dev/null | grep -v '\[info\]' | sed -n '1,5p'
