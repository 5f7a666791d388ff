#!/usr/bin/env bash
# Image runs (samples = "camera") against Blender Cycles camera renders (issue 40,
# docs/image-relighting.md "Checked against Cycles"). Called by `scripts/bench.sh camera`; runs on
# its own after a build:
#
#   bench/cycles/run.sh BUILD_DIR OUT_DIR
#
# Each case is "name|scene|cycles diffuse bounces|cycles glossy bounces|pixel"
# A vertex run's scene (glossy vertex transport, docs/glossy-transport.md) is rendered by
# prt-view from its [camera]; its pixels' meshes come from Cycles' index pass.
# (pixel: centre = one ray through the pixel centre, box = the pixel's footprint)
# (PRT_CAMERA_CASES, space-separated, replaces the list). Per case: prt-farm (2 ranks) farms the
# image scene, prt-pack packs it, bench/cycles/export_scene.py writes the run's own world-space
# geometry, camera and materials for Blender, and per environment of PRT_CAMERA_ENVS (names in
# BUILD_DIR/data/envmaps/): prt-view --exact writes the linear EXR, bench/cycles/render_camera.py
# renders it in Cycles with seeds 1 and 2 at PRT_CAMERA_SAMPLES samples per pixel, and
# bench/cycles/compare.py gives the noise-corrected relative RMS error on the model and the
# ground pixels, the error map and prtfarm | Cycles | error PNGs. A case whose scene prt-farm
# refuses (a feature not built) prints the refusal as its row and the others go on. Finished
# farm runs and Cycles renders are reused (delete OUT_DIR/<case> to redo one). Installs blender
# and python3-numpy if missing.
#
# Cost on the shared 2-core VM (160×120, 512 samples, four environments; measured 5 Dec 2026):
# prt-farm 8–40 s per case except path-k2-brute16 (134 s: every pixel path traces), a Cycles
# render 5–25 s at max bounces 0 or 2 diffuse bounces plus a few seconds of Blender start; the
# whole command about 15 min from nothing. Output: OUT_DIR/<case>/ (run/, <case>.prtpack, cycles/,
# <env>-prt.exr, <env>-compare.json, <env>-side.png, <env>-error.png) and OUT_DIR/table.txt.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
BUILD_DIR="$(cd "${1:?usage: run.sh BUILD_DIR OUT_DIR}" && pwd)"
OUT="${2:?usage: run.sh BUILD_DIR OUT_DIR}"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_pml=ob1 OMPI_MCA_btl=self,vader OMPI_MCA_rmaps_base_oversubscribe=1
export PRT_DATA_PATH="$BUILD_DIR/data${PRT_DATA_PATH:+:$PRT_DATA_PATH}"
CAMERA_CASES_DEFAULT=(
  "direct|scenes/bench/bunny-direct.toml|0|0|centre"
  "path-k2|scenes/bench/bunny-path-k2.toml|2|0|centre"
  "gather-k2|scenes/bench/bunny-gather-k2.toml|2|0|centre"
  "gather-k2-brute16|scenes/bench/bunny-gather-k2-brute16.toml|2|0|centre"
  "path-k2-brute16|scenes/bench/bunny-path-k2-brute16.toml|2|0|centre"
  "supersample-4|scenes/bench/bunny-ss4.toml|0|0|box"
  "ggx-k0|scenes/bench/bunny-ggx-k0.toml|0|0|centre"
  "ggx-k2|scenes/bench/bunny-ggx-k2.toml|2|1|centre"
)
dir="$OUT" shared="${PRT_SHARED_DATA:-$ROOT/../shared/data}"
samples="${PRT_CAMERA_SAMPLES:-512}" envs="${PRT_CAMERA_ENVS:-sunrise city studio interior}"
py=/usr/bin/python3 cases=("${CAMERA_CASES_DEFAULT[@]}")
[ -n "${PRT_CAMERA_CASES:-}" ] && read -r -a cases <<< "$PRT_CAMERA_CASES"
if ! command -v blender >/dev/null 2>&1 || ! "$py" -c 'import numpy' 2>/dev/null; then
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo=sudo
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq blender python3-numpy
fi
mkdir -p "$dir"
[ -n "${PRT_CAMERA_APPEND:-}" ] || : > "$dir/results.list"  # PRT_CAMERA_APPEND=1: add to the table
for spec in "${cases[@]}"; do
  name="" scene="" dbounce="" gbounce="" pixel=""
  IFS='|' read -r name scene dbounce gbounce pixel <<< "$spec"
  cdir="$dir/$name" run="$dir/$name/run"
  mkdir -p "$cdir"
  echo "== camera case $name: $scene (Cycles: diffuse bounces $dbounce, glossy $gbounce, pixel $pixel, $samples samples) =="
  if [ ! -f "$run/report.json" ] || [ "$ROOT/$scene" -nt "$run/report.json" ]; then
    rm -rf "$cdir/cycles"  # renders of an older run of this case are stale
    if ! PRT_DATA_PATH="$PRT_DATA_PATH:$shared" nice mpirun -np 2 --bind-to none \
        "$BUILD_DIR/farm/prt-farm" "$ROOT/$scene" --out "$run" --force -q > "$cdir/farm.log" 2>&1; then
      echo "$name|not run: $(grep -m1 -i 'error' "$cdir/farm.log" | cut -c1-160)" >> "$dir/results.list"
      echo "  prt-farm refused $scene: $(grep -m1 -i 'error' "$cdir/farm.log" | cut -c1-200)"
      continue
    fi
  fi
  "$BUILD_DIR/packager/prt-pack" pack "$run" --out "$cdir/$name.prtpack" > /dev/null
  "$py" "$ROOT/bench/cycles/export_scene.py" "$run" --out "$cdir/cycles"
  for env in $envs; do
    map="$BUILD_DIR/data/envmaps/$env.exr"
    "$BUILD_DIR/viewer/prt-view" "$cdir/$name.prtpack" --env "$map" --exact \
      --exr "$cdir/$env-prt.exr" --quiet 2>/dev/null
    for seed in 1 2; do
      render="$cdir/cycles/$env-s$seed-n$samples-$pixel.exr" index=()
      [ "$seed" = 1 ] && index=(--index-out "$cdir/cycles/index.exr")
      [ -f "$render" ] || nice blender -b --factory-startup --python-exit-code 1 --python \
        "$ROOT/bench/cycles/render_camera.py" -- --scene "$cdir/cycles/scene.json" --env "$map" \
        --out "$render" --samples "$samples" --seed "$seed" --bounces "$dbounce" \
        --glossy-bounces "$gbounce" --pixel "$pixel" "${index[@]}" > "$render.log" 2>&1 ||
        { tail -20 "$render.log"; echo "render_camera.py failed: $render.log" >&2; exit 1; }
      [ -f "$render.log" ] && grep 'render_camera.py:' "$render.log" || true
      # A vertex run (glossy vertex transport): the pixels' meshes from Cycles' index pass.
      if [ "$seed" = 1 ] && grep -q '"vertex_run": true' "$cdir/cycles/scene.json"; then
        "$py" - "$cdir/cycles/index.exr" "$cdir/cycles/pixel_mesh.bin" "$ROOT/bench/cycles" <<'PY'
