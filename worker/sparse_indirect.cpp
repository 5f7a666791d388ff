// Sparse precomputation of the indirect transport (see sparse_indirect.h).
#include "worker/sparse_indirect.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>

#include "worker/column_order.h"

namespace prt {

namespace {
double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

uint64_t GatheredBounce::Evaluate(const SpatialSample& x, uint64_t index,
                                  std::span<const uint32_t> texels, float* out) const {
  thread_local std::vector<GatherTerm> terms;
  thread_local std::vector<float> near;
  const GatherStats st =
      texels.empty()
          ? gatherer_.GatherRow(x, index, bounce_, channels_, previous_, vertex_count_,
                                prev_channels_, cols_, out, terms, near)
          : gatherer_.GatherTexels(x, index, bounce_, channels_, previous_, vertex_count_,
                                   prev_channels_, cols_, texels, out, terms, near);
  return st.rays_traced;
}

uint64_t PathTracedIndirect::Evaluate(const SpatialSample& x, uint64_t index,
                                      std::span<const uint32_t> texels, float* out) const {
  return reference_.ComputeIndirect(x, index, channels_, texels, out).rays_traced();
}

int IndirectFeatures(int direct_features, int cubemap_n, int indirect_n) {
  const double rate = double(direct_features) / (6.0 * cubemap_n * cubemap_n);
  return std::max(8, static_cast<int>(std::lround(rate * 6.0 * indirect_n * indirect_n)));
}

SparseIndirectOptions IndirectOptionsOf(const SparsePlan& plan, int cubemap_n, int indirect_n) {
  SparseIndirectOptions o;
  o.features = IndirectFeatures(plan.sparse.features, cubemap_n, indirect_n);
  o.lambda = plan.sparse.lambda;
  o.min_neighbors = plan.sparse.min_neighbors;
  o.min_normal_cos = plan.sparse.min_normal_cos;
  o.max_residual = plan.sparse.max_residual;
  return o;
}

SparseIndirectStats& SparseIndirectStats::operator+=(const SparseIndirectStats& o) {
  dense_rows += o.dense_rows;
  reconstructed += o.reconstructed;
  fallback_too_few_neighbors += o.fallback_too_few_neighbors;
  fallback_solve_failed += o.fallback_solve_failed;
  fallback_poor_fit += o.fallback_poor_fit;
  texels_evaluated += o.texels_evaluated;
  texels_total += o.texels_total;
  rays += o.rays;
  seconds_dense += o.seconds_dense;
  seconds_sparse += o.seconds_sparse;
  return *this;
}

std::vector<uint32_t> ChooseIndirectFeatures(std::span<const IndirectNeighbor> neighbors,
                                             int channels, std::size_t cols, int count) {
  const std::size_t want =
      std::min<std::size_t>(cols, static_cast<std::size_t>(std::max(0, count)));
  std::vector<double> mean(cols, 0.0), var(cols, 0.0);
  const double k = static_cast<double>(std::max<std::size_t>(1, neighbors.size()));
  for (int c = 0; c < channels; ++c) {
    std::vector<double> s(cols, 0.0), s2(cols, 0.0);
    for (const IndirectNeighbor& nb : neighbors) {
      const float* r = nb.row + static_cast<std::size_t>(c) * cols;
      for (std::size_t j = 0; j < cols; ++j) {
        s[j] += r[j];
        s2[j] += double(r[j]) * r[j];
      }
    }
    for (std::size_t j = 0; j < cols; ++j) {
      const double m = s[j] / k;
      mean[j] += m;
      var[j] += std::max(0.0, s2[j] / k - m * m);
    }
  }
  std::vector<uint32_t> order(cols);
  std::iota(order.begin(), order.end(), 0u);
  std::vector<uint8_t> taken(cols, 0);
  std::vector<uint32_t> out;
  out.reserve(want);
  auto take_best = [&](const std::vector<double>& key, std::size_t upto) {
    std::vector<uint32_t> cand;
    for (uint32_t j : order)
      if (!taken[j]) cand.push_back(j);
    const std::size_t m = std::min(cand.size(), upto - out.size());
    std::partial_sort(
        cand.begin(), cand.begin() + static_cast<std::ptrdiff_t>(m), cand.end(),
        [&](uint32_t a, uint32_t b) { return key[a] != key[b] ? key[a] > key[b] : a < b; });
    for (std::size_t i = 0; i < m; ++i) {
      taken[cand[i]] = 1;
      out.push_back(cand[i]);
    }
  };
  take_best(var, want / 2);  // where the neighbours disagree: what tells them apart
  take_best(mean, want);     // where the light is: what sets the level
  std::sort(out.begin(), out.end());
  return out;
}

SparseOutcome ReconstructIndirectRow(const IndirectComponent& component, const SpatialSample& x,
                                     uint64_t index, std::span<const IndirectNeighbor> neighbors,
                                     const SparseIndirectOptions& options, L1Solver& solver,
                                     float* row, SparseIndirectStats& stats) {
  const int C = component.channels();
  const std::size_t cols = component.cols();
  stats.texels_total += cols;
  auto whole_row = [&](SparseOutcome why, uint64_t& counter) {
    ++counter;
    stats.rays += component.Evaluate(x, index, {}, row);
    stats.texels_evaluated += cols;
    for (std::size_t i = 0; i < static_cast<std::size_t>(C) * cols; ++i)
      if (!std::isfinite(row[i])) row[i] = 0.0f;
    return why;
  };
  std::vector<IndirectNeighbor> same_side;
  if (options.min_normal_cos > -1) {
    const Vec3 nx = Normalize(x.normal);
    for (const IndirectNeighbor& nb : neighbors)
      if (Dot(nx, Normalize(nb.normal)) >= options.min_normal_cos) same_side.push_back(nb);
    neighbors = same_side;
  }
  if (static_cast<int>(neighbors.size()) < options.min_neighbors)
    return whole_row(SparseOutcome::kTooFewNeighbors, stats.fallback_too_few_neighbors);

  const std::vector<uint32_t> feats = ChooseIndirectFeatures(neighbors, C, cols, options.features);
  const std::size_t F = feats.size();
  std::vector<float> traced(static_cast<std::size_t>(C) * F);
  stats.rays += component.Evaluate(x, index, feats, traced.data());
  stats.texels_evaluated += F;

  // Eq. 5 over every channel's feature values.
  const int m = static_cast<int>(static_cast<std::size_t>(C) * F);
  const int k = static_cast<int>(neighbors.size());
  std::vector<double> A(static_cast<std::size_t>(m) * k), b(static_cast<std::size_t>(m));
  for (int c = 0; c < C; ++c)
    for (std::size_t f = 0; f < F; ++f) {
      const std::size_t i = static_cast<std::size_t>(c) * F + f;
      b[i] = std::isfinite(traced[i]) ? traced[i] : 0.0;
      for (int q = 0; q < k; ++q)
        A[i + static_cast<std::size_t>(m) * q] =
            neighbors[static_cast<std::size_t>(q)]
                .row[static_cast<std::size_t>(c) * cols + feats[f]];
    }
  const L1Result r = solver.Solve(A, b, m, k);
  if (r.status == L1Status::kFailed)
    return whole_row(SparseOutcome::kSolveFailed, stats.fallback_solve_failed);
  if (options.max_residual > 0) {
    double rr = 0, bb = 0;
    for (int i = 0; i < m; ++i) {
      double f = -b[static_cast<std::size_t>(i)];
      for (int q = 0; q < k; ++q)
        f += A[static_cast<std::size_t>(i) + static_cast<std::size_t>(m) * q] * r.alpha[q];
      rr += f * f;
      bb += b[static_cast<std::size_t>(i)] * b[static_cast<std::size_t>(i)];
    }
    if (bb > 0 && rr > options.max_residual * options.max_residual * bb)
      return whole_row(SparseOutcome::kPoorFit, stats.fallback_poor_fit);
  }
  // Eq. 4, then the evaluated values exactly.
  std::fill(row, row + static_cast<std::size_t>(C) * cols, 0.0f);
  for (int q = 0; q < k; ++q) {
    const auto a = static_cast<float>(r.alpha[static_cast<std::size_t>(q)]);
    if (a == 0.0f) continue;
    const float* src = neighbors[static_cast<std::size_t>(q)].row;
    for (std::size_t i = 0; i < static_cast<std::size_t>(C) * cols; ++i) row[i] += a * src[i];
  }
  for (std::size_t i = 0; i < static_cast<std::size_t>(C) * cols; ++i)
    row[i] = std::isfinite(row[i]) ? std::max(0.0f, row[i]) : 0.0f;
  for (int c = 0; c < C; ++c)
    for (std::size_t f = 0; f < F; ++f)
      row[static_cast<std::size_t>(c) * cols + feats[f]] =
          static_cast<float>(b[static_cast<std::size_t>(c) * F + f]);
  ++stats.reconstructed;
  return SparseOutcome::kReconstructed;
}

void RunSparseIndirect(const IndirectComponent& component, std::span<const SpatialSample> samples,
                       std::span<const uint8_t> is_dense, double radius, int max_neighbors,
                       const SparseIndirectOptions& options, float* out, SparseIndirectStats& stats,
                       std::span<const std::vector<SampleWeight>> combination,
                       const IndirectComponent* sparse_component) {
  const std::size_t N = samples.size();
  const int C = component.channels();
  const std::size_t cols = component.cols();
  std::vector<uint32_t> dense;
  for (uint32_t s = 0; s < N; ++s)
    if (is_dense[s]) dense.push_back(s);
  std::mutex mutex;
  // Dense rows, whole: one row per sample (channels × cols) then scattered channel-major.
  const double t0 = Now();
  std::vector<float> dense_rows(dense.size() * C * cols);
  tbb::parallel_for(std::size_t{0}, dense.size(), [&](std::size_t i) {
    float* r = dense_rows.data() + i * C * cols;
    const uint64_t rays = component.Evaluate(samples[dense[i]], dense[i], {}, r);
    for (std::size_t e = 0; e < C * cols; ++e)
      if (!std::isfinite(r[e])) r[e] = 0.0f;
    std::lock_guard<std::mutex> lock(mutex);
    stats.rays += rays;
  });
  stats.dense_rows += dense.size();
  stats.texels_evaluated += dense.size() * cols;
  stats.texels_total += dense.size() * cols;
  auto scatter = [&](uint32_t s, const float* r) {
    for (int c = 0; c < C; ++c)
      std::copy_n(r + c * cols, cols, out + (static_cast<std::size_t>(c) * N + s) * cols);
  };
  for (std::size_t i = 0; i < dense.size(); ++i)
    scatter(dense[i], dense_rows.data() + i * C * cols);
  const double t1 = Now();
  stats.seconds_dense += t1 - t0;

  // Sparse vertices along a Hilbert curve (neighbouring vertices share dense neighbours).
  std::vector<Vec3> pts;
  for (uint32_t d : dense) pts.push_back(samples[d].position);
  std::vector<uint32_t> slot(N, 0);
  for (std::size_t i = 0; i < dense.size(); ++i) slot[dense[i]] = static_cast<uint32_t>(i);
  const NeighborIndex index(pts, dense);
  std::vector<Vec3> all(N);
  for (std::size_t s = 0; s < N; ++s) all[s] = samples[s].position;
  std::vector<uint32_t> sparse_ids;
  for (uint32_t s : HilbertOrder(all))
    if (!is_dense[s]) sparse_ids.push_back(s);
  tbb::enumerable_thread_specific<L1Solver> solvers([&] {
    L1Options o;
    o.lambda = options.lambda;
    return L1Solver(o);
  });
  tbb::enumerable_thread_specific<SparseIndirectStats> local;
  tbb::parallel_for(std::size_t{0}, sparse_ids.size(), [&](std::size_t i) {
    const uint32_t s = sparse_ids[i];
    thread_local std::vector<float> row;
    row.resize(C * cols);
    // A combination of dense samples only (a reconstructed T⁰ row always is; anything else
    // evaluates its features).
    const bool combine =
        options.direct_weights && s < combination.size() && !combination[s].empty() &&
        std::all_of(combination[s].begin(), combination[s].end(),
                    [&](const SampleWeight& w) { return w.sample < N && is_dense[w.sample]; });
    if (combine) {
      CombineRows(
          combination[s],
          [&](uint32_t d) {
            return dense_rows.data() + static_cast<std::size_t>(slot[d]) * C * cols;
          },
          C * cols, row.data());
      SparseIndirectStats& l = local.local();
      ++l.reconstructed;
      l.texels_total += cols;
      scatter(s, row.data());
      return;
    }
    ReconstructIndirectAt(
        sparse_component != nullptr ? *sparse_component : component, samples, s, index, radius,
        max_neighbors,
        [&](uint32_t d) {
          return dense_rows.data() + static_cast<std::size_t>(slot[d]) * C * cols;
        },
        options, solvers.local(), row.data(), local.local());
    scatter(s, row.data());
  });
  for (const SparseIndirectStats& l : local) stats += l;
  stats.seconds_sparse += Now() - t1;
}

}  // namespace prt
