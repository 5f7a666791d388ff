# Shared by demo.sh and test.sh: where things live and how to build. Sourced, not run.
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD_DIR="${PRT_BUILD_DIR:-$ROOT/build}"
JOBS="${PRT_JOBS:-$(nproc)}"

# Everything mpirun needs in a root container and on a laptop (see docs/testing.md).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_pml=ob1 OMPI_MCA_btl=self,vader OMPI_MCA_rmaps_base_oversubscribe=1

GENERATOR=()
command -v ninja >/dev/null 2>&1 && GENERATOR=(-G Ninja)

configure_and_build() {
  if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
    cmake -S "$ROOT" -B "$BUILD_DIR" "${GENERATOR[@]}" -DCMAKE_BUILD_TYPE=Release \
      -DPRT_WERROR="${PRT_WERROR:-ON}" "$@"
  fi
  cmake --build "$BUILD_DIR" -j "$JOBS"
}
