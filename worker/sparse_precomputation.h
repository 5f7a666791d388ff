// Sparse precomputation of the transport matrix (Huang & Ramamoorthi 2010), as job-sized kernels
// that the farm distributes, plus an in-process driver that runs all phases on one machine:
//
//   phase 1 (dense vertices, §4): an initial random set (initial_fraction of the samples), then
//     `iterations` rounds: for candidate vertices estimate the local rank of the dense
//     neighbours' transport (§4.1; worker/local_rank.h) and draw the next dense vertices with
//     weight = rank, until dense_budget; every dense row by adaptive angular sampling (§4.2).
//   phase 2 (sparse vertices, §5): every other vertex from its dense neighbours within the radius
//     (capped at max_neighbors), feature directions, L1 solve; fallbacks become dense.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "vocabulary/scene.h"
#include "worker/adaptive_angular_sampling.h"
#include "worker/sparse_reconstruction.h"
#include "worker/transport_sampler.h"

namespace prt {

struct SparsePlan {
  double initial_fraction = 0.05;
  double dense_budget = 0.25;
  int iterations = 4;
  double radius = 0.1;  // absolute (scene units); see RadiusFor()
  int max_neighbors = 40;
  int rank_resolution = 8;  // rows are box-averaged to 6·m·m texels for rank estimation
  double rank_threshold = 0.05;
  int candidates_per_pick = 4;  // rank is estimated on this many random candidates per pick
  // Weight of a candidate with no dense neighbour within the radius: 0 = max_neighbors (nothing
  // is known there; the default), > 0 this fixed weight, < 0 the largest rank estimated in the
  // same round. Measured on the default scene and the dragon (docs/sparse-precomputation.md):
  // the round's largest rank gave more fallbacks and slightly larger ground errors.
  int empty_weight = 0;
  // The dense budget driven by rank (§4.1: dense vertices are added where the local rank of the
  // neighbours' transport is high; here also *only* there): a candidate with at
  // least sparse.min_neighbors dense neighbours whose local rank is ≤ rank_floor is covered (a
  // combination of its neighbours already explains it) and is never picked, and each round picks
  // its share of the budget × the fraction of its candidates that are not covered, so flat,
  // unoccluded, low-rank regions stop early and dense_budget becomes a cap. A candidate with
  // fewer dense neighbours than a sparse vertex needs gets the empty weight (it would fall back
  // to dense). 0: off, the fixed budget (the paper's).
  int rank_floor = 0;
  uint64_t seed = 1;
  AngularOptions angular;
  SparseOptions sparse;
  // Glossy vertex transport (docs/glossy-transport.md): the samples are the vertices once per
  // term, and the method runs on each T_i separately (Huang & Ramamoorthi 2010 §3): term t's
  // samples are searched for neighbours at position + t·term_offset·x̂, farther apart than any
  // radius (setup sets it from the scene's size). 0: one term.
  double term_offset = 0;
  Vec3 SearchPosition(const SpatialSample& s) const {
    return s.term == 0 ? s.position : s.position + Vec3{s.term * term_offset, 0, 0};
  }
};

// The plan from the scene's [sparse] settings: radius relative to the scene's bounding-box
// diagonal, features scaled with the cubemap resolution (350 at n = 32, ∝ n²).
SparsePlan PlanFromSettings(const SparseSettings& s, double scene_diagonal, int cubemap_n);

struct SparseReport {
  uint64_t samples = 0;
  uint64_t dense_initial = 0;
  uint64_t dense_by_rank = 0;
  uint64_t dense_fallback = 0;  // sparse vertices that fell back to dense
  uint64_t sparse = 0;          // reconstructed
  AngularStats dense_angular;   // over all dense rows
  SparseStats sparse_stats;
  uint64_t texels_above_horizon_total = 0;  // what brute force would evaluate
  double seconds_dense = 0, seconds_rank = 0, seconds_sparse = 0;
  std::vector<int> local_rank;    // rank estimated at each candidate vertex, −1 elsewhere
  std::vector<uint8_t> is_dense;  // per sample
  // Per sample: the dense samples and weights α its reconstructed row combines (§5, Eq. 4;
  // empty for dense samples and fallbacks). The indirect components may reuse them
  // (worker/sparse_indirect.h, SparseIndirectOptions::direct_weights).
  std::vector<std::vector<SampleWeight>> combination;
  // Traced texels as a fraction of what brute force traces (texels above the horizons).
  double SampledFraction() const;
};

// Deterministic initial dense set: `count` distinct sample indices, sorted.
std::vector<uint32_t> InitialDenseSet(std::size_t sample_count, std::size_t count, uint64_t seed);

// The pieces of the dense-vertex selection (§4.1) that RunSparseSchedule strings together.
// Total number of dense vertices aimed for: ceil(dense_budget · N), at most N.
std::size_t SparseDenseBudget(std::size_t sample_count, const SparsePlan& plan);
// Size of the initial random dense set: ceil(initial_fraction · N) in [1, budget].
std::size_t SparseInitialDenseCount(std::size_t sample_count, const SparsePlan& plan);
// Rounds of rank-weighted picks: max(1, iterations).
int SparseRounds(const SparsePlan& plan);
// Dense vertices to pick in round `it` (0-based) when `dense_count` are dense already.
std::size_t SparsePicksForRound(std::size_t budget, std::size_t dense_count, int rounds, int it);
// The candidates of round `it`: a deterministic random subset of the non-dense samples
// (candidates_per_pick per pick), sorted.
std::vector<uint32_t> SparseRankCandidates(std::span<const uint8_t> is_dense, std::size_t picks,
                                           const SparsePlan& plan, int it);
// A candidate's weight from its dense neighbours' downsampled rows (6·m·m floats each): the
// local rank, at least 1; with no dense neighbour (with rank_floor > 0: fewer than
// sparse.min_neighbors), max_neighbors (or plan.empty_weight when positive; 0, "unknown", when
// negative: SparsePickByRank resolves it to the round's largest rank); −1, covered, when
// rank_floor > 0 and the rank is ≤ rank_floor.
int SparseCandidateWeight(std::span<const float* const> neighbor_low_rows, std::size_t low_dim,
                          const SparsePlan& plan);
// The next dense vertices of round `it`, drawn with weight = rank (a weight 0, unknown, counts
// as the largest weight of the round, 1 if there is none); covered candidates (weight < 0) are
// never drawn, and with rank_floor > 0 the picks shrink to picks × the uncovered fraction of the
// candidates; sorted.
std::vector<uint32_t> SparsePickByRank(std::span<const uint32_t> candidates,
                                       std::span<const double> weights, std::size_t picks,
                                       const SparsePlan& plan, int it);
// Resolution m of the downsampled rows used for rank estimation at cubemap resolution n.
int SparseRankResolution(const SparsePlan& plan, int cubemap_n);

// ---- the one driver of the method: the order of its steps, shared by the in-process run below
// and the farm's distributed one (farm/sparse_phase.cpp), which differ only in how a step is
// computed (TBB threads here, jobs over MPI ranks there).
//
//   dense-initial        InitialDenseSet                                       §4.1
//   rank-k, dense-rank-k candidates of round k, their local rank, picks by rank §4.1, k = 1…
//   sparse-reconstruct   every non-dense sample from its dense neighbours      §5
//   dense-fallback       the samples whose reconstruction fell back
class SparseSteps {
 public:
  virtual ~SparseSteps() = default;
  // Samples `ids` densely (§4.2: adaptive angular sampling; T, visibility and feature rows).
  virtual void Dense(const std::string& step, std::span<const uint32_t> ids) = 0;
  // The weight of each candidate (SparseCandidateWeight of its dense neighbours' downsampled
  // rows), with `dense` the dense samples so far (in the order they became dense).
  virtual std::vector<double> Rank(const std::string& step, int round,
                                   std::span<const uint32_t> dense,
                                   std::span<const uint32_t> candidates) = 0;
  // Reconstructs every sample that is not dense (§5) from `dense` (sorted); returns the samples
  // that fell back, sorted.
  virtual std::vector<uint32_t> Reconstruct(const std::string& step,
                                            std::span<const uint32_t> dense,
                                            std::span<const uint8_t> is_dense) = 0;
};

struct SparseScheduleCounts {
  uint64_t dense_initial = 0;
  uint64_t dense_by_rank = 0;
  uint64_t candidates_ranked = 0;
  uint64_t dense_fallback = 0;
  std::vector<uint8_t> is_dense;  // per sample, at the end: 1 for every dense sample
};

// Runs the method's steps for `sample_count` samples in order; deterministic in plan.seed.
// skip (empty, or one flag per sample): samples with a 1 take no part — never dense, never a
// candidate or a neighbour, not reconstructed, their rows left as the caller has them (zero).
// An image's background pixels (SpatialSample::background: no surface, a zero row) are skipped,
// so that the method's budget and steps are spent on the surface pixels alone. The schedule
// runs on the remaining samples' indices in order, so without a skipped sample it is exactly
// the schedule without `skip`.
SparseScheduleCounts RunSparseSchedule(std::size_t sample_count, const SparsePlan& plan,
                                       SparseSteps& steps, std::span<const uint8_t> skip = {});
// The skip flags of RunSparseSchedule for `samples`: 1 for a background sample; empty when there
// is none.
std::vector<uint8_t> SparseSkipOf(std::span<const SpatialSample> samples);

// Runs every phase in this process (TBB threads). Returns T as sample_count rows of
// texel_count floats. `progress` (may be empty) receives (phase name, done, total).
std::vector<float> RunSparsePrecomputation(
    const TransportSampler& sampler, std::span<const SpatialSample> samples, const SparsePlan& plan,
    SparseReport& report,
    const std::function<void(const char*, std::size_t, std::size_t)>& progress = {});
// The same into caller-owned storage of sample_count · texel_count floats (every entry is
// written), as TransportSampler::ComputeRows does: a benchmark allocates both outputs before
// timing either (first-touching 350 MB of fresh pages costs ~0.5 s on a VM).
void RunSparsePrecomputation(
    const TransportSampler& sampler, std::span<const SpatialSample> samples, const SparsePlan& plan,
    SparseReport& report, float* out,
    const std::function<void(const char*, std::size_t, std::size_t)>& progress = {});

}  // namespace prt
