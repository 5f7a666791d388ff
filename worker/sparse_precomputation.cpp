#include "worker/sparse_precomputation.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <string>

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
  p.rank_floor = s.rank_floor;
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
  if (plan.rank_floor > 0) {
    if (static_cast<int>(rows.size()) < std::max(1, plan.sparse.min_neighbors)) return empty;
    const int rank = std::max(1, LocalRank(rows, low_dim, plan.rank_threshold));
    return rank <= plan.rank_floor ? -1 : rank;
  }
  return rows.empty() ? empty : std::max(1, LocalRank(rows, low_dim, plan.rank_threshold));
}

std::vector<uint32_t> SparsePickByRank(std::span<const uint32_t> candidates,
                                       std::span<const double> weights, std::size_t picks,
                                       const SparsePlan& plan, int it) {
  double top = 0;
  for (double w : weights) top = std::max(top, w);
  std::vector<uint32_t> ids;
  std::vector<double> w;
  for (std::size_t i = 0; i < candidates.size(); ++i) {
    if (weights[i] < 0) continue;  // covered (rank_floor)
    ids.push_back(candidates[i]);
    w.push_back(weights[i] > 0 ? weights[i] : (top > 0 ? top : 1.0));
  }
  if (plan.rank_floor > 0 && !candidates.empty())
    picks = static_cast<std::size_t>(
        std::ceil(static_cast<double>(picks) * static_cast<double>(ids.size()) /
                  static_cast<double>(candidates.size())));
  return WeightedSampleWithoutReplacement(ids, w, std::min(picks, ids.size()),
                                          plan.seed + 7919 * (it + 1));
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

std::vector<uint8_t> SparseSkipOf(std::span<const SpatialSample> samples) {
  std::vector<uint8_t> skip(samples.size(), 0);
  bool any = false;
  for (std::size_t s = 0; s < samples.size(); ++s) any |= (skip[s] = samples[s].background) != 0;
  return any ? skip : std::vector<uint8_t>{};
}

SparseScheduleCounts RunSparseSchedule(std::size_t N, const SparsePlan& plan, SparseSteps& steps,
                                       std::span<const uint8_t> skip) {
  SparseScheduleCounts c;
  c.is_dense.assign(N, 0);
  if (N == 0) return c;
  if (!skip.empty() && skip.size() != N)
    throw std::invalid_argument("RunSparseSchedule: skip has " + std::to_string(skip.size()) +
                                " flags for " + std::to_string(N) + " samples");
  // The samples that take part, in order: the schedule picks among their indices 0 … M−1 and
  // hands the steps global ids (the identity without a skipped sample).
  std::vector<uint32_t> part, local(N, 0);
  for (uint32_t s = 0; s < N; ++s)
    if (skip.empty() || !skip[s]) {
      local[s] = static_cast<uint32_t>(part.size());
      part.push_back(s);
    }
  const std::size_t M = part.size();
  if (M == 0) return c;
  const auto global = [&](std::vector<uint32_t> ids) {
    for (uint32_t& s : ids) s = part[s];
    return ids;
  };
  std::vector<uint8_t> local_dense(M, 0);  // SparseRankCandidates' view
  auto mark = [&](std::span<const uint32_t> ids) {
    for (uint32_t s : ids) {
      c.is_dense[s] = 1;
      local_dense[local[s]] = 1;
    }
  };
  // §4.1: the initial random dense set, then rank-weighted rounds.
  const std::size_t budget = SparseDenseBudget(M, plan);
  std::vector<uint32_t> dense =
      global(InitialDenseSet(M, SparseInitialDenseCount(M, plan), plan.seed));
  c.dense_initial = dense.size();
  steps.Dense("dense-initial", dense);
  mark(dense);
  const int rounds = SparseRounds(plan);
  for (int it = 0; it < rounds && dense.size() < budget; ++it) {
    const std::size_t picks = SparsePicksForRound(budget, dense.size(), rounds, it);
    const std::vector<uint32_t> cand = global(SparseRankCandidates(local_dense, picks, plan, it));
    const std::string k = std::to_string(it + 1);
    const std::vector<double> weight = steps.Rank("rank-" + k, it, dense, cand);
    const std::vector<uint32_t> next = SparsePickByRank(cand, weight, picks, plan, it);
    c.candidates_ranked += cand.size();
    c.dense_by_rank += next.size();
    steps.Dense("dense-rank-" + k, next);
    mark(next);
    dense.insert(dense.end(), next.begin(), next.end());
  }
  // §5: every other sample from its dense neighbours; fallbacks become dense. A skipped sample
  // is not reconstructed (it is passed as if dense, and is in nobody's neighbour set).
  std::sort(dense.begin(), dense.end());
  std::vector<uint8_t> settled = c.is_dense;
  for (uint32_t s = 0; s < N; ++s)
    if (!skip.empty() && skip[s]) settled[s] = 1;
  const std::vector<uint32_t> fallback = steps.Reconstruct("sparse-reconstruct", dense, settled);
  c.dense_fallback = fallback.size();
  steps.Dense("dense-fallback", fallback);
  mark(fallback);
  return c;
}

namespace {

// The steps in this process: every row in memory, TBB threads.
class InProcessSteps final : public SparseSteps {
 public:
  using ProgressFn = std::function<void(const char*, std::size_t, std::size_t)>;
  InProcessSteps(const TransportSampler& sampler, std::span<const SpatialSample> samples,
                 const SparsePlan& plan, SparseReport& report, float* out,
                 const ProgressFn& progress)
      : sampler_(sampler),
        samples_(samples),
        plan_(plan),
        report_(report),
        out_(out),
        progress_(progress),
        T_(sampler.layout().texel_count()),
        n_(sampler.layout().n()),
        m_(SparseRankResolution(plan, n_)),
        Tm_(static_cast<std::size_t>(6) * m_ * m_),
        vis_(samples.size()),
        low_(samples.size()),
        feat_(samples.size()) {}

  std::size_t texel_count() const { return T_; }

  void Dense(const std::string& step, std::span<const uint32_t> ids) override {
    const double t0 = Now();
    std::size_t done = 0;
    tbb::parallel_for(std::size_t{0}, ids.size(), [&](std::size_t i) {
      const uint32_t s = ids[i];
      DenseRow row;
      const AngularStats st = SampleDenseRowAdaptive(sampler_, samples_[s], s, plan_.angular, row);
      std::copy(row.transport.begin(), row.transport.end(), out_ + s * T_);
      low_[s].resize(Tm_);
      DownsampleRow(row.transport.data(), n_, m_, low_[s].data());
      vis_[s] = std::move(row.visibility);
      feat_[s] = std::move(row.feature);
      std::lock_guard<std::mutex> lock(stats_mutex_);
      report_.dense_angular += st;
      if (progress_ && (++done % 256 == 0 || done == ids.size()))
        progress_(step.c_str(), done, ids.size());
    });
    report_.seconds_dense += Now() - t0;
  }

  std::vector<double> Rank(const std::string&, int, std::span<const uint32_t> dense,
                           std::span<const uint32_t> cand) override {
    const double t0 = Now();
    const NeighborIndex index = IndexOf(dense);
    std::vector<double> weight(cand.size(), 0.0);
    tbb::parallel_for(std::size_t{0}, cand.size(), [&](std::size_t i) {
      const std::vector<uint32_t> nb = index.RadiusSearch(plan_.SearchPosition(samples_[cand[i]]),
                                                          plan_.radius, plan_.max_neighbors);
      std::vector<const float*> rows;
      rows.reserve(nb.size());
      for (uint32_t d : nb) rows.push_back(low_[d].data());
      weight[i] = SparseCandidateWeight(rows, Tm_, plan_);
    });
    for (std::size_t i = 0; i < cand.size(); ++i)
      report_.local_rank[cand[i]] = static_cast<int>(weight[i]);
    report_.seconds_rank += Now() - t0;
    return weight;
  }

  std::vector<uint32_t> Reconstruct(const std::string& step, std::span<const uint32_t> dense,
                                    std::span<const uint8_t> is_dense) override {
    const double t0 = Now();
    const std::size_t N = samples_.size();
    const NeighborIndex index = IndexOf(dense);
    // Along a Hilbert curve of the positions, as the farm orders its sparse jobs (there by Morton
    // key): consecutive vertices share most of their dense neighbours, so the neighbours' rows
    // (48 KB each, read twice per vertex) come from cache instead of memory. The result does not
    // depend on the order.
    std::vector<Vec3> all_positions(N);
    for (std::size_t s = 0; s < N; ++s) all_positions[s] = plan_.SearchPosition(samples_[s]);
    std::vector<uint32_t> sparse_ids;
    for (uint32_t s : HilbertOrder(all_positions))
      if (!is_dense[s]) sparse_ids.push_back(s);
    std::vector<uint8_t> fallback(N, 0);
    tbb::enumerable_thread_specific<L1Solver> solvers([&] {
      L1Options o;
      o.lambda = plan_.sparse.lambda;
      return L1Solver(o);
    });
    std::size_t done = 0;
    // Batches of consecutive vertices along the curve: ReconstructSparseRows reads their shared
    // neighbours' rows once per batch; a vertex's row does not depend on its batch.
    const std::size_t batches = (sparse_ids.size() + kSparseRowBatch - 1) / kSparseRowBatch;
    tbb::parallel_for(std::size_t{0}, batches, [&](std::size_t bi) {
      const std::size_t first = bi * kSparseRowBatch;
      const std::size_t last = std::min(sparse_ids.size(), first + kSparseRowBatch);
      std::vector<std::vector<uint32_t>> nb(last - first);
      std::vector<std::vector<DenseNeighbor>> nbs(last - first);
      std::vector<std::vector<NeighborWeight>> w(last - first);
      std::vector<SparseRowTask> tasks;
      for (std::size_t i = first; i < last; ++i) {
        const uint32_t s = sparse_ids[i];
        nb[i - first] = index.RadiusSearch(plan_.SearchPosition(samples_[s]), plan_.radius,
                                           plan_.max_neighbors);
        for (uint32_t d : nb[i - first])
          nbs[i - first].push_back({out_ + static_cast<std::size_t>(d) * T_, vis_[d].data(),
                                    feat_[d].data(), samples_[d].normal});
        tasks.push_back({&samples_[s], s, nbs[i - first], out_ + static_cast<std::size_t>(s) * T_,
                         nullptr, &w[i - first]});
      }
      SparseStats st;
      ReconstructSparseRows(sampler_, tasks, plan_.sparse, solvers.local(), st);
      for (std::size_t i = first; i < last; ++i) {
        const uint32_t s = sparse_ids[i];
        if (tasks[i - first].outcome != SparseOutcome::kReconstructed) {
          fallback[s] = 1;
        } else {
          std::vector<SampleWeight>& c = report_.combination[s];
          c.clear();
          for (const NeighborWeight& x : w[i - first])
            c.push_back({nb[i - first][x.neighbor], x.alpha});
        }
      }
      std::lock_guard<std::mutex> lock(stats_mutex_);
      report_.sparse_stats += st;
      const std::size_t before = done;
      done += last - first;
      if (progress_ && (done / 1024 != before / 1024 || done == sparse_ids.size()))
        progress_(step.c_str(), done, sparse_ids.size());
    });
    report_.seconds_sparse += Now() - t0;
    std::vector<uint32_t> fb;
    for (uint32_t s = 0; s < N; ++s)
      if (fallback[s]) fb.push_back(s);
    return fb;
  }

 private:
  // Over the dense positions, in the order given (as the farm builds it).
  NeighborIndex IndexOf(std::span<const uint32_t> dense) const {
    std::vector<Vec3> pts;
    pts.reserve(dense.size());
    for (uint32_t d : dense) pts.push_back(plan_.SearchPosition(samples_[d]));
    return NeighborIndex(pts, dense);
  }

  const TransportSampler& sampler_;
  std::span<const SpatialSample> samples_;
  const SparsePlan& plan_;
  SparseReport& report_;
  float* out_;
  const ProgressFn& progress_;
  const std::size_t T_;
  const int n_;
  const int m_;
  const std::size_t Tm_;
  // Dense records, indexed by sample.
  std::vector<std::vector<float>> vis_, low_;
  std::vector<std::vector<uint8_t>> feat_;
  std::mutex stats_mutex_;
};

}  // namespace

void RunSparsePrecomputation(
    const TransportSampler& sampler, std::span<const SpatialSample> samples, const SparsePlan& plan,
    SparseReport& report, float* out,
    const std::function<void(const char*, std::size_t, std::size_t)>& progress) {
  const std::size_t N = samples.size();
  report = SparseReport{};
  report.samples = N;
  report.is_dense.assign(N, 0);
  report.local_rank.assign(N, -1);
  report.combination.assign(N, {});
  if (N == 0) return;
  InProcessSteps steps(sampler, samples, plan, report, out, progress);
  // Background pixels take no part; their rows are 0 (worker/camera_samples.h).
  const std::vector<uint8_t> skip = SparseSkipOf(samples);
  for (std::size_t s = 0; s < skip.size(); ++s)
    if (skip[s])
      std::fill(out + s * steps.texel_count(), out + (s + 1) * steps.texel_count(), 0.0f);
  SparseScheduleCounts counts = RunSparseSchedule(N, plan, steps, skip);
  report.dense_initial = counts.dense_initial;
  report.dense_by_rank = counts.dense_by_rank;
  report.dense_fallback = counts.dense_fallback;
  report.is_dense = std::move(counts.is_dense);
  report.sparse = report.sparse_stats.reconstructed;
  report.texels_above_horizon_total =
      report.dense_angular.texels_above_horizon + report.sparse_stats.texels_above_horizon;
}

}  // namespace prt
