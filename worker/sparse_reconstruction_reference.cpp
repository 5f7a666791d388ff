// The sparse-row reconstruction as it was before the fast path (docs/sparse-precomputation.md,
// "The reconstruction's own cost"): every step on its own pass over the neighbours' rows, the
// solve through L1Solver::Solve (Eigen's AᵀA, then SolveGram). Kept, unchanged, as the reference
// the fast ReconstructSparseRow is tested against (sparse_reconstruction_test.cpp) and timed
// against (prt-sparse-reconstruct-bench); nothing in the farm calls it.
#include "worker/sparse_reconstruction_reference.h"

#include <algorithm>
#include <cmath>

#include "worker/local_rank.h"

namespace prt {

namespace {
// Contiguous runs [first, last) of the texels above a horizon: a horizon cuts each face row in
// one interval, so there are at most about 6·n runs, and the loops over the neighbours' rows
// below touch only the half of each row that matters.
using Runs = std::vector<std::pair<uint32_t, uint32_t>>;
Runs RunsOf(const uint8_t* above, std::size_t total) {
  Runs runs;
  for (std::size_t j = 0; j < total;) {
    if (!above[j]) {
      ++j;
      continue;
    }
    const std::size_t first = j;
    while (j < total && above[j]) ++j;
    runs.push_back({static_cast<uint32_t>(first), static_cast<uint32_t>(j)});
  }
  return runs;
}

// Per-texel statistics over the neighbours on the given runs (entries outside them are left
// 0), neighbour-outer so that the inner loops run contiguously over texels.
// Per-thread buffers of the functions below, reused from row to row: a sparse row used to
// allocate and zero ten full-sphere arrays, which showed as memset and page faults in the profile.
// Only the texels on the runs are ever read, so only those are cleared. Thread-local is safe:
// nothing a row calls (the sampler's texel tracing, the L1 solver) runs parallel loops, so a
// thread never starts another row while it is inside one.
struct RowScratch {
  std::vector<float> s, s2, var, unocc, acc, vmin;
  std::vector<uint16_t> feat;
  std::vector<uint8_t> above, fully;
};
RowScratch& ThreadScratch() {
  thread_local RowScratch scratch;
  return scratch;
}

void ClearOnRuns(std::vector<float>& v, std::size_t total, const Runs& runs) {
  if (v.size() < total) v.resize(total);
  for (const auto& [first, last] : runs) std::fill(v.begin() + first, v.begin() + last, 0.0f);
}

void NeighbourStatistics(std::span<const DenseNeighbor> neighbors, std::size_t total,
                         const Runs& runs, std::vector<float>& var, std::vector<uint16_t>& feat) {
  RowScratch& scratch = ThreadScratch();
  std::vector<float>& s = scratch.s;
  std::vector<float>& s2 = scratch.s2;
  ClearOnRuns(s, total, runs);
  ClearOnRuns(s2, total, runs);
  if (feat.size() < total) feat.resize(total);
  for (const auto& [first, last] : runs)
    std::fill(feat.begin() + first, feat.begin() + last, uint16_t{0});
  float* __restrict sp = s.data();
  float* __restrict s2p = s2.data();
  uint16_t* __restrict fp = feat.data();
  for (const DenseNeighbor& nb : neighbors) {
    const float* __restrict t = nb.transport;
    const uint8_t* __restrict f = nb.feature;
    for (const auto& [first, last] : runs) {
      for (std::size_t j = first; j < last; ++j) {
        sp[j] += t[j];
        s2p[j] += t[j] * t[j];
        fp[j] = static_cast<uint16_t>(fp[j] + f[j]);
      }
    }
  }
  if (var.size() < total) var.resize(total);  // written on the runs below, read only there
  const float inv = neighbors.empty() ? 0.0f : 1.0f / static_cast<float>(neighbors.size());
  for (const auto& [first, last] : runs) {
    for (std::size_t j = first; j < last; ++j) {
      const float m = s[j] * inv;
      var[j] = std::max(0.0f, s2[j] * inv - m * m);
    }
  }
}

// `count` texels, best first by the keys below; with `min_extra` < count, only as many as there
// are texels with a positive primary key plus `min_extra`, at most `count`.
std::vector<uint32_t> ChooseFromStatistics(const uint8_t* above, std::size_t total,
                                           const std::vector<float>& var,
                                           const std::vector<uint16_t>& feat, int count,
                                           int min_extra, uint64_t seed) {
  struct Cand {
    double key;
    uint32_t texel;
  };
  std::vector<Cand> cands;
  cands.reserve(total / 2 + 8);
  std::size_t primary = 0;
  for (std::size_t j = 0; j < total; ++j) {
    if (!above[j]) continue;
    // Primary: the paper's product of variance and feature count; then variance alone; then a
    // deterministic spread so that a region where all neighbours agree still gets constraints.
    const double v = var[j];
    primary += v * feat[j] > 0;
    cands.push_back(
        {v * feat[j] + 1e-3 * v + 1e-12 * HashUniform(seed, j), static_cast<uint32_t>(j)});
  }
  std::size_t take =
      std::min<std::size_t>(static_cast<std::size_t>(std::max(count, 0)), cands.size());
  if (min_extra < count)
    take = std::min(take, primary + static_cast<std::size_t>(std::max(min_extra, 0)));
  auto better = [](const Cand& a, const Cand& b) {
    return a.key != b.key ? a.key > b.key : a.texel < b.texel;
  };
  std::nth_element(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(take), cands.end(),
                   better);
  std::vector<uint32_t> out(take);
  for (std::size_t i = 0; i < take; ++i) out[i] = cands[i].texel;
  std::sort(out.begin(), out.end());
  return out;
}
}  // namespace

SparseOutcome ReconstructSparseRowReference(const TransportSampler& sampler,
                                            const SpatialSample& sample, uint64_t sample_index,
                                            std::span<const DenseNeighbor> neighbors,
                                            const SparseOptions& options, L1Solver& solver,
                                            float* row, SparseStats& stats, float* variance,
                                            std::vector<NeighborWeight>* weights) {
  std::vector<DenseNeighbor> same_side;
  std::vector<uint32_t> kept;  // index into the caller's neighbours of each one used
  if (options.min_normal_cos > -1) {
    const Vec3 nx = Normalize(sample.normal);
    for (std::size_t i = 0; i < neighbors.size(); ++i)
      if (Dot(nx, Normalize(neighbors[i].normal)) >= options.min_normal_cos) {
        same_side.push_back(neighbors[i]);
        kept.push_back(static_cast<uint32_t>(i));
      }
    stats.neighbors_dropped_by_normal += neighbors.size() - same_side.size();
    neighbors = same_side;
  }
  if (static_cast<int>(neighbors.size()) < options.min_neighbors) {
    ++stats.fallback_too_few_neighbors;
    return SparseOutcome::kTooFewNeighbors;
  }
  const CubemapLayout& layout = sampler.layout();
  const std::size_t total = layout.texel_count();
  RowScratch& scratch = ThreadScratch();
  std::vector<uint8_t>& above = scratch.above;
  std::vector<uint8_t>& fully = scratch.fully;
  above.resize(total);
  fully.resize(total);
  const std::size_t above_count =
      SampleHorizonMask(sampler, sample, sample_index, above.data(), fully.data());
  const Runs runs = RunsOf(above.data(), total);
  std::vector<float>& var = scratch.var;
  std::vector<uint16_t>& featcount = scratch.feat;
  NeighbourStatistics(neighbors, total, runs, var, featcount);
  const std::vector<uint32_t> feats = ChooseFromStatistics(
      above.data(), total, var, featcount, options.features, options.min_features, sample_index);
  const int m = static_cast<int>(feats.size());
  const int k = static_cast<int>(neighbors.size());
  std::vector<float> traced(feats.size()), traced_unocc(feats.size()), traced_var;
  if (variance != nullptr) traced_var.resize(feats.size());
  stats.trace +=
      sampler.ComputeTexels(sample, sample_index, feats, traced.data(), traced_unocc.data(),
                            variance != nullptr ? traced_var.data() : nullptr);
  if (variance != nullptr) {
    std::fill(variance, variance + total, 0.0f);
    for (std::size_t i = 0; i < feats.size(); ++i) variance[feats[i]] = traced_var[i];
  }
  stats.features_traced += feats.size();

  // Unoccluded values U_x(j) of every texel above this vertex's horizon: exact where the texel
  // is entirely above, the sampler's estimate where it straddles the horizon.
  std::vector<uint32_t> above_list;
  above_list.reserve(above_count);
  for (std::size_t j = 0; j < total; ++j)
    if (above[j]) above_list.push_back(static_cast<uint32_t>(j));
  std::vector<float> unocc_list(above_list.size());
  UnoccludedValues(sampler, sample, sample_index, above_list, fully.data(), unocc_list.data());
  std::vector<float>& unocc = scratch.unocc;  // read only above the horizon, all written here
  if (unocc.size() < total) unocc.resize(total);
  for (std::size_t i = 0; i < above_list.size(); ++i) unocc[above_list[i]] = unocc_list[i];
  for (std::size_t i = 0; i < feats.size(); ++i) unocc[feats[i]] = traced_unocc[i];

  // Equations in transport units for both modes, so that each constraint weighs what it adds to
  // the relit radiance: visibility mode fits Σ α_k v_k(j) · U_x(j) to T_x(j) (the neighbours'
  // visibility under this vertex's own cosine); transport mode fits Σ α_k T_k(j) to T_x(j).
  const bool vis = options.mode == InterpolationMode::kVisibility;
  // The partition-of-unity row (SparseOptions::unity_weight): the untraced texels where every
  // neighbour is unoccluded.
  double unity_w = 0;
  if (vis && options.unity_weight > 0) {
    std::vector<float>& vmin = scratch.vmin;
    if (vmin.size() < total) vmin.resize(total);
    for (const auto& [first, last] : runs)
      std::fill(vmin.begin() + first, vmin.begin() + last, 1.0f);
    float* __restrict vm = vmin.data();
    for (const DenseNeighbor& nb : neighbors) {
      const float* __restrict v = nb.visibility;
      for (const auto& [first, last] : runs)
        for (std::size_t j = first; j < last; ++j) vm[j] = std::min(vm[j], v[j]);
    }
    for (uint32_t j : feats) vm[j] = 0.0f;  // traced: already an equation
    double w2 = 0;
    for (const auto& [first, last] : runs)
      for (std::size_t j = first; j < last; ++j)
        if (vm[j] >= 1.0f) w2 += static_cast<double>(unocc[j]) * unocc[j];
    unity_w = options.unity_weight * std::sqrt(w2);
  }
  const int rows = m + (unity_w > 0 ? 1 : 0);
  std::vector<double> A(static_cast<std::size_t>(rows) * k), b(static_cast<std::size_t>(rows));
  if (rows > m) {
    b[static_cast<std::size_t>(m)] = unity_w;
    for (int c = 0; c < k; ++c)
      A[static_cast<std::size_t>(m) + static_cast<std::size_t>(rows) * c] = unity_w;
  }
  for (int i = 0; i < m; ++i) {
    const uint32_t j = feats[static_cast<std::size_t>(i)];
    const double u = unocc[j];
    b[static_cast<std::size_t>(i)] = traced[static_cast<std::size_t>(i)];
    for (int c = 0; c < k; ++c) {
      const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
      A[static_cast<std::size_t>(i) + static_cast<std::size_t>(rows) * c] =
          vis ? nb.visibility[j] * u : nb.transport[j];
    }
  }
  std::vector<double> alpha;
  if (options.solver == SolverKind::kLeastSquares) {
    alpha = L1Solver::LeastSquares(A, b, rows, k);
  } else {
    const L1Result r = solver.Solve(A, b, rows, k);
    if (r.status == L1Status::kFailed) {
      ++stats.fallback_solve_failed;
      return SparseOutcome::kSolveFailed;
    }
    stats.solved_lars += r.status == L1Status::kLars;
    stats.solved_admm += r.status == L1Status::kAdmm;
    stats.zero_systems += r.status == L1Status::kZeroSystem;
    alpha = r.alpha;
  }
  if (options.max_residual > 0) {  // over the traced features only
    double rr = 0, bb = 0;
    for (int i = 0; i < m; ++i) {
      double f = -b[static_cast<std::size_t>(i)];
      for (int c = 0; c < k; ++c)
        f += A[static_cast<std::size_t>(i) + static_cast<std::size_t>(rows) * c] *
             alpha[static_cast<std::size_t>(c)];
      rr += f * f;
      bb += b[static_cast<std::size_t>(i)] * b[static_cast<std::size_t>(i)];
    }
    if (bb > 0 && rr > options.max_residual * options.max_residual * bb) {
      ++stats.fallback_poor_fit;
      return SparseOutcome::kPoorFit;
    }
  }

  // Eq. 4 on this vertex's own hemisphere (neighbour-outer, contiguous over texels), then the
  // traced values exactly.
  std::vector<float>& acc = scratch.acc;
  ClearOnRuns(acc, total, runs);
  for (int c = 0; c < k; ++c) {
    const float a = static_cast<float>(alpha[static_cast<std::size_t>(c)]);
    if (a == 0.0f) continue;
    const DenseNeighbor& nb = neighbors[static_cast<std::size_t>(c)];
    const float* src = vis ? nb.visibility : nb.transport;
    for (const auto& [first, last] : runs)
      for (std::size_t j = first; j < last; ++j) acc[j] += a * src[j];
  }
  for (std::size_t j = 0; j < total; ++j) {
    if (!above[j]) {
      row[j] = 0.0f;
      continue;
    }
    const float u = unocc[j];
    const float t = vis ? std::clamp(acc[j], 0.0f, 1.0f) * u : std::clamp(acc[j], 0.0f, u);
    row[j] = std::isfinite(t) ? t : 0.0f;
  }
  for (int i = 0; i < m; ++i)
    row[feats[static_cast<std::size_t>(i)]] = traced[static_cast<std::size_t>(i)];
  if (weights != nullptr) {
    weights->clear();
    for (int c = 0; c < k; ++c) {
      const auto a = static_cast<float>(alpha[static_cast<std::size_t>(c)]);
      if (a == 0.0f || !std::isfinite(a)) continue;
      weights->push_back(
          {kept.empty() ? static_cast<uint32_t>(c) : kept[static_cast<std::size_t>(c)], a});
    }
  }
  ++stats.reconstructed;
  stats.texels_above_horizon += above_count;
  return SparseOutcome::kReconstructed;
}

}  // namespace prt
