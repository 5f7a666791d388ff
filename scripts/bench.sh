#!/usr/bin/env bash
# Long benchmarks, never part of the test suite. Each prints ratios measured in one run on this
# machine (against raw Embree, against brute force, against the 2D baseline), because the
# machines are shared and noisy. Usage: scripts/bench.sh [all|transport|scaling|million|sparse|compression|cpca|compress|figure9|viewer|relight|runtime|glossy|tp|sweep|stress|rebake|mc-error|gi|sparse-gi|image|camera|supersample|glossy-cycles|glossy-terms] [--quick]
# `sweep` is prt-bench (docs/benchmarks.md): every setting's run time against error, Pareto fronts
# and plots in $OUT/prt-bench; PRT_BENCH_NP=K runs it under mpirun -np K, PRT_BENCH_ARGS adds options.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$ROOT/scripts/install-deps.sh"
configure_and_build
export PRT_DATA_PATH="$BUILD_DIR/data${PRT_DATA_PATH:+:$PRT_DATA_PATH}"
OUT="${PRT_BENCH_OUT:-$ROOT/bench-out}"
WHAT="${1:-all}"
QUICK=""
[ "${2:-}" = "--quick" ] && QUICK="--quick"
mkdir -p "$OUT"

run_transport() {
  echo "== transport sampling against raw Embree on the same rays =="
  "$BUILD_DIR/bench/transport_bench"
}

# The farm's scaling (docs/farm.md, "Scaling"): the demo scene (sparse method and two bounces)
# and the same scene by brute force, one thread per rank, with mpirun -np 1 2 4 8 16
# (PRT_SCALING_NP; PRT_SCALING_METHODS="sparse brute"; beyond the cores the ranks share them, so
# the wall time measures the overhead of more ranks, not a speed-up). Prints per rank count the
# wall times, the coordinator's CPU per job, rank 0's bytes per row (all job traffic, and the
# compression's reads and sends), every rank's peak memory and the checksums of transport.prtt
# and transport.prtc, which must be the same for every rank count. PRT_SCALING_ARGS adds
# prt-farm options (e.g. --rows-via-rank0 to measure the old funnel).
run_scaling() {
  local nps="${PRT_SCALING_NP:-1 2 4 8 16}"
  local rpt="${PRT_SCALING_RAYS_PER_TEXEL:-1}"
  for method in ${PRT_SCALING_METHODS:-sparse brute}; do
    echo "== prt-farm scaling, method $method: mpirun -np ${nps// /, }, one thread per rank, ${rpt} ray(s) per texel =="
    for np in $nps; do
      mpirun -np "$np" --oversubscribe --bind-to none "$BUILD_DIR/farm/prt-farm" \
        --out "$OUT/scaling-$method-np$np" --force --threads 1 --method "$method" \
        --rays-per-texel "$rpt" ${PRT_SCALING_ARGS:-} -q
    done
    python3 - "$OUT/scaling-$method" $nps <<'PY'
import hashlib, json, sys
out, nps = sys.argv[1], [int(x) for x in sys.argv[2:]]
def phase(d, name):
    return sum(p["wall_seconds"] for p in d["phases"] if p["name"] == name)
def md5(path):
    h = hashlib.md5()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:12]
print(f"{'ranks':>5} {'wall s':>7} {'rows s':>7} {'bounces s':>9} {'compress s':>10} "
      f"{'jobs':>5} {'coord ms/job':>12} {'r0 B/row jobs':>13} {'r0 B/row compress':>17} "
      f"{'peak MiB max':>12} {'transport.prtt':>14} {'transport.prtc':>14}")
