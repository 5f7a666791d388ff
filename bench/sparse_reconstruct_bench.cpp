// prt-sparse-reconstruct-bench: the sparse-row reconstruction (Huang & Ramamoorthi 2010, §5) on
// real problems, the reference implementation (worker/sparse_reconstruction_reference.h) against
// the fast one (ReconstructSparseRow), in one run on one thread, alternating, so that the ratio
// is robust on a shared machine. The problems: a benchmark scene's sparse vertices in runs of
// consecutive vertices along the Hilbert curve (as the farm's jobs and the in-process driver
// order them), with their dense neighbours' rows traced by adaptive angular sampling (§4.2) for
// a deterministic random dense set of the plan's dense budget.
//
// Prints each path's seconds per vertex, the part of it inside the sampler (the feature rays,
// the same in both paths: TransportSampler::MeasureTraceCpu), the rest, and both ratios; then
// whether the two paths agree (outcomes, weights and rows bit for bit). Usage:
//   prt-sparse-reconstruct-bench [--scene default] [--problems 2000] [--reps 3]
#include <tbb/parallel_for.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "bench/bench_scenes.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/adaptive_angular_sampling.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/neighbor_index.h"
#include "worker/sparse_precomputation.h"
#include "worker/sparse_reconstruction_reference.h"
#include "worker/transport_sampler.h"

