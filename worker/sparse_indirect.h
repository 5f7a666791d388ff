// Sparse precomputation of the indirect transport (Huang & Ramamoorthi 2010 on global
// illumination; docs/sparse-precomputation.md, "With interreflection"). No MPI here.
//
// T = T⁰ + Σ_k Tᵏ. The direct part T⁰ is sampled sparsely as before (worker/
// sparse_precomputation.h): dense vertices by local rank (§4.1) with adaptive angular sampling
// (§4.2), sparse vertices from a few traced features by L1 (§5). The indirect part I is, per the
// paper's §4.2, "generally much smoother and low-frequency, so sparsely sampling it is even
// simpler. We directly use the low-resolution grid": it lives on the indirect grid of m texels
// per face edge (docs/interreflection.md), and
//   - a dense vertex (the same dense set as T⁰'s) evaluates its whole coarse row;
//   - a sparse vertex x evaluates only `features` coarse texels F (§5.2: where its dense
//     neighbours' rows differ most, and where they carry the most light), then
//       α = argmin ½‖A α − b‖² + λ‖α‖₁,  A[(c,f), k] = I_k,c(F_f),  b[(c,f)] = I_x,c(F_f)  (Eq. 5)
//       I_x,c(J) = max(0, Σ_k α_k I_k,c(J))  for J ∉ F,   I_x,c(F_f) = b[(c,f)]        (Eq. 4)
//     with every evaluated value kept exactly; too few dense neighbours, a failed solve or a fit
//     leaving more than max_residual of ‖b‖ (the same tests as T⁰'s, docs/sparse-
//     precomputation.md) make x evaluate its whole row instead.
// One component is reconstructed at a time: with bounce gathering each bounce Tᵏ (which needs
// Tᵏ⁻¹ at every vertex first, so the bounces go in order), with per-element path tracing the sum
// Σ_k Tᵏ at once. "With gathering a sparse vertex gathers only its feature texels": its rays are
// traced in full (they find the hit points), but the gather is applied, and in bounce 1 the near
// field traced, only at F. With path tracing the direct rows at the path vertices are traced only
// at F, which is where a path estimator's time goes.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "worker/bounce_gather.h"
#include "worker/l1_solver.h"
#include "worker/neighbor_index.h"
#include "worker/path_trace_reference.h"
#include "worker/sparse_precomputation.h"
#include "worker/sparse_reconstruction.h"

namespace prt {

// An estimator of one indirect component at a vertex: channels() rows of cols() coarse texels,
// evaluable at any subset of the texels with each value bit-identical to the full row's.
class IndirectComponent {
 public:
  virtual ~IndirectComponent() = default;
  virtual int channels() const = 0;
  virtual std::size_t cols() const = 0;
  // texels (sorted, distinct) empty: the whole row into out[c·cols + J]; else the listed texels
  // into out[c·texels.size() + i]. Returns the rays traced. Thread-safe.
  virtual uint64_t Evaluate(const SpatialSample& x, uint64_t index,
                            std::span<const uint32_t> texels, float* out) const = 0;
};

// Bounce k by gathering (worker/bounce_gather.h) from the previous bounce's rows of every vertex
// (prev_channels × vertex_count rows of cols floats, channel-major).
class GatheredBounce final : public IndirectComponent {
 public:
  GatheredBounce(const BounceGatherer& gatherer, int bounce, int channels, const float* previous,
                 uint64_t vertex_count, int prev_channels, std::size_t cols)
      : gatherer_(gatherer),
        bounce_(bounce),
        channels_(channels),
        previous_(previous),
        vertex_count_(vertex_count),
        prev_channels_(prev_channels),
        cols_(cols) {}
  int channels() const override { return channels_; }
  std::size_t cols() const override { return cols_; }
  uint64_t Evaluate(const SpatialSample& x, uint64_t index, std::span<const uint32_t> texels,
                    float* out) const override;

 private:
  const BounceGatherer& gatherer_;
  int bounce_, channels_;
  const float* previous_;
  uint64_t vertex_count_;
  int prev_channels_;
  std::size_t cols_;
};

// Σ_k Tᵏ by per-element path tracing (PathTraceReference::ComputeIndirect) on the reference's
// grid (built at the indirect grid's n).
class PathTracedIndirect final : public IndirectComponent {
 public:
  PathTracedIndirect(const PathTraceReference& reference, int channels)
      : reference_(reference), channels_(channels) {}
  int channels() const override { return channels_; }
  std::size_t cols() const override { return reference_.layout().texel_count(); }
  uint64_t Evaluate(const SpatialSample& x, uint64_t index, std::span<const uint32_t> texels,
                    float* out) const override;