base = None
for np in nps:
    run = f"{out}-np{np}"
    d = json.load(open(f"{run}/report.json"))
    batches = d["coordinator"]["batches"]
    jobs = sum(b["jobs"] for b in batches)
    cpu = sum(b["cpu_seconds"] for b in batches)
    traffic = sum(b["bytes_in"] + b["bytes_out"] for b in batches)
    c = d["compression"]
    rows = d["rows"]
    r0c = (c.get("rank0_bytes_read", 0) + c.get("rank0_bytes_sent", 0)) / rows
    peak = max(x["peak_rss_bytes"] for x in d["rank_details"]) / 2**20
    sums = (md5(f"{run}/transport.prtt"), md5(f"{run}/transport.prtc"))
    base = base or sums
    rows_s = phase(d, d["method"]) + phase(d, "finalize")
    bounce_s = sum(p["wall_seconds"] for p in d["phases"] if p["name"].startswith(("bounce", "path-trace")))
    print(f"{np:>5} {d['wall_seconds']:>7.1f} {rows_s:>7.1f} {bounce_s:>9.1f} "
          f"{phase(d, 'compress'):>10.1f} {jobs:>5} {1e3 * cpu / max(1, jobs):>12.3f} "
          f"{traffic / rows:>13.2f} {r0c:>17.0f} {peak:>12.0f} {sums[0]:>14} {sums[1]:>14}"
          + ("" if sums == base else "  DIFFERS"))
print(f"rows {rows}, row bytes {4 * d['cols']}; r0 B/row jobs = rank 0's job and result bytes "
      f"with the other ranks per row, all batches; r0 B/row compress = rank 0's reads + sends in "
      f"the transpose per row of T (its own share once every rank reads its rows)")
PY
  done
}

# The million-vertex memory case (docs/farm.md, "Memory"): scenes/million.toml with 2 ranks and
# --memory-budget 16M, 64M, 256M (PRT_MILLION_BUDGETS), and once without the compression; prints
# each rank's peak resident memory, peak − budget, the bytes spilled and the compression's time.
run_million() {
  local budgets="${PRT_MILLION_BUDGETS:-16M 64M 256M}"
  echo "== prt-farm on 1,026,002 vertices (scenes/million.toml), 2 ranks =="
  mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" "$ROOT/scenes/million.toml" \
    --out "$OUT/million-none" --force --no-compress -q
  for b in $budgets; do
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" "$ROOT/scenes/million.toml" \
      --out "$OUT/million-$b" --force --memory-budget "$b" -q
  done
  python3 - "$OUT" none $budgets <<'PY'
import json, sys
out, budgets = sys.argv[1], sys.argv[2:]
mult = {"k": 2**10, "M": 2**20, "G": 2**30}
print(f"{'budget':>7} {'rank 0 MiB':>10} {'rank 1 MiB':>10} {'peak-budget MiB':>15} {'spilled MiB':>11} {'compress s':>10}")
for b in budgets:
    d = json.load(open(f"{out}/million-{b}/report.json"))
    peaks = [x["peak_rss_bytes"] / 2**20 for x in d["rank_details"]]
    c = d.get("compression", {})
    budget = 0 if b == "none" else int(b[:-1]) * mult[b[-1]] / 2**20
    comp = next((p["wall_seconds"] for p in d["phases"] if p["name"] == "compress"), 0.0)
    print(f"{b:>7} {peaks[0]:>10.0f} {peaks[1]:>10.0f} {max(peaks) - budget:>15.0f} "
          f"{c.get('spill_bytes', 0) / 2**20:>11.0f} {comp:>10.1f}")
print(f"rows {d['rows']}, n {d['cubemap_n']}")
PY
}