namespace {
using namespace prt;
using Clock = std::chrono::steady_clock;

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Problem {
  uint32_t sample = 0;
  std::vector<DenseNeighbor> neighbors;
};

struct PathResult {
  std::vector<uint8_t> outcome;
  std::vector<float> rows;
  std::vector<std::vector<NeighborWeight>> weights;
  double cpu = 0, trace = 0;
  SparseStats stats;
};

using Reconstruct = SparseOutcome (*)(const TransportSampler&, const SpatialSample&, uint64_t,
                                      std::span<const DenseNeighbor>, const SparseOptions&,
                                      L1Solver&, float*, SparseStats&, float*,
                                      std::vector<NeighborWeight>*);

// fn == nullptr: the fast path in batches of kSparseRowBatch consecutive vertices, as the farm
// and the in-process driver call it.
PathResult RunPath(Reconstruct fn, TransportSampler& sampler,
                   std::span<const SpatialSample> samples, const std::vector<Problem>& problems,
                   const SparsePlan& plan, std::size_t T) {
  PathResult r;
  r.outcome.resize(problems.size());
  r.rows.assign(problems.size() * T, 0.0f);  // touched before the clock starts
  r.weights.resize(problems.size());
  L1Options o;
  o.lambda = plan.sparse.lambda;
  L1Solver solver(o);
  SparseStats st;
  sampler.MeasureTraceCpu(true);
  const double c0 = ThreadCpuSeconds();
  std::vector<SparseRowTask> batch;
  for (std::size_t first = 0; first < problems.size(); first += kSparseRowBatch) {
    const std::size_t last = std::min(problems.size(), first + kSparseRowBatch);
    if (fn != nullptr) {
      for (std::size_t i = first; i < last; ++i) {
        const Problem& p = problems[i];
        r.outcome[i] =
            static_cast<uint8_t>(fn(sampler, samples[p.sample], p.sample, p.neighbors, plan.sparse,
                                    solver, r.rows.data() + i * T, st, nullptr, &r.weights[i]));
      }
      continue;
    }
    batch.clear();
    for (std::size_t i = first; i < last; ++i) {
      const Problem& p = problems[i];
      batch.push_back({&samples[p.sample], p.sample, p.neighbors, r.rows.data() + i * T, nullptr,
                       &r.weights[i]});
    }
    ReconstructSparseRows(sampler, batch, plan.sparse, solver, st);
    for (std::size_t i = first; i < last; ++i)
      r.outcome[i] = static_cast<uint8_t>(batch[i - first].outcome);
  }
  r.cpu = ThreadCpuSeconds() - c0;
  r.trace = sampler.trace_cpu_seconds();
  r.stats = st;
  sampler.MeasureTraceCpu(false);
  return r;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();
  CLI::App app{"prt-sparse-reconstruct-bench: reference against fast sparse-row reconstruction"};
  std::string scene_name = "default";
  int n = 32, reps = 3, runs = 8;
  std::size_t problem_count = 2000;
  app.add_option("--scene", scene_name, "benchmark scene (bench/bench_scene.h)");
  app.add_option("--n", n, "cubemap resolution");
  app.add_option("--problems", problem_count, "sparse vertices reconstructed per path and rep");
  app.add_option("--runs", runs, "runs of consecutive vertices they are drawn in");
  app.add_option("--reps", reps, "alternating repetitions of both paths (median reported)");
  CLI11_PARSE(app, argc, argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);

  const SceneDescription scene = bench::BenchScene(scene_name, n);
  const SceneGeometry geometry = BuildSceneGeometry(scene);
  const EmbreeScene embree(geometry);
  TransportSamplerOptions so;
  so.rays_per_texel = scene.sampling.rays_per_texel;
  so.seed = scene.sampling.seed;
  TransportSampler sampler(embree, n, so);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
  const std::size_t N = samples.size(), T = sampler.layout().texel_count();
  const SparsePlan plan = PlanFromSettings(scene.sparse, geometry.diagonal(), n);

  // The dense set: the plan's budget, at random (the farm's is denser near occluders).
  const std::vector<uint32_t> dense = InitialDenseSet(
      N, static_cast<std::size_t>(plan.dense_budget * static_cast<double>(N)), plan.seed);
  std::vector<uint8_t> is_dense(N, 0);
  std::vector<Vec3> dense_pos;
  for (uint32_t d : dense) {
    is_dense[d] = 1;
    dense_pos.push_back(samples[d].position);
  }
  const NeighborIndex index(dense_pos, dense);
  std::vector<Vec3> pos(N);
  for (std::size_t s = 0; s < N; ++s) pos[s] = samples[s].position;
  std::vector<uint32_t> sparse;
  for (uint32_t s : HilbertOrder(pos))
    if (!is_dense[s]) sparse.push_back(s);
  // Runs of consecutive sparse vertices, evenly spaced along the curve.
  std::vector<uint32_t> chosen;
  const std::size_t per_run = std::max<std::size_t>(1, problem_count / std::max(runs, 1));
  for (int r = 0; r < runs; ++r) {
    const std::size_t first =
        sparse.size() * static_cast<std::size_t>(r) / static_cast<std::size_t>(std::max(runs, 1));
    for (std::size_t i = first; i < std::min(sparse.size(), first + per_run); ++i)
      chosen.push_back(sparse[i]);
  }
  std::vector<std::vector<uint32_t>> lists(chosen.size());
  std::vector<int32_t> slot(N, -1);
  std::vector<uint32_t> unions;
  for (std::size_t i = 0; i < chosen.size(); ++i) {
    lists[i] = index.RadiusSearch(samples[chosen[i]].position, plan.radius, plan.max_neighbors);
    for (uint32_t d : lists[i])
      if (slot[d] < 0) {
        slot[d] = static_cast<int32_t>(unions.size());
        unions.push_back(d);
      }
  }
  std::printf("%s: %zu samples, n = %d; %zu sparse vertices in %d runs, %zu dense rows\n",
              scene_name.c_str(), N, n, chosen.size(), runs, unions.size());
  std::vector<DenseRow> rows(unions.size());
  tbb::parallel_for(std::size_t{0}, unions.size(), [&](std::size_t u) {
    SampleDenseRowAdaptive(sampler, samples[unions[u]], unions[u], plan.angular, rows[u]);
  });
  std::vector<Problem> problems(chosen.size());
  std::size_t neighbour_total = 0;
  for (std::size_t i = 0; i < chosen.size(); ++i) {
    problems[i].sample = chosen[i];
    for (uint32_t d : lists[i]) {
      const DenseRow& r = rows[static_cast<std::size_t>(slot[d])];
      problems[i].neighbors.push_back(
          {r.transport.data(), r.visibility.data(), r.feature.data(), samples[d].normal});
    }
    neighbour_total += lists[i].size();
  }
  std::printf("neighbours per vertex: %.1f on average\n",
              static_cast<double>(neighbour_total) / static_cast<double>(chosen.size()));

  std::vector<double> old_cpu, old_trace, new_cpu, new_trace, ratio, rest_ratio;
  PathResult ref, fast;
  for (int rep = 0; rep < reps; ++rep) {
    ref = RunPath(&ReconstructSparseRowReference, sampler, samples, problems, plan, T);
    fast = RunPath(nullptr, sampler, samples, problems, plan, T);
    old_cpu.push_back(ref.cpu);
    old_trace.push_back(ref.trace);
    new_cpu.push_back(fast.cpu);
    new_trace.push_back(fast.trace);
    ratio.push_back(ref.cpu / fast.cpu);
    rest_ratio.push_back((ref.cpu - ref.trace) / std::max(1e-9, fast.cpu - fast.trace));
    std::printf(
        "rep %d: reference %.3f s (sampler %.3f s), fast %.3f s (sampler %.3f s): "
        "%.2fx, without the sampler %.2fx\n",
        rep + 1, ref.cpu, ref.trace, fast.cpu, fast.trace, ratio.back(), rest_ratio.back());
  }
  const double per = 1e3 / static_cast<double>(problems.size());
  std::printf(
      "\nper vertex (median of %d): reference %.3f ms (sampler %.3f, rest %.3f), fast %.3f ms "
      "(sampler %.3f, rest %.3f)\n",
      reps, Median(old_cpu) * per, Median(old_trace) * per,
      (Median(old_cpu) - Median(old_trace)) * per, Median(new_cpu) * per, Median(new_trace) * per,
      (Median(new_cpu) - Median(new_trace)) * per);
  std::printf("speed-up, one thread, same problems: %.2fx whole row, %.2fx without the sampler\n",
              Median(ratio), Median(rest_ratio));

  // Agreement: outcomes, weights and rows.
  std::size_t outcome_diff = 0, row_diff = 0, weight_diff = 0, reconstructed = 0;
  double max_row = 0, max_alpha = 0;
  for (std::size_t i = 0; i < problems.size(); ++i) {
    if (ref.outcome[i] != fast.outcome[i]) {
      ++outcome_diff;
      continue;
    }
    if (ref.outcome[i] != static_cast<uint8_t>(SparseOutcome::kReconstructed)) continue;
    ++reconstructed;
    if (std::memcmp(ref.rows.data() + i * T, fast.rows.data() + i * T, T * sizeof(float)) != 0)
      ++row_diff;
    for (std::size_t j = 0; j < T; ++j)
      max_row = std::max(max_row,
                         static_cast<double>(std::abs(ref.rows[i * T + j] - fast.rows[i * T + j])));
    const auto& a = ref.weights[i];
    const auto& b = fast.weights[i];
    if (a.size() != b.size()) {
      ++weight_diff;
      continue;
    }
    bool same = true;
    for (std::size_t w = 0; w < a.size(); ++w) {
      same = same && a[w].neighbor == b[w].neighbor;
      max_alpha = std::max(max_alpha, static_cast<double>(std::abs(a[w].alpha - b[w].alpha)));
    }
    weight_diff += !same;
  }
  std::printf(
      "solves: %llu LARS, %llu ADMM, %llu zero systems; fallbacks: %llu too few "
      "neighbours, %llu failed, %llu poor fits\n",
      static_cast<unsigned long long>(fast.stats.solved_lars),
      static_cast<unsigned long long>(fast.stats.solved_admm),
      static_cast<unsigned long long>(fast.stats.zero_systems),
      static_cast<unsigned long long>(fast.stats.fallback_too_few_neighbors),
      static_cast<unsigned long long>(fast.stats.fallback_solve_failed),
      static_cast<unsigned long long>(fast.stats.fallback_poor_fit));
  std::printf(
      "agreement: %zu of %zu outcomes differ; of %zu reconstructed rows %zu differ in any bit "
      "(max |difference| %.3g), %zu weight supports differ (max |Δα| %.3g)\n",
      outcome_diff, problems.size(), reconstructed, row_diff, max_row, weight_diff, max_alpha);
  return outcome_diff == 0 ? 0 : 1;
}
