#!/usr/bin/env bash
# Installs what is needed, builds, and runs the whole test suite (MPI tests with 2 ranks
# included). Ends with CTest's summary line. Idempotent.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$ROOT/scripts/install-deps.sh"
configure_and_build

# The .prtpack reader's and the runtime's libFuzzer runs need clang (libFuzzer is clang's): a
# second, small build of only the fuzz targets (packager/ and runtime/CMakeLists.txt), run before
# the main suite.
FUZZ_DIR="${PRT_FUZZ_BUILD_DIR:-$ROOT/build-fuzz}"
if command -v clang++ >/dev/null 2>&1; then
  if [ ! -f "$FUZZ_DIR/CMakeCache.txt" ]; then
    CC=clang CXX=clang++ cmake -S "$ROOT" -B "$FUZZ_DIR" "${GENERATOR[@]}" \
      -DCMAKE_BUILD_TYPE=Release -DPRT_WERROR="${PRT_WERROR:-ON}" -DPRT_BUILD_BENCH=OFF
  fi
  cmake --build "$FUZZ_DIR" -j "$JOBS" --target prtpack_reader_fuzz prt_runtime_fuzz
  (cd "$FUZZ_DIR" && ctest --output-on-failure -R '^(prtpack_reader_fuzz|prt_runtime_fuzz)$')
fi

# The web page's WebAssembly build (docs/web.md), before CTest so that the web_page test does not
# spend its time compiling Draco: a no-op when it is up to date.
"$ROOT/scripts/build-web.sh"

cd "$BUILD_DIR"
ctest --output-on-failure -j "$JOBS" --timeout 900