run_sparse() { "$BUILD_DIR/bench/prt-sparse-bench" --out "$OUT/sparse" $QUICK; }
run_compression() { "$BUILD_DIR/bench/compression_bench"; }
# Clustered PCA (issue #24, docs/cpca.md): prt-cpca-bench on the default scene, the dragon and the
# armadillo at n = 32: bytes and relight time against relit error next to adaptive 4D and 2D (and
# the ratios at equal error), incremental CPCA relighting under a rotating environment, Huang §6's
# compression time against standard CPCA on a sparse run's T. CSVs and PNGs in $OUT/cpca; the
# traced T is kept in $OUT/transport-cache (about 2 GB) for the next run. --quick: the default
# scene and a smaller grid (about 2.5 min).
run_cpca() {
  # shellcheck disable=SC2086
  "$BUILD_DIR/bench/prt-cpca-bench" --cache "$OUT/transport-cache" --out "$OUT/cpca" $QUICK
}
# Google Benchmark of the viewer's B = T·L and its fixed per-frame parts on the demo's pack
# (PRT_RELIGHT_PACK names another).
run_relight() {
  local pack="${PRT_RELIGHT_PACK:-$ROOT/demo-out/default.prtpack}"
  [ -f "$pack" ] || "$ROOT/scripts/demo.sh"
  "$BUILD_DIR/bench/relight_microbench" --benchmark_repetitions=5 \
    --benchmark_report_aggregates_only=true "$pack"
}
# Google Benchmark of the farm's per-column compression kernels on real columns: the raw T of a
# demo-scene farm run (made once in $OUT/compress-run; PRT_RAW_TRANSPORT
# names another transport.prtt).
run_compress() {
  local raw="${PRT_RAW_TRANSPORT:-$OUT/compress-run/transport.prtt}"
  if [ ! -f "$raw" ]; then
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" --out "$OUT/compress-run" --force \
      --keep-raw -q
  fi
  "$BUILD_DIR/bench/compress_microbench" --benchmark_repetitions=5 \
    --benchmark_report_aggregates_only=true "$raw"
}
# Cheslack-Postava et al. Figure 9 on the T the farm ships: viewer_bench's 2D/4D sweep on the raw
# T of a default-scene farm run (the one run_compress keeps), with every image error also
# measured against an independent 64-ray brute-force estimate of T (made once, seed 7), so the
# table shows where compression error falls below the uncompressed T's own error.
run_figure9() {
  local raw="${PRT_RAW_TRANSPORT:-$OUT/compress-run/transport.prtt}"
  local truth="$OUT/truth-run/transport.prtt"
  if [ ! -f "$raw" ]; then
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" --out "$OUT/compress-run" --force \
      --keep-raw -q
  fi
  if [ ! -f "$truth" ]; then
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" --out "$OUT/truth-run" --force \
      --method brute --rays-per-texel 64 --seed 7 --no-compress -q
  fi
  "$BUILD_DIR/bench/viewer_bench" --raw "$raw" --truth "$truth" --frames 0 --hold 0 \
    --sweep-4d 0.003,0.01,0.03,0.05,0.1 --out-dir "$OUT/figure9" $QUICK
}
run_viewer() { [ -x "$BUILD_DIR/bench/viewer_bench" ] && "$BUILD_DIR/bench/viewer_bench" || echo "viewer_bench not built"; }
run_sweep() {
  local np="${PRT_BENCH_NP:-1}" launch=()
  [ "$np" -gt 1 ] && launch=(mpirun -np "$np" --bind-to none)
  # shellcheck disable=SC2086
  "${launch[@]}" "$BUILD_DIR/bench/prt-bench" --out "$OUT/prt-bench" $QUICK ${PRT_BENCH_ARGS:-}
}
# Issue 9's long stress versions of suite tests: 100,000 frames of incremental lighting (BI and
# PBI) without drift.
run_stress() {
  PRT_STRESS_FRAMES="${PRT_STRESS_FRAMES:-100000}" "$BUILD_DIR/viewer/viewer_tests" \
    --gtest_filter='PerBandIncrementalTest.*Drift*'
}
# Issue 27's table: each kind of scene edit of a finished default-scene run, what --resume re-ran,
# the rays it traced and its wall time against the fresh run (scripts/rebake_bench.py).
run_rebake() { python3 "$ROOT/scripts/rebake_bench.py" "$BUILD_DIR" "$OUT/rebake" --np 2; }
# The farm's error estimates (accuracy.json) against measured differences (prt-mc-check), on the
# default scene and the dragon: two brute-force seeds (the Monte-Carlo estimate), the sparse
# method against brute force (its total: rays and reconstruction), two sparse seeds.
run_mc_error() {
  local dir="$OUT/mc-error" scenes=(default dragon) methods=(brute sparse)
  mkdir -p "$dir"
  sed 's|"meshes/bunny00.off"|"meshes/ChineseDragon-10kv.off"|; s|name = "bunny"|name = "dragon"|'     "$ROOT/scenes/default.toml" > "$dir/dragon.toml"
  for scene in "${scenes[@]}"; do
    local file="$ROOT/scenes/default.toml"
    [ "$scene" = dragon ] && file="$dir/dragon.toml"
    for method in "${methods[@]}"; do
      for seed in 1 2; do
        local run="$dir/$scene-$method-s$seed"
        [ -f "$run/accuracy.json" ] || mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm"           "$file" --out "$run" --force --method "$method" --seed "$seed" --no-compress -q
      done
      echo "== $scene, $method seed 1 against $method seed 2 =="
      "$BUILD_DIR/bench/prt-mc-check" "$dir/$scene-$method-s1" "$dir/$scene-$method-s2"
    done
    echo "== $scene, sparse seed 1 against brute force seed 2 =="
    "$BUILD_DIR/bench/prt-mc-check" "$dir/$scene-sparse-s1" "$dir/$scene-brute-s2"
  done
}
# Issue 22's figures (docs/interreflection.md "Measured"): bounce gathering against the
# path-traced reference on the default scene and two more real meshes, K = 1 and 2, n = 32, four
# lights, model and ground apart, with images and the per-bounce energy plot; the colour-bleeding
# scene (a red ground); then prt-farm's wall time with K = 2 against K = 0 on the same 2 ranks.
# Image relighting (docs/image-relighting.md): each image scene farmed once (sparse, 2 ranks, raw
# T kept), then bytes against relit error for 2D, 4D and adaptive 4D on the image domain
# (compression_bench), relighting time at N = 30, 100, 300 at equal error (viewer_bench's
# Figure 9), the rotation run, the error image against the uncompressed T, and the image relit
# under four real environments plus a 36-frame rotation by prt-view. The teapot needs the shared
# data (PRT_SHARED_DATA, default ../shared/data); without it only the bunny runs.
run_image() {
  local shared="${PRT_SHARED_DATA:-$ROOT/../shared/data}" scenes=(bunny-image)
  [ -f "$shared/meshes/utah_teapot_24x24.obj" ] && scenes=(teapot bunny-image)
  for scene in "${scenes[@]}"; do
    local dir="$OUT/image/$scene" run="$OUT/image/$scene/run"
    mkdir -p "$dir"
    if [ ! -f "$run/transport.prtt" ] || [ ! -f "$run/image.prti" ]; then
      echo "== prt-farm $scene.toml, 2 ranks =="
      PRT_DATA_PATH="$PRT_DATA_PATH:$shared" mpirun -np 2 --bind-to none \
        "$BUILD_DIR/farm/prt-farm" "$ROOT/scenes/$scene.toml" --out "$run" --force --keep-raw -q
    fi
    echo "== $scene: bytes against relit error, 2D / 4D / adaptive 4D on the image =="
    "$BUILD_DIR/bench/compression_bench" --run "$run" --budget global \
      --keep 0.0003,0.0006,0.00125,0.0025,0.005,0.01,0.02,0.04,0.08 --out "$dir/compression" 2>&1 | grep -v '\[warning\]'
    echo "== $scene: relighting time at equal error (Figure 9), rotation, error image =="
    "$BUILD_DIR/bench/viewer_bench" --raw "$run/transport.prtt" --deg 1 --frames 60 --hold 30 \
      --sweep-4d 0.003,0.01,0.03 --sweep-2d 0.003,0.01,0.03,0.1,0.25 --out-dir "$dir/viewer" $QUICK \
      2>&1 | grep -v '\[warning\]'
    "$BUILD_DIR/packager/prt-pack" pack "$run" --out "$dir/$scene.prtpack" > /dev/null
    for env in sunrise city studio interior; do
      "$BUILD_DIR/viewer/prt-view" "$dir/$scene.prtpack" --env "$BUILD_DIR/data/envmaps/$env.exr" \
        --exact --out "$dir/$env.png" --quiet 2>/dev/null
    done
    "$BUILD_DIR/viewer/prt-view" "$dir/$scene.prtpack" --env "$BUILD_DIR/data/envmaps/sunrise.exr" \
      --rotate 10 --frames 36 --out-dir "$dir/rotation" --quiet 2>/dev/null
    echo "images: $dir/{sunrise,city,studio,interior}.png, $dir/rotation/, $dir/viewer/"
  done
}
run_sparse_gi() {
  # Sparse precomputation with interreflection against brute force of the same estimator
  # (docs/sparse-precomputation.md, "With interreflection"), one run per case.
  local dir="$OUT/sparse-gi" bench="$BUILD_DIR/bench/prt-sparse-gi-bench"
  mkdir -p "$dir"
  echo "== gather, n = 32: default, dragon, armadillo (the fixed budget and the features as variants) =="
  "$bench" --scenes default,dragon,armadillo --estimators gather --variant "rank_floor=0" \
    --variant "direct_weights=0" --out "$dir/gather32" 2>&1 | grep -v '\[info\]\|\[warning\]'
  echo "== path tracing (64 paths), n = 32: dragon, armadillo (the combination as a variant) =="
  "$bench" --scenes dragon,armadillo --estimators path --path-paths 64 --variant "direct_weights=1" \
    --out "$dir/path32" 2>&1 | grep -v '\[info\]\|\[warning\]'
  echo "== gather, n = 64: dragon, default (a quarter-resolution grid as a variant) =="
  "$bench" --scenes dragon,default --n 64 --estimators gather --variant "grid_step=4" \
    --out "$dir/gather64" 2>&1 | grep -v '\[info\]\|\[warning\]'
  echo "== time against error (docs/benchmarks.md) =="
  for scene in dragon armadillo default; do
    python3 "$ROOT/scripts/sparse_gi_pareto.py" "$dir" "$scene" "$dir/gather32/results.csv" \
      "$dir/path32/results.csv"
  done
  echo "== prt-farm, default scene, 2 ranks, K = 2: brute against sparse =="
  for m in brute sparse; do
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" --out "$dir/farm-$m" --force \
      --method "$m" --bounces 2 -q
  done
  python3 - "$dir" <<'PY'
import json, sys
d = sys.argv[1]
r = {m: json.load(open(f"{d}/farm-{m}/report.json")) for m in ("brute", "sparse")}
def phases(rep):
    return {p["name"]: p["wall_seconds"] for p in rep["phases"]}
for m in ("brute", "sparse"):
    print(m, {k: round(v, 1) for k, v in phases(r[m]).items()})
b, s = phases(r["brute"]), phases(r["sparse"])
rows_b = b.get("brute", 0.0)
rows_s = s.get("sparse", 0.0)
ind_b = sum(v for k, v in b.items() if k.startswith("bounce-"))
ind_s = sum(v for k, v in s.items() if k.startswith("bounce-"))
print(f"rows {rows_s:.1f} / {rows_b:.1f} s = {rows_s / rows_b:.3f}x; bounces {ind_s:.1f} / {ind_b:.1f} s = "
      f"{ind_s / ind_b:.3f}x; rows + bounces {(rows_s + ind_s) / (rows_b + ind_b):.3f}x")
PY
}

