// prt-farm's coordinator: the only code in prtfarm that knows MPI (docs/farm.md).
//
// Every rank runs the same sequence of phases (SPMD). Phases of the brute-force method:
//   setup     rank 0 loads and validates the scene, prepares the run folder (or verifies the
//             checkpoints of --resume) and broadcasts the world-space geometry; every rank
//             builds its Embree scene and transport sampler from that same geometry
//   brute     rank 0 hands out contiguous ranges of spatial samples (JobPlanner); workers send
//             rows back to rank 0 in messages of at most 64 MiB; rank 0 writes them in place
//             into transport.prtt.partial, fdatasyncs, then journals the job (CheckpointJournal)
//   finalize  rank 0 computes the block checksums and renames the file to transport.prtt
// More phases (dense/sparse sampling, transpose, compression) plug in as further FarmPhase
// objects between these. The visibility job (scene [sampling] job = "visibility" or --job
// visibility) runs setup, visibility (the same queue, per-vertex visibility cubemaps) and
// visibility-finalize (assembles visibility.prtv) instead.
#pragma once

#include "farm/farm_options.h"

namespace prt {

// Runs the farm on MPI_COMM_WORLD (MPI must be initialised with at least
// MPI_THREAD_FUNNELED). Returns this rank's exit code (FarmExitCode); the ranks agree on it.
// A rank that must stop the whole job (a dead or hung worker, an I/O error after the workers
// started) calls MPI_Abort with the exit code instead of returning. `transport_job` (optional)
// is set on every rank to whether the run computed transport (the compression phase follows)
// rather than visibility (docs/farm.md, "Visibility job").
int RunFarm(const FarmOptions& options, bool* transport_job = nullptr);

}  // namespace prt
