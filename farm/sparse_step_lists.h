// What rank 0 and the workers of the sparse phase (farm/sparse_phase.cpp) both build a job from:
// a step's neighbour lists (Huang & Ramamoorthi 2010 §4.1 and §5.3), the step's lists file that
// lets a worker build them itself where every rank sees the run folder, and the compact job that
// then replaces the lists in the message. Rank 0 and the worker build the same lists from the
// same index (an exact search on one FLANN k-d tree over the same points in the same order).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "farm/farm_context.h"
#include "farm/sparse_jobs.h"
#include "worker/neighbor_index.h"

namespace prt {

// The points a step's NeighborIndex is built over: the dense samples' positions in the dense
// list's order (rank 0 and, with rows in place, every worker build the same index from them).
std::vector<Vec3> DenseIndexPoints(const SparsePlan& plan, std::span<const SpatialSample> samples,
                                   std::span<const uint32_t> dense);

// Huang & Ramamoorthi 2010 §4.1 (a candidate's local rank over its dense neighbours) and §5.3
// (a sparse vertex's reconstruction from "dense vertices within some spatial radius", capped at
// k): the neighbour lists of items [first, first + count) of `items` (sample ids): each item's
// dense neighbours within the plan's radius, nearest first, at most max_neighbors (`exclude_self`:
// the item, dense itself, left out — cross-validation), as indices into the union of their sample
// ids in first-seen order. `max_union` > 0: the items stop before the union would exceed it (at
// least one item). Returns the items taken. Rank 0 and, with rows in place, the worker build the
// same lists from the same index (an exact search on one FLANN k-d tree over the same points in
// the same order).
struct NeighbourLists {
  std::vector<uint32_t> offsets{0}, neighbors, union_ids;
};
uint64_t ListNeighbours(const NeighborIndex& index, std::span<const SpatialSample> samples,
                        const SparsePlan& plan, std::span<const uint32_t> items, uint64_t first,
                        uint64_t count, bool exclude_self, uint64_t max_union, NeighbourLists& out);

// A step's lists with rows in place (run/sparse/lists-<step number>.bin, written durably by rank 0
// before the step's first job): the dense samples its index is built over, in order, and its
// items (candidates, sparse vertices in Morton order, or the cross-validated vertices). The
// magic "PRTSLS1\0", uint64 dense count, uint64 item count, the uint32 ids, then the XXH64 of
// everything before it.
std::string StepListsPath(const RunFolder& f, uint32_t step);
void WriteStepLists(const std::string& path, std::span<const uint32_t> dense,
                    std::span<const uint32_t> items);
// The rows-in-place scratch of the steps (dense_low.bin, lists-<step>.bin): read only while the
// steps run, and written again by a resume. Removed once the steps are done, so that the run
// folder holds the same files for any number of ranks (docs/farm.md, "Determinism").
void RemoveSparseScratch(const RunFolder& f);
// Throws InputError for a file that is not a step's lists, is damaged, or names a sample at or
// beyond `samples`.
void ReadStepLists(const std::string& path, uint64_t samples, std::vector<uint32_t>& dense,
                   std::vector<uint32_t>& items);

// A job without its neighbour lists (rows in place): the worker builds them from its step's
// lists file. [magic "PRSC"][SparseJobHeader][uint32 exclude_self][step name].
std::string EncodeCompactJob(const SparseJobHeader& h, bool exclude_self, const std::string& step,
                             std::string prefix);

// A worker's side of compact jobs: the full job (neighbour lists, union ids, in-place flags) from
// the step's lists file and an index over its dense samples, both loaded once per step.
class CompactJobExpander {
 public:
  // `payload` is a compact job (IsCompact) of the run in `ctx`.
  std::string Expand(const FarmContext& ctx, std::string_view payload);
  static bool IsCompact(std::string_view payload);

 private:
  uint32_t step_ = 0;
  std::vector<uint32_t> dense_, items_;
  std::unique_ptr<NeighborIndex> index_;
};

}  // namespace prt