run_gi() {
  local dir="$OUT/gi" args="--bounces 2 --ref-vertices ${PRT_GI_REF_VERTICES:-48} --ref-paths ${PRT_GI_REF_PATHS:-1024} --images"
  mkdir -p "$dir"
  for scene in default dragon armadillo; do
    echo "== prt-gi-bench --scene $scene =="
    # shellcheck disable=SC2086
    "$BUILD_DIR/bench/prt-gi-bench" --scene "$scene" $args --out "$dir" 2>&1 | grep -v '\[info\]\|\[warning\]'
  done
  echo "== prt-gi-bench: colour bleeding (default scene, ground albedo 0.8, 0.25, 0.2) =="
  # shellcheck disable=SC2086
  "$BUILD_DIR/bench/prt-gi-bench" --scene default --ground-albedo 0.8,0.25,0.2 $args \
    --out "$dir/colour" 2>&1 | grep -v '\[info\]\|\[warning\]'
  echo "== prt-farm, default scene (brute), 2 ranks: K = 0 against K = 2 =="
  for k in 0 2; do
    mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" --out "$dir/farm-K$k" --force \
      --method brute --bounces "$k" -q
  done
  python3 - "$dir" <<'PY'
import json, sys
d = sys.argv[1]
r = {k: json.load(open(f"{d}/farm-K{k}/report.json")) for k in (0, 2)}
def phases(rep):
    return {p["name"]: p["wall_seconds"] for p in rep["phases"]}
p0, p2 = phases(r[0]), phases(r[2])
print(f"K = 0: wall {r[0]['wall_seconds']:.1f} s (brute {p0['brute']:.1f} s)")
print(f"K = 2: wall {r[2]['wall_seconds']:.1f} s (brute {p2['brute']:.1f} s, bounce-1 {p2['bounce-1']:.1f} s, bounce-2 {p2['bounce-2']:.1f} s)")
print(f"K = 2 / K = 0 wall time: {r[2]['wall_seconds'] / r[0]['wall_seconds']:.2f}x; "
      f"(brute + bounces) / brute of the same run: {(p2['brute'] + p2['bounce-1'] + p2['bounce-2']) / p2['brute']:.2f}x")
for s in r[2]["interreflection"]["indirect_share"]:
    print(f"  indirect share of B under {s['light']}: {100 * s['indirect_share']:.1f}%")
PY
}
# The embeddable runtime's C API against prt-view's relighter on the demo pack (docs/runtime.md,
# "Speed"): exact and PBI-30/100/300 frames, 1 thread, a 2-thread task runner, 2 host ranges.
run_runtime() {
  local pack="${PRT_RELIGHT_PACK:-$ROOT/demo-out/default.prtpack}"
  [ -f "$pack" ] || "$ROOT/scripts/demo.sh"
  "$BUILD_DIR/bench/prt-runtime-bench" "$pack" "$BUILD_DIR/data/envmaps/sunrise.exr" 40
}
run_glossy() { [ -x "$BUILD_DIR/bench/glossy_bench" ] && "$BUILD_DIR/bench/glossy_bench" --out "$OUT/glossy" || echo "glossy_bench not built"; }
# Triple products per frame (issue 41, docs/viewer.md "Triple products: where a frame goes"):
# before/after and each speedup alone, 1 and 2 threads, the whole frame, on the default scene,
# the armadillo and the dragon (visibility traced once into bench-out/glossy, shared with
# glossy_bench).
run_tp() { "$BUILD_DIR/bench/prt-tp-bench" --cache "$OUT/glossy" --out "$OUT/tp"; }

