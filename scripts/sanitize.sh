#!/usr/bin/env bash
# Installs what is needed, builds prtfarm with AddressSanitizer and UndefinedBehaviorSanitizer
# (PRT_SANITIZE=ON, -O1 -g, no benchmarks) into build-asan/ and runs the whole test suite under
# them (MPI tests with 2 ranks included). Ends with CTest's summary line. Idempotent.
# What is suppressed and why: docs/testing.md and scripts/lsan.supp.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
BUILD_DIR="${PRT_ASAN_BUILD_DIR:-$ROOT/build-asan}"
"$ROOT/scripts/install-deps.sh"

# Configured every time (cheap once configured) so that an existing folder gets these settings.
# -O1 -g, as the sanitizers' documentation advises: readable stacks at a tolerable speed.
CONFIGURE=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g -DNDEBUG"
           "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g -DNDEBUG" -DPRT_WERROR="${PRT_WERROR:-ON}"
           -DPRT_SANITIZE=ON -DPRT_BUILD_BENCH=OFF)
if [ -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S "$ROOT" -B "$BUILD_DIR" "${CONFIGURE[@]}" >/dev/null
else
  cmake -S "$ROOT" -B "$BUILD_DIR" "${GENERATOR[@]}" "${CONFIGURE[@]}"
fi
cmake --build "$BUILD_DIR" -j "$JOBS"

# Leaks: OpenMPI, hwloc, PMIx and libevent keep allocations until exit by design; those library
# frames are suppressed (scripts/lsan.supp), never prtfarm's own. OpenMPI is built without frame
# pointers, so the fast unwinder stops inside it and the stack never reaches the library names the
# suppressions match: fast_unwind_on_malloc=0 records whole allocation stacks. Per program,
# scripts/asan/<name>.options overrides that (read last, %b = the program's name): prt-view keeps
# the fast unwinder, since under Xvfb Mesa's software renderer registers code with the unwinder
# and the slow unwinder called from inside it deadlocks (prt-view uses no MPI).
export ASAN_OPTIONS="detect_leaks=1:fast_unwind_on_malloc=0:include_if_exists=$ROOT/scripts/asan/%b.options"
export LSAN_OPTIONS="suppressions=$ROOT/scripts/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# Wall-clock bounds of the few tests that have one grow by this factor (docs/testing.md).
export PRT_TEST_TIME_SCALE="${PRT_TEST_TIME_SCALE:-10}"

cd "$BUILD_DIR"
ctest --output-on-failure -j "$JOBS" --timeout 900
