// prt-farm: mpirun -np N prt-farm [scene.toml] --out run/   (docs/farm.md)
#include <malloc.h>
#include <mpi.h>

#include <cstdio>
#include <iostream>
#include <sstream>

#include "farm/farm_options.h"
#include "farm/farm_run.h"
#include "vocabulary/tbb_parallel.h"

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  // Blocks up to 32 MiB (glibc's largest mmap threshold) come from the heap and stay there when
  // freed, instead of fresh zero pages per allocation: a farm run allocates, fills and frees
  // job and result buffers of 1–24 MiB thousands of times, and on a VM every first touch of a
  // page is an expensive fault (a 2-rank sparse run spent 14 s of its 47 s encoding jobs into
  // freshly mapped pages; docs/farm.md).
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
  int provided = 0;
  if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
    std::fprintf(stderr, "prt-farm: MPI_Init_thread failed\n");
    return prt::kExitRankFailed;
  }
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  prt::FarmOptions options;
  std::ostringstream quiet_out, quiet_err;
  // Every rank parses the same command line; only rank 0 prints help, version and errors.
  const int early = rank == 0
                        ? prt::ParseFarmCommandLine(argc, argv, options, std::cout, std::cerr)
                        : prt::ParseFarmCommandLine(argc, argv, options, quiet_out, quiet_err);
  int code = early;
  if (early < 0) {
    if (provided < MPI_THREAD_FUNNELED) {
      if (rank == 0)
        std::fprintf(stderr, "prt-farm: this MPI does not provide MPI_THREAD_FUNNELED\n");
      code = prt::kExitRankFailed;
    } else {
      code = prt::RunFarm(options);
    }
  }
  MPI_Finalize();
  return code;
}