# Image runs against Blender Cycles (issue 40, docs/image-relighting.md "Checked against Cycles"):
# bench/cycles/run.sh farms each case's image scene, relights it with prt-view, renders it twice
# in Cycles (two seeds) and prints the noise-corrected per-pixel error on the model and the
# ground; its header lists the cases, the settings (PRT_CAMERA_CASES, PRT_CAMERA_ENVS,
# PRT_CAMERA_SAMPLES) and the run time. Output: bench-out/camera/.
run_camera() {
  PRT_SHARED_DATA="${PRT_SHARED_DATA:-$ROOT/../shared/data}" \
    "$ROOT/bench/cycles/run.sh" "$BUILD_DIR" "$OUT/camera"
}

# [camera] supersample (docs/image-relighting.md, "Supersampling"): scenes/bench/bunny-direct.toml
# at k = 1, 2, 4 and a k = 16 reference, brute force at PRT_SS_RAYS rays per texel (16), raw rows
# kept; supersample_bench prints edge and interior error under sunrise and city and the rows'
# seconds. About 4 min on the 2-core VM. Output: $OUT/supersample/{k1,k2,k4,k16,table.txt}.
run_supersample() {
  local d="$OUT/supersample" rays="${PRT_SS_RAYS:-16}"
  mkdir -p "$d"
  for k in 16 1 2 4; do
    sed "s/^height = 120$/height = 120\nsupersample = $k/" "$ROOT/scenes/bench/bunny-direct.toml" \
      > "$d/bunny-k$k.toml"
    PRT_DATA_PATH="$BUILD_DIR/data" mpirun -np 2 --bind-to none "$BUILD_DIR/farm/prt-farm" \
      "$d/bunny-k$k.toml" --out "$d/k$k" --method brute --rays-per-texel "$rays" --no-compress \
      --force -q
  done
  "$BUILD_DIR/bench/supersample_bench" --reference "$d/k16" "$d/k1" "$d/k2" "$d/k4" \
    --env "$BUILD_DIR/data/envmaps/sunrise.exr" --env "$BUILD_DIR/data/envmaps/city.exr" |
    tee "$d/table.txt"
}

