// The TBB backend of vocabulary/parallel.h, for the programs that link TBB (prt-view, prt-farm,
// the benchmarks, the tests): the core vocabulary's and the runtime's loops then run on TBB's
// threads, as many as its arena has.
#pragma once

namespace prt {

// Installs TBB as the parallel backend (idempotent).
void UseTbbParallelism();

}  // namespace prt
