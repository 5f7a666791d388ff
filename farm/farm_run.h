// prt-farm's run: the only entry point of farm/ (docs/farm.md, docs/architecture.md).
//
// Every rank runs the same list of phases (SPMD; farm/farm_context.h), one file each:
//   setup         rank 0 loads and validates the scene, prepares the run folder (or verifies the
//                 checkpoints of --resume) and broadcasts the world-space geometry; every rank
//                 builds its Embree scene and sampler from those same bytes   (setup_phase.cpp)
//   brute|sparse  the transport rows on the job loop (job_loop.h)   (brute_phase.cpp,
//                                                                      sparse_phase.cpp)
//   finalize      rank 0 checksums transport.prtt and renames it      (finalize_phase.cpp)
//   compress      the distributed transpose and column compression, transport.prtc
//                 (compression_phase.cpp; not with --no-compress)
// The visibility job (scene [sampling] job = "visibility" or --job visibility) runs setup,
// visibility and visibility-finalize (visibility_phase.cpp) instead.
#pragma once

#include "farm/farm_options.h"

namespace prt {

// Runs the farm on MPI_COMM_WORLD (MPI must be initialised with at least MPI_THREAD_FUNNELED).
// Returns this rank's exit code (FarmExitCode); the ranks agree on it. A rank that must stop the
// whole job (a dead or hung worker, an I/O error after the workers started) calls MPI_Abort
// with the exit code instead of returning.
int RunFarm(const FarmOptions& options);

}  // namespace prt