# Glossy vertex transport against Cycles (issue 39, docs/glossy-transport.md): the GGX bunny
# baked per vertex with [glossy] terms (scenes/bench/bunny-ggx-vertex-*.toml), relit by prt-view
# from the scene's camera, against Cycles at max bounces 0, through bench/cycles/run.sh.
# PRT_CAMERA_ENVS picks the environments (default: all four). Output: $OUT/glossy-cycles/.
# A second view of the r = 0.8 bake re-uses its run folder (the rows do not depend on the camera):
# the view2 scene replaces run/scene.toml in a copy, and only the pack, prt-view and Cycles run.
run_glossy_cycles() {
  local d="$OUT/glossy-cycles"
  PRT_SHARED_DATA="${PRT_SHARED_DATA:-$ROOT/../shared/data}" \
    PRT_CAMERA_CASES="${PRT_CAMERA_CASES:-vertex-ggx-k0|scenes/bench/bunny-ggx-vertex-k0.toml|0|0|centre vertex-ggx-r08-k0|scenes/bench/bunny-ggx-vertex-r08-k0.toml|0|0|centre}" \
    "$ROOT/bench/cycles/run.sh" "$BUILD_DIR" "$d"
  if [ -f "$d/vertex-ggx-r08-k0/run/report.json" ] && [ -z "${PRT_CAMERA_CASES:-}" ]; then
    rm -rf "$d/vertex-ggx-r08-k0-view2"
    mkdir -p "$d/vertex-ggx-r08-k0-view2"
    cp -a "$d/vertex-ggx-r08-k0/run" "$d/vertex-ggx-r08-k0-view2/run"
    cp "$ROOT/scenes/bench/bunny-ggx-vertex-r08-k0-view2.toml" "$d/vertex-ggx-r08-k0-view2/run/scene.toml"
    touch "$d/vertex-ggx-r08-k0-view2/run/report.json"
    PRT_SHARED_DATA="${PRT_SHARED_DATA:-$ROOT/../shared/data}" PRT_CAMERA_APPEND=1 \
      PRT_CAMERA_CASES="vertex-ggx-r08-k0-view2|scenes/bench/bunny-ggx-vertex-r08-k0-view2.toml|0|0|centre" \
      "$ROOT/bench/cycles/run.sh" "$BUILD_DIR" "$d"
  fi
}