 private:
  const PathTraceReference& reference_;
  int channels_;
};

struct SparseIndirectOptions {
  // Coarse texels evaluated per sparse vertex: the paper's 350 of 6·32² directions (5.7 %) at
  // the indirect grid's 6·m² texels, at least 8 (22 at m = 8, 88 at m = 16).
  int features = 22;
  double lambda = 1e-3;         // relative L1 penalty (L1Options::lambda)
  int min_neighbors = 3;        // fewer dense neighbours: the whole row is evaluated
  double min_normal_cos = 0.5;  // as SparseOptions::min_normal_cos
  double max_residual = 0.3;    // as SparseOptions::max_residual; ≤ 0: off
  // Bounce gathering's cost is its rays (P per vertex, whatever the texels asked for; measured
  // in docs/sparse-precomputation.md), so a sparse vertex gathering its features costs about
  // half a brute-force vertex. With direct_weights a sparse vertex evaluates nothing: its row is
  // the combination its T⁰ row was reconstructed with (SparseReport::combination, the paper's
  // one α for the whole row, Eq. 4), I_x = max(0, Σ α_k I_k); a vertex without one evaluates
  // its features as above.
  bool direct_weights = false;
};

// The feature count for an indirect grid of m texels per face edge at the direct features'
// rate: direct_features / (6·n²) of 6·m², at least 8.
int IndirectFeatures(int direct_features, int cubemap_n, int indirect_n);

// The options a sparse plan implies on the indirect grid: IndirectFeatures of its direct
// features, its λ, neighbour and fit tests (direct_weights off).
SparseIndirectOptions IndirectOptionsOf(const SparsePlan& plan, int cubemap_n, int indirect_n);

struct SparseIndirectStats {
  uint64_t dense_rows = 0;  // dense vertices: whole rows
  uint64_t reconstructed = 0;
  uint64_t fallback_too_few_neighbors = 0;  // whole rows evaluated instead
  uint64_t fallback_solve_failed = 0;
  uint64_t fallback_poor_fit = 0;
  uint64_t texels_evaluated = 0;  // coarse texels evaluated (a texel counts once for all channels)
  uint64_t texels_total = 0;      // what evaluating every vertex's whole row would be
  uint64_t rays = 0;
  double seconds_dense = 0, seconds_sparse = 0;
  uint64_t fallbacks() const {
    return fallback_too_few_neighbors + fallback_solve_failed + fallback_poor_fit;
  }
  double SampledFraction() const {
    return texels_total > 0 ? double(texels_evaluated) / double(texels_total) : 0.0;
  }
  SparseIndirectStats& operator+=(const SparseIndirectStats& o);
};

// A dense neighbour: its row of the component (channels × cols, channel c at c·cols) and normal.
struct IndirectNeighbor {
  const float* row = nullptr;
  Vec3 normal{0, 0, 0};
};

// The feature texels of a sparse vertex [§5.2], sorted: half the count where the neighbours'
// values vary most (variance over the neighbours, summed over channels), the rest where they
// carry the most light (mean), ties by texel index. Deterministic.
std::vector<uint32_t> ChooseIndirectFeatures(std::span<const IndirectNeighbor> neighbors,
                                             int channels, std::size_t cols, int count);

// One sparse vertex's row of the component into row (channels × cols): reconstructed (Eq. 4–5
// above) or, on a fallback outcome, evaluated whole (counted in stats). Never leaves a NaN/Inf.
SparseOutcome ReconstructIndirectRow(const IndirectComponent& component, const SpatialSample& x,
                                     uint64_t index, std::span<const IndirectNeighbor> neighbors,
                                     const SparseIndirectOptions& options, L1Solver& solver,
                                     float* row, SparseIndirectStats& stats);

// A non-dense sample's row (§5): its dense neighbours within `radius` (at most max_neighbors,
// nearest first, from `dense_index` over the dense samples), whose rows row_of(d) gives (channels
// × cols each), then ReconstructIndirectRow. What RunSparseIndirect and the farm's -sparse phases
// (farm/bounce/features.cpp) do per vertex.
template <class RowOf>
SparseOutcome ReconstructIndirectAt(const IndirectComponent& component,
                                    std::span<const SpatialSample> samples, uint32_t s,
                                    const NeighborIndex& dense_index, double radius,
                                    int max_neighbors, RowOf&& row_of,
                                    const SparseIndirectOptions& options, L1Solver& solver,
                                    float* row, SparseIndirectStats& stats) {
  std::vector<IndirectNeighbor> nbs;
  for (uint32_t d : dense_index.RadiusSearch(samples[s].position, radius, max_neighbors))
    nbs.push_back({row_of(d), samples[d].normal});
  return ReconstructIndirectRow(component, samples[s], s, nbs, options, solver, row, stats);
}

// Every sample's row of the component in this process (TBB threads): the dense samples'
// (is_dense[s] = 1) whole rows first, then every other sample from its dense neighbours within
// `radius` (at most max_neighbors, nearest first), along a Hilbert curve of the positions.
// out: channels × samples.size() rows of cols floats, channel-major (row c·N + s), as
// GatherBounces' bounces.
// combination (with options.direct_weights): per sample, SparseReport::combination.
// sparse_component (optional): what the sparse vertices evaluate their features (and fallback
// rows) with, when it differs from the dense vertices' estimator (a gather with fewer
// directions, prt-sparse-gi-bench's `feature_paths`); same channels and cols.
void RunSparseIndirect(const IndirectComponent& component, std::span<const SpatialSample> samples,
                       std::span<const uint8_t> is_dense, double radius, int max_neighbors,
                       const SparseIndirectOptions& options, float* out, SparseIndirectStats& stats,
                       std::span<const std::vector<SampleWeight>> combination = {},
                       const IndirectComponent* sparse_component = nullptr);

// I_x = max(0, Σ α_k I_k) (channels × cols) from the dense samples' rows; row_of(sample) gives a
// dense sample's row (channels × cols, channel c at c·cols). Non-finite values become 0.
template <class RowOf>
void CombineRows(std::span<const SampleWeight> weights, RowOf&& row_of, std::size_t size,
                 float* out) {
  std::fill(out, out + size, 0.0f);
  for (const SampleWeight& w : weights) {
    const float* src = row_of(w.sample);
    for (std::size_t i = 0; i < size; ++i) out[i] += w.alpha * src[i];
  }
  for (std::size_t i = 0; i < size; ++i)
    out[i] = out[i] > 0.0f && out[i] <= 3.0e38f ? out[i] : 0.0f;
}

}  // namespace prt
