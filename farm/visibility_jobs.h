// The farm's visibility job kind (docs/farm.md, "Visibility job"): per-vertex visibility cubemaps
// for glossy triple-product relighting (Inger, Farbman & Lischinski 2013, §4.2), traced by
// worker/visibility_sampler.h on the same job queue as transport rows. No MPI here: a job is a
// contiguous range of spatial samples (farm/job_planner.h), its result the block-differential
// encoding of those samples' maps (EncodeVisibilityBlocks, formats/visibility_blocks.h) with
// its counters, as one self-checking message.
//
// Run folder (rank 0 writes):
//   visibility.chunks  each finished job's encoded maps appended as they arrive; a journal line
//                      "sjob visibility <first> <count> <xxh64 of the chunk> <rank> <busy s> 4
//                      <offset> <length> <rays> <texels below horizon> <line xxh64>" is fsynced
//                      after the chunk is durable;
//   visibility.prtv    the final file: EncodeVisibilityBlocks of every sample in sample order,
//                      assembled from the journaled chunks (AssembleVisibilityChunks), so its
//                      bytes depend on neither the ranks nor the job boundaries.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "farm/checkpoint_journal.h"
#include "formats/visibility_blocks.h"
#include "worker/visibility_sampler.h"

namespace prt {

inline constexpr const char* kVisibilityPhaseName = "visibility";

struct VisibilityJobResult {
  uint64_t first = 0;  // sample range
  uint64_t count = 0;
  uint64_t rays_traced = 0;
  uint64_t texels_below_horizon = 0;
  double busy_seconds = 0;
  std::vector<uint8_t> chunk;  // EncodeVisibilityBlocks of samples [first, first + count)
};

// Traces samples [first, first + count) of `samples` (TBB threads) and encodes them.
// Throws NumericalError for a bad sample, std::out_of_range for a range outside `samples`.
VisibilityJobResult ComputeVisibilityJob(const VisibilitySampler& sampler,
                                         std::span<const SpatialSample> samples, uint64_t first,
                                         uint64_t count);

// One message: a fixed header (magic, range, counters, busy time, chunk length, XXH64 of the
// chunk), then the chunk. Decode throws std::runtime_error on a truncated, foreign or damaged
// message (checksum mismatch).
std::vector<uint8_t> EncodeVisibilityJobResult(const VisibilityJobResult& r);
VisibilityJobResult DecodeVisibilityJobResult(std::span<const uint8_t> bytes);

// The journal line of a chunk written at `offset` of visibility.chunks (counters: offset,
// length, rays, texels below horizon) and its inverse; ChunkOfJournalEntry returns false for a
// line of another phase or with the wrong number of counters.
JournalEntry VisibilityJournalEntry(const VisibilityJobResult& r, int rank, uint64_t offset,
                                    uint64_t checksum);
struct VisibilityChunkRef {
  uint64_t first = 0, count = 0;
  uint64_t offset = 0, length = 0;
  uint64_t checksum = 0;
  uint64_t rays_traced = 0, texels_below_horizon = 0;
};
bool ChunkOfJournalEntry(const JournalEntry& e, VisibilityChunkRef& ref);

// Decodes chunks (any order; each EncodeVisibilityBlocks of its own range, n and bits as given)
// and concatenates them in sample order into the final file's bytes. Throws InputError naming
// `source` when a chunk does not decode, disagrees with n/bits or its range, or the chunks do
// not cover [0, samples) exactly once.
struct VisibilityChunk {
  uint64_t first = 0, count = 0;
  std::span<const uint8_t> bytes;
};
// `counts` (optional) receives the block counts of the whole file.
std::vector<uint8_t> AssembleVisibilityChunks(std::vector<VisibilityChunk> chunks, uint64_t samples,
                                              int n, int bits, const std::string& source,
                                              VisibilityBlockCounts* counts = nullptr);

}  // namespace prt
