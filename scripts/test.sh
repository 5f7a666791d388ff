#!/usr/bin/env bash
# Installs what is needed, builds, and runs the whole test suite (MPI tests with 2 ranks
# included). Ends with CTest's summary line. Idempotent.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
"$ROOT/scripts/install-deps.sh"
configure_and_build
cd "$BUILD_DIR"
ctest --output-on-failure -j "$JOBS" --timeout 900
