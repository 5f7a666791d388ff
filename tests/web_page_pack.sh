#!/bin/sh
# Fixture of the web_page test (tests/CMakeLists.txt, docs/web.md): bakes tests/data/web_bunny.toml
# with prt-farm on 2 ranks and packs it, writes sunrise.exr as the page's .hdr, renders prt-view's
# reference image of the pack (its camera, exact lighting, exposure 0.45) from that .hdr and its
# image of a small image pack (runtime/fuzz_corpus/image.prtpack, 24 × 16 pixels); a copy of the
# pack with one byte of a transport block flipped, and the .hdr cut short; a small glossy pack
# (GLOSSY_SCENE: visibility, no transport) and prt-view's image of it from its camera.
#   web_page_pack.sh MPIEXEC NUMPROC_FLAG PRT_FARM PRT_PACK PRT_VIEW PRT_ENV_HDR SCENE ENV_EXR
#                    IMAGE_PACK WORK GLOSSY_SCENE
set -eu
mpiexec=$1 np_flag=$2
shift 2
farm=$1 pack=$2 view=$3 env_hdr=$4 scene=$5 env_exr=$6 image_pack=$7 work=$8 glossy_scene=$9
rm -rf "$work"
mkdir -p "$work"
"$mpiexec" "$np_flag" 2 "$farm" "$scene" --out "$work/run" --force --quiet
"$pack" pack "$work/run" --out "$work/web_bunny.prtpack"
"$env_hdr" "$env_exr" "$work/sunrise.hdr"
"$view" "$work/web_bunny.prtpack" --env "$work/sunrise.hdr" --exact --exposure 0.45 \
  --out "$work/prt-view.png" --quiet
"$view" "$image_pack" --env "$work/sunrise.hdr" --exact --exposure 0.45 \
  --out "$work/prt-view-image.png" --quiet
# The corrupt pack: the byte in the middle of the file (inside the transport, whose block
# checksums the runtime verifies on opening) XOR 0x5a.
size=$(wc -c <"$work/web_bunny.prtpack")
cp "$work/web_bunny.prtpack" "$work/corrupt.prtpack"
mid=$((size / 2))
byte=$(od -An -tu1 -j "$mid" -N1 "$work/web_bunny.prtpack" | tr -d ' ')
printf "$(printf '\\%03o' $((byte ^ 90)))" |
  dd of="$work/corrupt.prtpack" bs=1 seek="$mid" count=1 conv=notrunc status=none
cmp -s "$work/web_bunny.prtpack" "$work/corrupt.prtpack" && { echo "corrupt copy unchanged" >&2; exit 1; }
# The glossy pack (per-vertex visibility at n = 32, about a second) and prt-view's image of it.
"$mpiexec" "$np_flag" 2 "$farm" "$glossy_scene" --out "$work/run-glossy" --force --quiet
"$pack" pack "$work/run-glossy" --out "$work/web_glossy.prtpack"
"$view" "$work/web_glossy.prtpack" --env "$work/sunrise.hdr" --exposure 0.45 \
  --out "$work/prt-view-glossy.png" --quiet
# A glossy vertex pack (BRDF terms: runtime/fuzz_corpus/glossy_terms.prtpack, next to IMAGE_PACK)
# and prt-view's exact image of it from its camera.
cp "$(dirname "$image_pack")/glossy_terms.prtpack" "$work/web_terms.prtpack"
"$view" "$work/web_terms.prtpack" --env "$work/sunrise.hdr" --exact --exposure 0.45 \
  --out "$work/prt-view-terms.png" --quiet
# A map cut short in its scanlines.
head -c 100000 "$work/sunrise.hdr" >"$work/truncated.hdr"
echo "web_page_pack: $work/web_bunny.prtpack ($size bytes), sunrise.hdr, prt-view.png, prt-view-image.png, corrupt.prtpack, truncated.hdr, web_glossy.prtpack, prt-view-glossy.png"
