#!/usr/bin/env bash
# Prints the sha256 of every file a change to the house must not alter (docs/testing.md, "Same
# bytes"): transport.prtt, transport.prtc and geometry.prtg of the demo farm (default scene, sparse,
# 2 ranks), of brute force on the default scene (1 ray per texel, 2 ranks), of tests/data's tiny
# scene by brute force (3 ranks, jobs of at most 7 rows) and of its sparse scene (2 ranks), and
# visibility.prtv of the glossy tiny scene; then the .prtpack of each transport run, packed with
# REPORT_DIR/<run>/report.json in place of the run's own (a report holds timings; everything else
# in a pack is deterministic) when REPORT_DIR is given.
#   scripts/output-checksums.sh [BUILD_DIR] [OUT_DIR] [REPORT_DIR]
# Run it with the old build and the new one and diff the two outputs. Takes ~2 minutes.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
B="$(cd "${1:-$BUILD_DIR}" && pwd)"
O="${2:-$ROOT/checksums-out}"
R="${3:-}"
export PRT_DATA_PATH="$B/data"
T="$ROOT/tests/data"
rm -rf "$O"
mkdir -p "$O"
farm() { local run=$1 np=$2; shift 2; mpirun -np "$np" "$B/farm/prt-farm" "$@" --out "$O/$run" --quiet; }
farm demo 2 --keep-raw
farm brute_demo 2 --method brute --rays-per-texel 1 --keep-raw
farm brute_tiny 3 "$T/tiny.toml" --method brute --max-job-rows 7 --keep-raw
farm sparse_tiny 2 "$T/sparse_tiny.toml" --keep-raw
farm vis 2 "$T/glossy_tiny.toml"
for run in demo brute_demo brute_tiny sparse_tiny; do
  [ -n "$R" ] && cp "$R/$run/report.json" "$O/$run/report.json"
  "$B/packager/prt-pack" pack "$O/$run" --out "$O/$run.prtpack" > /dev/null
done
cd "$O"
sha256sum */transport.prtt */transport.prtc */geometry.prtg vis/visibility.prtv *.prtpack
