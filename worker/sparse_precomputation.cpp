#include "worker/sparse_precomputation.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>

#include "worker/column_order.h"
#include "worker/local_rank.h"
#include "worker/neighbor_index.h"

namespace prt {

namespace {
double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

SparsePlan PlanFromSettings(const SparseSettings& s, double scene_diagonal, int cubemap_n) {
  SparsePlan p;
  p.initial_fraction = s.initial_fraction;
  p.dense_budget = s.dense_budget;
  p.iterations = s.iterations;
  p.radius = s.radius * scene_diagonal;
  p.max_neighbors = s.max_neighbors;
  p.seed = s.seed;
  const double scale = static_cast<double>(cubemap_n) * cubemap_n / (32.0 * 32.0);
  p.sparse.features = std::max(8, static_cast<int>(std::lround(s.features * scale)));
  p.sparse.lambda = s.lambda;
  p.angular.window = s.window;
  p.sparse.unity_weight = s.unity_weight;
  p.sparse.max_residual = s.max_residual;
  p.sparse.min_normal_cos = s.min_normal_cos;
  p.rank_resolution = std::min(8, cubemap_n);
  return p;
}

double SparseReport::SampledFraction() const {
  if (texels_above_horizon_total == 0) return 0;
  const double traced =
      static_cast<double>(dense_angular.trace.texels_traced + sparse_stats.trace.texels_traced);
  return traced / static_cast<double>(texels_above_horizon_total);
}

std::vector<uint32_t> InitialDenseSet(std::size_t sample_count, std::size_t count, uint64_t seed) {
  std::vector<uint32_t> ids(sample_count);
  for (std::size_t i = 0; i < sample_count; ++i) ids[i] = static_cast<uint32_t>(i);
  std::vector<double> w(sample_count, 1.0);
  return WeightedSampleWithoutReplacement(ids, w, count, seed ^ 0x1234567ull);
}

std::size_t SparseDenseBudget(std::size_t N, const SparsePlan& plan) {
  return std::min(N,
                  static_cast<std::size_t>(std::ceil(plan.dense_budget * static_cast<double>(N))));
}

std::size_t SparseInitialDenseCount(std::size_t N, const SparsePlan& plan) {
  return std::min(
      SparseDenseBudget(N, plan),
      std::max<std::size_t>(
          1, static_cast<std::size_t>(std::ceil(plan.initial_fraction * static_cast<double>(N)))));
}

int SparseRounds(const SparsePlan& plan) {
  return std::max(1, plan.iterations);
}

std::size_t SparsePicksForRound(std::size_t budget, std::size_t dense_count, int rounds, int it) {
  const std::size_t remaining_rounds = static_cast<std::size_t>(rounds - it);
  return (budget - dense_count + remaining_rounds - 1) / remaining_rounds;
}

std::vector<uint32_t> SparseRankCandidates(std::span<const uint8_t> is_dense, std::size_t picks,
                                           const SparsePlan& plan, int it) {
  std::vector<uint32_t> pool;
  for (std::size_t s = 0; s < is_dense.size(); ++s)
    if (!is_dense[s]) pool.push_back(static_cast<uint32_t>(s));
  const std::size_t ncand = std::min(
      pool.size(), picks * static_cast<std::size_t>(std::max(1, plan.candidates_per_pick)));
  std::vector<double> ones(pool.size(), 1.0);
  return WeightedSampleWithoutReplacement(pool, ones, ncand, plan.seed + 101 * (it + 1));
}

int SparseCandidateWeight(std::span<const float* const> rows, std::size_t low_dim,
                          const SparsePlan& plan) {
  // Rank ≥ 1 everywhere so that every region keeps some chance; an empty neighbourhood (no
  // dense vertex within the radius) gets the largest weight by default: nothing is known there,
  // and a sparse vertex there would fall back to dense anyway.
  const int empty = plan.empty_weight == 0 ? plan.max_neighbors : std::max(0, plan.empty_weight);
  return rows.empty() ? empty : std::max(1, LocalRank(rows, low_dim, plan.rank_threshold));
}

std::vector<uint32_t> SparsePickByRank(std::span<const uint32_t> candidates,
                                       std::span<const double> weights, std::size_t picks,
                                       const SparsePlan& plan, int it) {
  double top = 0;
  for (double w : weights) top = std::max(top, w);
  std::vector<double> w(weights.begin(), weights.end());
  for (double& x : w)
    if (!(x > 0)) x = top > 0 ? top : 1.0;
  return WeightedSampleWithoutReplacement(candidates, w, picks, plan.seed + 7919 * (it + 1));
}

int SparseRankResolution(const SparsePlan& plan, int cubemap_n) {
  return std::min(plan.rank_resolution, cubemap_n);
}

std::vector<float> RunSparsePrecomputation(
    const TransportSampler& sampler, std::span<const SpatialSample> samples, const SparsePlan& plan,
    SparseReport& report,
    const std::function<void(const char*, std::size_t, std::size_t)>& progress) {
  std::vector<float> out(samples.size() * sampler.layout().texel_count(), 0.0f);
  RunSparsePrecomputation(sampler, samples, plan, report, out.data(), progress);
  return out;
}

void RunSparsePrecomputation(
    const TransportSampler& sampler, std::span<const SpatialSample> samples, const SparsePlan& plan,
    SparseReport& report, float* out,
    const std::function<void(const char*, std::size_t, std::size_t)>& progress) {
  const std::size_t N = samples.size();
  const CubemapLayout& layout = sampler.layout();
  const std::size_t T = layout.texel_count();
  const int n = layout.n();
  const int m = SparseRankResolution(plan, n);
  const std::size_t Tm = static_cast<std::size_t>(6) * m * m;
  report = SparseReport{};
  report.samples = N;
  report.is_dense.assign(N, 0);
  report.local_rank.assign(N, -1);
  if (N == 0) return;

  // Dense records, indexed by sample.
  std::vector<std::vector<float>> vis(N), low(N);
  std::vector<std::vector<uint8_t>> feat(N);
  std::mutex stats_mutex;
  auto sample_dense = [&](std::span<const uint32_t> ids, const char* phase) {
    const double t0 = Now();
    std::size_t done = 0;
    tbb::parallel_for(std::size_t{0}, ids.size(), [&](std::size_t i) {
      const uint32_t s = ids[i];
      DenseRow row;
      const AngularStats st = SampleDenseRowAdaptive(sampler, samples[s], s, plan.angular, row);
      std::copy(row.transport.begin(), row.transport.end(), out + s * T);
      low[s].resize(Tm);
      DownsampleRow(row.transport.data(), n, m, low[s].data());
      vis[s] = std::move(row.visibility);
      feat[s] = std::move(row.feature);
      std::lock_guard<std::mutex> lock(stats_mutex);
      report.dense_angular += st;
      report.is_dense[s] = 1;
      if (progress && (++done % 256 == 0 || done == ids.size())) progress(phase, done, ids.size());
    });
    report.seconds_dense += Now() - t0;
  };

  // Phase 1: initial random set, then rank-weighted rounds.
  const std::size_t budget = SparseDenseBudget(N, plan);
  const std::size_t initial = SparseInitialDenseCount(N, plan);
  std::vector<uint32_t> dense = InitialDenseSet(N, initial, plan.seed);
  report.dense_initial = dense.size();
  sample_dense(dense, "dense-initial");
  const int rounds = SparseRounds(plan);
  for (int it = 0; it < rounds && dense.size() < budget; ++it) {
    const double t0 = Now();
    const std::size_t picks = SparsePicksForRound(budget, dense.size(), rounds, it);
    std::vector<Vec3> pts;
    pts.reserve(dense.size());
    for (uint32_t d : dense) pts.push_back(samples[d].position);
    NeighborIndex index(pts, dense);
    // Candidates: a deterministic random subset of the non-dense samples.
    const std::vector<uint32_t> cand = SparseRankCandidates(report.is_dense, picks, plan, it);
    std::vector<double> weight(cand.size(), 0.0);
    tbb::parallel_for(std::size_t{0}, cand.size(), [&](std::size_t i) {
      const std::vector<uint32_t> nb =
          index.RadiusSearch(samples[cand[i]].position, plan.radius, plan.max_neighbors);
      std::vector<const float*> rows;
      rows.reserve(nb.size());
      for (uint32_t d : nb) rows.push_back(low[d].data());
      weight[i] = SparseCandidateWeight(rows, Tm, plan);
    });
    const std::vector<uint32_t> next = SparsePickByRank(cand, weight, picks, plan, it);
    for (std::size_t i = 0; i < cand.size(); ++i)
      report.local_rank[cand[i]] = static_cast<int>(weight[i]);
    report.seconds_rank += Now() - t0;
    report.dense_by_rank += next.size();
    sample_dense(next, "dense-rank");
    dense.insert(dense.end(), next.begin(), next.end());
  }

  // Phase 2: sparse vertices from their dense neighbours.
  {
    const double t0 = Now();
    std::vector<Vec3> pts;
    std::sort(dense.begin(), dense.end());
    pts.reserve(dense.size());
    for (uint32_t d : dense) pts.push_back(samples[d].position);
    NeighborIndex index(pts, dense);
    // Along a Hilbert curve of the positions, as the farm orders its sparse jobs (there by Morton
    // key): consecutive vertices share most of their dense neighbours, so the neighbours' rows
    // (48 KB each, read twice per vertex) come from cache instead of memory. The result does not
    // depend on the order.
    std::vector<Vec3> all_positions(N);
    for (std::size_t s = 0; s < N; ++s) all_positions[s] = samples[s].position;
    std::vector<uint32_t> sparse_ids;
    for (uint32_t s : HilbertOrder(all_positions))
      if (!report.is_dense[s]) sparse_ids.push_back(s);
    std::vector<uint8_t> fallback(N, 0);
    tbb::enumerable_thread_specific<L1Solver> solvers([&] {
      L1Options o;
      o.lambda = plan.sparse.lambda;
      return L1Solver(o);
    });
    std::size_t done = 0;
    tbb::parallel_for(std::size_t{0}, sparse_ids.size(), [&](std::size_t i) {
      const uint32_t s = sparse_ids[i];
      const std::vector<uint32_t> nb =
          index.RadiusSearch(samples[s].position, plan.radius, plan.max_neighbors);
      std::vector<DenseNeighbor> nbs;
      nbs.reserve(nb.size());
      for (uint32_t d : nb)
        nbs.push_back({out + static_cast<std::size_t>(d) * T, vis[d].data(), feat[d].data(),
                       samples[d].normal});
      SparseStats st;
      const SparseOutcome o =
          ReconstructSparseRow(sampler, samples[s], s, nbs, plan.sparse, solvers.local(),
                               out + static_cast<std::size_t>(s) * T, st);
      if (o != SparseOutcome::kReconstructed) fallback[s] = 1;
      std::lock_guard<std::mutex> lock(stats_mutex);
      report.sparse_stats += st;
      if (progress && (++done % 1024 == 0 || done == sparse_ids.size()))
        progress("sparse", done, sparse_ids.size());
    });
    report.seconds_sparse += Now() - t0;
    std::vector<uint32_t> fb;
    for (uint32_t s = 0; s < N; ++s)
      if (fallback[s]) fb.push_back(s);
    report.dense_fallback = fb.size();
    report.sparse = report.sparse_stats.reconstructed;
    if (!fb.empty()) sample_dense(fb, "dense-fallback");
  }
  report.texels_above_horizon_total =
      report.dense_angular.texels_above_horizon + report.sparse_stats.texels_above_horizon;
}

}  // namespace prt
