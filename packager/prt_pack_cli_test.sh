#!/bin/sh
# prt-pack's documented exit codes (0 success, 1 unreadable input / failed verification,
# 2 usage error) and its pack → verify → inspect path on a real mesh.
# With CPCA_PACK (a 1.3 pack with a clustered-PCA transport), its verify and inspect lines too.
# Usage: prt_pack_cli_test.sh PRT_PACK SEED_PACK MESH WORK_DIR [CPCA_PACK]
set -u
PACK=$1 SEED=$2 MESH=$3 WORK=$4 CPCA=${5:-}
fail=0
expect() {  # expect CODE command...
  code=$1; shift
  "$@" >"$WORK/out.txt" 2>"$WORK/err.txt"
  got=$?
  if [ "$got" -ne "$code" ]; then
    echo "FAIL: '$*' exited $got, expected $code"; cat "$WORK/out.txt" "$WORK/err.txt"; fail=1
  fi
}
mkdir -p "$WORK"
expect 0 "$PACK" --version
expect 0 "$PACK" --help
expect 0 "$PACK" verify "$SEED"
grep -q "OK" "$WORK/out.txt" || { echo "FAIL: verify printed no OK"; fail=1; }
expect 0 "$PACK" inspect "$SEED"
grep -q "MESH" "$WORK/out.txt" || { echo "FAIL: inspect printed no MESH section"; fail=1; }
expect 2 "$PACK"
expect 2 "$PACK" verify
expect 2 "$PACK" frobnicate --out x
expect 2 "$PACK" pack --mesh "$MESH"
expect 1 "$PACK" verify "$WORK/missing.prtpack"
grep -q "cannot open" "$WORK/err.txt" || { echo "FAIL: no reason for a missing file"; fail=1; }
# One flipped byte inside the first section: verify must fail with the reason.
cp "$SEED" "$WORK/bad.prtpack"
printf '\377' | dd of="$WORK/bad.prtpack" bs=1 seek=500 conv=notrunc 2>/dev/null
expect 1 "$PACK" verify "$WORK/bad.prtpack"
grep -q "checksum mismatch" "$WORK/err.txt" || { echo "FAIL: no checksum reason"; cat "$WORK/err.txt"; fail=1; }
# Pack a real mesh, then verify and inspect the result.
expect 0 "$PACK" pack --mesh "$MESH" --out "$WORK/mesh.prtpack" --alignment 4096
expect 0 "$PACK" verify "$WORK/mesh.prtpack"
expect 0 "$PACK" inspect "$WORK/mesh.prtpack"
grep -q "transport: none" "$WORK/out.txt" || { echo "FAIL: inspect summary"; fail=1; }
if [ -n "$CPCA" ]; then
  expect 0 "$PACK" verify "$CPCA"
  grep -q "CPCA transport decoded (12 rows, 2 clusters x 2 bases" "$WORK/out.txt" ||
    { echo "FAIL: verify of a CPCA pack"; cat "$WORK/out.txt"; fail=1; }
  expect 0 "$PACK" inspect "$CPCA"
  grep -q "transport: CPCA (clustered PCA), 12 samples" "$WORK/out.txt" ||
    { echo "FAIL: inspect of a CPCA pack"; cat "$WORK/out.txt"; fail=1; }
fi
[ $fail -eq 0 ] && echo "prt-pack CLI: all checks passed"
exit $fail
