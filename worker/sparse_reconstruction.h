// Sparse vertices (Huang & Ramamoorthi 2010, §5): a sparse vertex's transport row is a linear
// combination of its dense neighbours' rows (Eq. 4), with weights α found from a few traced
// feature directions (Eq. 5) by L1-regularised least squares (§5.1; worker/l1_solver.h).
// Feature directions are chosen from the neighbours [§5.2]: variance of the neighbours' values
// in that direction × how many neighbours had it as a feature.
//
// The neighbours' rows live in their own normals' hemispheres, so the sparse vertex's own
// horizon and cosine are handled explicitly. Two modes:
//   kVisibility (default): interpolate fractional visibility v = T/U (U: the same estimator with
//     V ≡ 1) and re-apply the vertex's own cosine: T_x(j) = clamp(Σ α_k v_k(j), 0, 1) · U_x(j);
//     α fits Σ α_k v_k(j) U_x(j) to the traced T_x(j);
//   kTransport: interpolate T directly, T_x(j) = clamp(Σ α_k T_k(j), 0, U_x(j)), zero below the
//     vertex's horizon; α fits Σ α_k T_k(j) to T_x(j).
// Both fit in transport units, so each constraint weighs what it adds to the relit radiance
// (fitting v directly gave 2× the ground error on the test scene). In both, the traced feature
// values are kept exactly. Features are ranked by the variance of the neighbours' T.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "worker/adaptive_angular_sampling.h"
#include "worker/l1_solver.h"
#include "worker/transport_sampler.h"

namespace prt {

enum class InterpolationMode : uint8_t { kVisibility = 0, kTransport = 1 };
enum class SolverKind : uint8_t { kL1 = 0, kLeastSquares = 1 };

struct SparseOptions {
  int features = 350;  // traced directions per sparse vertex (at n = 32), at most
  // Adaptive feature count: a vertex traces the texels where its neighbours disagree and had
  // features (the primary key of ChooseFeatureDirections) plus `min_features` more, at most
  // `features`. min_features ≥ features gives the paper's fixed count.
  int min_features = 1 << 30;
  double lambda = 1e-3;   // relative L1 penalty (L1Options::lambda)
  int min_neighbors = 3;  // fewer dense neighbours: the vertex becomes dense
  // Neighbours whose normal makes a larger angle with the vertex's own (cosine below this) are
  // not used: across a thin part (a claw, a wing, an ear) the radius reaches the other side,
  // and from the ground it reaches the model's underside, whose visibility has nothing in common
  // with this vertex's. ≤ −1: every neighbour is used. The scene's [sparse] min_normal_cos
  // (default 0.5, 60°).
  double min_normal_cos = 0.5;
  InterpolationMode mode = InterpolationMode::kVisibility;
  SolverKind solver = SolverKind::kL1;
  // A vertex whose fit leaves more than this relative residual ‖Aα − b‖ / ‖b‖ on its own traced
  // features is sampled densely instead (a combination of its neighbours does not explain it);
  // ≤ 0: off. The scene's [sparse] max_residual (default 0.3).
  double max_residual = 0.3;
  // Visibility mode: weight of the partition-of-unity equation (Σ α_k − 1)·w = 0, where w² is
  // the sum of U_x(j)² over the untraced texels every neighbour sees unoccluded (v_k(j) = 1):
  // the equations those texels would add if the vertex saw them unoccluded too, collapsed into
  // one (their rows are all U_x(j)·[1 … 1]). 0: off (the paper's system, features only). The
  // scene's [sparse] unity_weight (default 1).
  double unity_weight = 1.0;
};

// A dense neighbour as a sparse job receives it.
struct DenseNeighbor {
  const float* transport = nullptr;   // texel_count floats
  const float* visibility = nullptr;  // texel_count floats
  const uint8_t* feature = nullptr;   // texel_count flags
  Vec3 normal{0, 0, 0};               // the dense vertex's normal (SparseOptions::min_normal_cos)
};

enum class SparseOutcome : uint8_t {
  kReconstructed = 0,
  kTooFewNeighbors = 1,  // fallback: make it dense
  kSolveFailed = 2,      // fallback: make it dense
  kPoorFit = 3,          // fallback (SparseOptions::max_residual): make it dense
};

struct SparseStats {
  SampleStats trace;
  uint64_t reconstructed = 0;
  uint64_t fallback_too_few_neighbors = 0;
  uint64_t fallback_solve_failed = 0;
  uint64_t fallback_poor_fit = 0;
  uint64_t neighbors_dropped_by_normal = 0;
  uint64_t solved_lars = 0;
  uint64_t solved_admm = 0;
  uint64_t zero_systems = 0;
  uint64_t features_traced = 0;
  uint64_t texels_above_horizon = 0;  // of reconstructed vertices
  SparseStats& operator+=(const SparseStats& o);
};

// Chooses up to `count` feature texels above the vertex's horizon [§5.2], best first:
// weight = variance across neighbours of v (or T) × number of neighbours that had it as a
// feature; ties and the remainder are filled by variance alone, then by a deterministic spread.
std::vector<uint32_t> ChooseFeatureDirections(const CubemapLayout& layout, const Vec3& normal,
                                              std::span<const DenseNeighbor> neighbors,
                                              InterpolationMode mode, int count, uint64_t seed);

// Reconstructs one sparse row into `row` (texel_count floats). On a fallback outcome `row` is
// untouched and the caller must sample the vertex densely.
// variance (optional, texel_count floats): the Monte-Carlo variance of the traced feature texels
// (kept exactly in the row), 0 elsewhere: the reconstructed texels' error is the fit's, not the
// rays'.
// weights (optional): on kReconstructed, receives the fit's α_k with the index (into
// `neighbors`) of each neighbour it used, the non-zero ones only: what the vertex's row is a
// combination of, for the indirect components (worker/sparse_indirect.h).
struct NeighborWeight {
  uint32_t neighbor = 0;
  float alpha = 0;
};
// The same with the neighbour's global sample index: a sparse row as a combination of dense rows.
struct SampleWeight {
  uint32_t sample = 0;
  float alpha = 0;
};
SparseOutcome ReconstructSparseRow(const TransportSampler& sampler, const SpatialSample& sample,
                                   uint64_t sample_index, std::span<const DenseNeighbor> neighbors,
                                   const SparseOptions& options, L1Solver& solver, float* row,
                                   SparseStats& stats, float* variance = nullptr,
                                   std::vector<NeighborWeight>* weights = nullptr);

// One vertex of a batch for ReconstructSparseRows: ReconstructSparseRow's arguments, and its
// outcome.
struct SparseRowTask {
  const SpatialSample* sample = nullptr;
  uint64_t sample_index = 0;
  std::span<const DenseNeighbor> neighbors;
  float* row = nullptr;
  float* variance = nullptr;                       // optional
  std::vector<NeighborWeight>* weights = nullptr;  // optional
  SparseOutcome outcome = SparseOutcome::kReconstructed;
};

// ReconstructSparseRow for each task, with the same results bit for bit, whatever the batch (a
// vertex's row depends on its own task only). Consecutive vertices along a space-filling curve
// share most of their dense neighbours; a batch of them reads the neighbours' rows for the
// feature statistics about once instead of once per vertex (docs/sparse-precomputation.md,
// "The reconstruction's own cost"). kSparseRowBatch is the batch the callers use.
inline constexpr std::size_t kSparseRowBatch = 16;
void ReconstructSparseRows(const TransportSampler& sampler, std::span<SparseRowTask> tasks,
                           const SparseOptions& options, L1Solver& solver, SparseStats& stats);

}  // namespace prt
