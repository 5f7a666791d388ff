#include "worker/sparse_reconstruction.h"

#include <algorithm>
#include <cmath>

#include "worker/local_rank.h"

namespace prt {

SparseStats& SparseStats::operator+=(const SparseStats& o) {
  trace += o.trace;
  reconstructed += o.reconstructed;
  fallback_too_few_neighbors += o.fallback_too_few_neighbors;
  fallback_solve_failed += o.fallback_solve_failed;
  solved_lars += o.solved_lars;
  solved_admm += o.solved_admm;
  zero_systems += o.zero_systems;
  features_traced += o.features_traced;
  texels_above_horizon += o.texels_above_horizon;
  return *this;
}

std::vector<uint32_t> ChooseFeatureDirections(const CubemapLayout& layout, const Vec3& normal,
                                              std::span<const DenseNeighbor> neighbors,
                                              InterpolationMode /*mode*/, int count,
                                              uint64_t seed) {
  struct Cand {
    double key;
    uint32_t texel;
  };
  std::vector<Cand> cands;
  const std::size_t total = layout.texel_count();
  cands.reserve(total / 2 + 8);
  const double k = static_cast<double>(neighbors.size());
  for (std::size_t j = 0; j < total; ++j) {
    if (!layout.TexelAboveHorizon(j, normal)) continue;
    double s = 0, s2 = 0;
    int feat = 0;
    for (const DenseNeighbor& nb : neighbors) {
      const double v = nb.transport[j];
      s += v;
      s2 += v * v;
      feat += nb.feature[j] != 0;
    }
    const double var = k > 0 ? std::max(0.0, s2 / k - (s / k) * (s / k)) : 0.0;
    // Primary: the paper's product; then variance alone; then a deterministic spread so that
    // a region where all neighbours agree still gets constraints.
    const double key = var * feat + 1e-3 * var + 1e-9 * HashUniform(seed, j);
    cands.push_back({key, static_cast<uint32_t>(j)});
  }
  const std::size_t take =
      std::min<std::size_t>(static_cast<std::size_t>(std::max(count, 0)), cands.size());
  std::partial_sort(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(take), cands.end(),
                    [](const Cand& a, const Cand& b) {
                      return a.key != b.key ? a.key > b.key : a.texel < b.texel;
                    });
  std::vector<uint32_t> out(take);
  for (std::size_t i = 0; i < take; ++i) out[i] = cands[i].texel;
  std::sort(out.begin(), out.end());
  return out;
}

SparseOutcome ReconstructSparseRow(const TransportSampler& sampler, const SpatialSample& sample,
                                   uint64_t sample_index, std::span<const DenseNeighbor> neighbors,
                                   const SparseOptions& options, L1Solver& solver, float* row,
                                   SparseStats& stats) {
  if (static_cast<int>(neighbors.size()) < options.min_neighbors) {
    ++stats.fallback_too_few_neighbors;
    return SparseOutcome::kTooFewNeighbors;
  }
  const CubemapLayout& layout = sampler.layout();
  const std::size_t total = layout.texel_count();
  const std::vector<uint32_t> feats = ChooseFeatureDirections(
      layout, sample.normal, neighbors, options.mode, options.features, sample_index);
  const int m = static_cast<int>(feats.size());
  const int k = static_cast<int>(neighbors.size());
  std::vector<float> traced(feats.size());
  stats.trace += sampler.ComputeTexels(sample, sample_index, feats, traced.data());
  stats.features_traced += feats.size();

  // Unoccluded values of every texel above this vertex's horizon (no rays).
  std::vector<uint32_t> above;
  above.reserve(total / 2 + 8);
  for (std::size_t j = 0; j < total; ++j)
    if (layout.TexelAboveHorizon(j, sample.normal)) above.push_back(static_cast<uint32_t>(j));
  std::vector<float> unocc_above(above.size());
  sampler.ComputeUnoccludedTexels(sample, sample_index, above, unocc_above.data());
  std::vector<float> unocc(total, 0.0f);
  for (std::size_t i = 0; i < above.size(); ++i) unocc[above[i]] = unocc_above[i];

  // Equations in transport units for both modes, so that each constraint weighs what it adds to
  // the relit radiance: visibility mode fits Σ α_k v_k(j) · U_x(j) to T_x(j) (the neighbours'
  // visibility under this vertex's own cosine); transport mode fits Σ α_k T_k(j) to T_x(j).
  const bool vis = options.mode == InterpolationMode::kVisibility;
  std::vector<double> A(static_cast<std::size_t>(m) * k), b(static_cast<std::size_t>(m));
  for (int i = 0; i < m; ++i) {
    const uint32_t j = feats[static_cast<std::size_t>(i)];
    const double u = unocc[j];
    b[static_cast<std::size_t>(i)] = traced[static_cast<std::size_t>(i)];
    for (int c = 0; c < k; ++c) {
      const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
      A[static_cast<std::size_t>(i) + static_cast<std::size_t>(m) * c] =
          vis ? nb.visibility[j] * u : nb.transport[j];
    }
  }
  std::vector<double> alpha;
  if (options.solver == SolverKind::kLeastSquares) {
    alpha = L1Solver::LeastSquares(A, b, m, k);
  } else {
    const L1Result r = solver.Solve(A, b, m, k);
    if (r.status == L1Status::kFailed) {
      ++stats.fallback_solve_failed;
      return SparseOutcome::kSolveFailed;
    }
    stats.solved_lars += r.status == L1Status::kLars;
    stats.solved_admm += r.status == L1Status::kAdmm;
    stats.zero_systems += r.status == L1Status::kZeroSystem;
    alpha = r.alpha;
  }

  // Eq. 4 on this vertex's own hemisphere, then the traced values exactly.
  std::fill(row, row + total, 0.0f);
  for (uint32_t j : above) {
    double s = 0;
    for (int c = 0; c < k; ++c) {
      const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
      s += alpha[static_cast<std::size_t>(c)] * (vis ? nb.visibility[j] : nb.transport[j]);
    }
    const double u = unocc[j];
    const double t = vis ? std::clamp(s, 0.0, 1.0) * u : std::clamp(s, 0.0, u);
    row[j] = std::isfinite(t) ? static_cast<float>(t) : 0.0f;
  }
  for (int i = 0; i < m; ++i)
    row[feats[static_cast<std::size_t>(i)]] = traced[static_cast<std::size_t>(i)];
  ++stats.reconstructed;
  stats.texels_above_horizon += above.size();
  return SparseOutcome::kReconstructed;
}

}  // namespace prt