# The BRDF factorisation of glossy vertex transport against the exact BRDF on the same rays, per
# roughness and term count, plus the error split of a finished run (docs/glossy-transport.md).
# About 2 min. Output: $OUT/glossy-terms/{table.csv,terms.png}.
run_glossy_terms() {
  "$BUILD_DIR/bench/glossy_terms_bench" --out "$OUT/glossy-terms" | tee "$OUT/glossy-terms.txt"
}

case "$WHAT" in
  all) run_transport; run_scaling; run_sparse; run_compression; run_cpca; run_compress; run_figure9; run_viewer; run_relight; run_runtime; run_glossy; run_tp ;;
  transport|scaling|million|sparse|compression|cpca|compress|figure9|viewer|relight|runtime|glossy|tp|sweep|stress|rebake) "run_$WHAT" ;;
  mc-error) run_mc_error ;;
  gi) run_gi ;;
  sparse-gi) run_sparse_gi ;;
  image) run_image ;;
  camera) run_camera ;;
  supersample) run_supersample ;;
  glossy-cycles) run_glossy_cycles ;;
  glossy-terms) run_glossy_terms ;;
  *) echo "usage: scripts/bench.sh [all|transport|scaling|million|sparse|compression|cpca|compress|figure9|viewer|relight|runtime|glossy|tp|sweep|stress|rebake|mc-error|gi|sparse-gi|image|camera|supersample|glossy-cycles|glossy-terms] [--quick]" >&2; exit 1 ;;
esac