import sys
sys.path.insert(0, sys.argv[3])
import numpy as np, exrio
idx = np.rint(exrio.read_rgb(sys.argv[1])[:, :, 0]).astype(np.int64) - 1
idx[idx < 0] = 0xFFFFFFFF
idx.astype("<u4").tofile(sys.argv[2])
PY
      fi
    done
    "$py" "$ROOT/bench/cycles/compare.py" --prt "$cdir/$env-prt.exr" \
      --cycles "$cdir/cycles/$env-s1-n$samples-$pixel.exr" "$cdir/cycles/$env-s2-n$samples-$pixel.exr" \
      --scene "$cdir/cycles/scene.json" --index "$cdir/cycles/index.exr" --label "$name/$env" \
      --json "$cdir/$env-compare.json" --png-prefix "$cdir/$env"
    echo "$name|$cdir/$env-compare.json" >> "$dir/results.list"
  done
done
"$py" - "$dir/results.list" <<'PY' | tee "$dir/table.txt"
import json, sys
print(f"{'case / environment':<24} {'group':<16} {'pixels':>6} {'rel err':>8} {'plain':>7} {'noise':>7} "
    f"{'R':>6} {'G':>6} {'B':>6} {'P/ref':>7}")
for line in open(sys.argv[1]):
  name, what = line.rstrip("\n").split("|", 1)
  if not what.endswith(".json"):
      print(f"{name:<24} {what}")
      continue
  d = json.load(open(what))
  for g in ("model", "ground", "model-interior", "ground-interior"):
      s = d["groups"].get(g)
      if s:
          a = s["all"]
          print(f"{d['label']:<24} {g:<16} {s['pixels']:>6} {100 * a['rel']:>7.2f}% "
                f"{100 * a['plain']:>6.2f}% {100 * a['noise']:>6.2f}% "
                + " ".join(f"{100 * s[c]['rel']:>5.2f}%" for c in "RGB")
                + f" {a['mean_ratio']:>7.4f}")
  bg, ia = d.get("background_check"), d.get("index_agreement")
  print(f"{'':<24} checks: background (environment orientation) {100 * bg['all']['plain']:.2f}%"
        + (f", Cycles pixel mesh = image.prti on {ia['pixels']}/{ia['of']}" if ia else ""))
print("rel err = sqrt(max(mean((P-R)^2) - mean((A-B)^2)/4, 0) / mean(R^2)), R = (A+B)/2 of two "
    "Cycles seeds; plain = before the noise correction; noise = sqrt(mean((A-B)^2)/4 / mean(R^2))")
PY
