// prt-sparse-gi-bench (scripts/bench.sh sparse-gi; docs/sparse-precomputation.md, "With
// interreflection"): sparse precomputation of the full transport T = T⁰ + Σ_k Tᵏ against brute
// force of the same estimator, in one process and one run, per scene and estimator:
//
//   brute    T⁰ for every vertex (TransportSampler), then the indirect part for every vertex:
//            gather: K bounces on the indirect grid (worker/bounce_gather.h), bounce by bounce;
//            path:   Σ_k Tᵏ per element by path tracing at the full n (worker/
//                    path_trace_reference.h), the paper's brute force.
//   sparse   T⁰ by the sparse method (worker/sparse_precomputation.h), then each indirect
//            component on the indirect grid from the same dense vertices (worker/
//            sparse_indirect.h): dense vertices whole rows, sparse vertices their features + L1.
//
// Prints per variant: the sampling rates (Figure 9: dense spatial, dense angular, sparse
// angular, the indirect components' rates, and the total of all elements against brute force's),
// the wall time per phase (Figure 10) and the wall and CPU ratios to brute force, the same for
// the direct part alone (T⁰, what the issue-4 measurements were), the relative RMS error of relit
// B against brute force's T, model and ground separately, under real environments, and both
// against the per-element path-traced reference on a few vertices (--ref-vertices). Writes
// results.csv (one line per method and light: the Pareto front of time against error), per scene
// <scene>-<estimator>_sparse_brute_diff10.png (sparse | brute | 10× difference), <scene>_dense.png
// (where the dense vertices went, coloured by local rank) and, with gnuplot, pareto.png.
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_scenes.h"
#include "bench/sparse_variant.h"
#include "vocabulary/hash.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/bounce_gather.h"
#include "worker/path_trace_reference.h"
#include "worker/sparse_indirect.h"
#include "worker/sparse_precomputation.h"

namespace {

using namespace prt;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
// A full transport as this benchmark holds it: T⁰ rows (V × 6n²) and indirect components, each
// C × V rows of `cols` texels (channel-major), relit with the light averaged to their grid.
struct Transport {
  const std::vector<float>* direct = nullptr;  // not owned (n = 64: 4 GB for the default scene)
  std::vector<std::vector<float>> indirect;
  std::size_t indirect_cols = 0;
};

// B = ρ ⊙ (T⁰·L + Σ I·L̄) per vertex (3 floats per vertex).
std::vector<float> Relit(const SceneGeometry& geometry, const Transport& t, int C, std::size_t cols,
                         const CubemapRgb& light,
                         const std::array<std::vector<float>, 3>& coarse_light) {
  const uint64_t V = t.direct->size() / cols;
  std::vector<float> b(V * 3);
  tbb::parallel_for(uint64_t{0}, V, [&](uint64_t v) {
    const Rgb& rho = geometry.meshes[geometry.MeshOfVertex(v)].albedo;
    for (int c = 0; c < 3; ++c) {
      double x = bench::DotRow(t.direct->data() + v * cols, light.Channel(c).data(), cols);
      const int tc = C == 1 ? 0 : c;
      for (const std::vector<float>& ind : t.indirect)
        x += bench::DotRow(ind.data() + (tc * V + v) * t.indirect_cols, coarse_light[c].data(),
                           t.indirect_cols);
      b[v * 3 + c] = static_cast<float>(rho[c] * x);
    }
  });
  return b;
}

struct Light {
  std::string name;
  CubemapRgb cube;
  std::array<std::vector<float>, 3> coarse;  // averaged to the indirect grid
};

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  std::string scenes_arg = "default,dragon,armadillo", estimators_arg = "gather",
              out_dir = "bench-out/sparse-gi", envs_arg = "sunrise,city,studio,interior";
  int n = 32, bounces = 2, gather_paths = 1024, path_paths = 16, indirect_n = 0, threads = 0;
  int ref_paths = 256;
  std::size_t ref_vertices = 24;
  std::vector<std::string> variant_specs;
  CLI::App app{"prt-sparse-gi-bench: sparse precomputation with interreflection vs brute force"};
  app.add_option("--scenes", scenes_arg, "comma-separated benchmark scenes")->capture_default_str();
  app.add_option("--estimators", estimators_arg, "gather, path or gather,path")
      ->capture_default_str();
  app.add_option("--n", n, "cubemap n")->capture_default_str();
  app.add_option("--bounces", bounces, "K")->check(CLI::Range(1, 8))->capture_default_str();
  app.add_option("--gather-paths", gather_paths, "gather: directions per vertex and bounce")
      ->capture_default_str();
  app.add_option("--path-paths", path_paths, "path estimator: paths per vertex")
      ->capture_default_str();
  app.add_option("--indirect-n", indirect_n, "the indirect grid's n (0: n/4)");
  app.add_option("--envs", envs_arg, "environments")->capture_default_str();
  app.add_option("--ref-vertices", ref_vertices,
                 "path-traced reference vertices per group (model, ground); 0: none")
      ->capture_default_str();
  app.add_option("--ref-paths", ref_paths, "reference paths per vertex")->capture_default_str();
  app.add_option("--variant", variant_specs,
                 "sparse plan \"key=value;...\" (bench/sparse_variant.h; rank_floor, "
                 "ind_features, budget, …); repeatable; the default plan runs first");
  app.add_option("--threads", threads, "TBB threads (0: all)");
  app.add_option("--out", out_dir, "output folder")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  threads);
  try {
    std::filesystem::create_directories(out_dir);
    std::ofstream csv(out_dir + "/results.csv");
    csv << "scene,n,estimator,method,variant,seconds,cpu_seconds,ratio_wall,ratio_cpu,"
           "direct_ratio_wall,samples,dense_spatial,light,err_model,err_ground,ref_model,"
           "ref_ground\n";
    std::ofstream pareto(out_dir + "/pareto.dat");
    for (const std::string& name : bench::Split(scenes_arg)) {
      const SceneDescription scene = bench::BenchScene(name, n);
      const SceneGeometry geometry = BuildSceneGeometry(scene);
      const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
      const uint64_t V = samples.size();
      const int m = indirect_n > 0 ? indirect_n : std::max(1, n / 4);
      const int C = HasColouredAlbedo(geometry) ? 3 : 1;
      const EmbreeScene embree(geometry);
      const SceneSurfaces surfaces(geometry);
      const CubemapLayout fine(n), coarse(m);
      const std::size_t cols = fine.texel_count(), mcols = coarse.texel_count();
      const bench::SampleRanges ranges = bench::RangesOf(geometry);
      TransportSamplerOptions so;
      so.rays_per_texel = scene.sampling.rays_per_texel;
      so.seed = scene.sampling.seed;
      const TransportSampler sampler(embree, n, so);
      std::printf(
          "\n== %s: %llu vertices (%zu model, %zu ground), n = %d, indirect n = %d, K = %d, %d "
          "channel(s) ==\n",
          name.c_str(), static_cast<unsigned long long>(V), ranges.model_last - ranges.model_first,
          ranges.ground_last - ranges.ground_first, n, m, bounces, C);

      std::vector<Light> lights;
      for (auto& e : bench::BenchEnvironments(n, bench::Split(envs_arg))) {
        Light l{e.name, std::move(e.cube), {}};
        lights.push_back(std::move(l));
      }
      auto coarse_for = [&](const CubemapLayout& grid) {
        for (Light& l : lights)
          for (int c = 0; c < 3; ++c) l.coarse[c] = CoarsenLight(fine, grid, l.cube.Channel(c));
      };

      // Brute force's T⁰, shared by both estimators (timed once).
      std::vector<float> brute_direct(V * cols, 0.0f);
      Transport brute_direct_only;
      brute_direct_only.direct = &brute_direct;
      auto t0 = Clock::now();
      double c0 = bench::CpuSeconds();
      const SampleStats bst = sampler.ComputeRows(samples, 0, brute_direct.data());
      const double brute_direct_s = Seconds(t0), brute_direct_cpu = bench::CpuSeconds() - c0;
      std::printf("brute T0: %.2f s wall, %.2f s CPU, %llu texels\n", brute_direct_s,
                  brute_direct_cpu, static_cast<unsigned long long>(bst.texels_traced));

      // The reference vertices (per-element path tracing, many paths): the common truth.
      std::vector<uint64_t> picked;
      std::vector<RelitEstimate> ref_relit;
      std::vector<CubemapRgb> light_cubes;
      for (const Light& l : lights) light_cubes.push_back(l.cube);
      const std::size_t ref_model =
          bench::PickVertices(ranges.model_first, ranges.model_last, ref_vertices, 11).size();
      if (ref_vertices > 0) {
        picked = bench::PickVertices(ranges.model_first, ranges.model_last, ref_vertices, 11);
        const auto g =
            bench::PickVertices(ranges.ground_first, ranges.ground_last, ref_vertices, 12);
        picked.insert(picked.end(), g.begin(), g.end());
        PathTraceOptions po;
        po.bounces = bounces;
        po.paths = ref_paths;
        po.rays_per_texel = so.rays_per_texel;
        po.path_rays_per_texel = 1;
        po.seed = 7;
        const PathTraceReference reference(embree, surfaces, n, po);
        ref_relit.resize(picked.size() * lights.size() * 3);
        const auto tr = Clock::now();
        tbb::parallel_for(std::size_t{0}, picked.size(), [&](std::size_t i) {
          std::vector<float> row(static_cast<std::size_t>(C) * cols);
          PathTraceExtras ex;
          ex.lights = light_cubes;
          ex.relit = ref_relit.data() + i * lights.size() * 3;
          reference.ComputeRow(samples[picked[i]], picked[i], C, row.data(), ex);
        });
        std::printf("reference: %zu vertices, %d paths each, %.1f s\n", picked.size(), ref_paths,
                    Seconds(tr));
      }
      // Relative RMS error of B against the reference on the picked vertices of a group.
      auto ref_error = [&](const std::vector<float>& b, std::size_t l, bool model) {
        double e2 = 0, r2 = 0;
        const std::size_t first = model ? 0 : ref_model, last = model ? ref_model : picked.size();
        for (std::size_t i = first; i < last; ++i) {
          const Rgb& rho = geometry.meshes[geometry.MeshOfVertex(picked[i])].albedo;
          for (int c = 0; c < 3; ++c) {
            const double r = rho[c] * ref_relit[(i * lights.size() + l) * 3 + c].total();
            const double d = b[picked[i] * 3 + c] - r;
            e2 += d * d;
            r2 += r * r;
          }
        }
        return r2 > 0 ? std::sqrt(e2 / r2) : 0.0;
      };

      const SparsePlan base = PlanFromSettings(scene.sparse, geometry.diagonal(), n);
      std::vector<bench::SparseVariant> variants{{"default", base, 0, -1, 0}};
      for (const std::string& spec : variant_specs)
        variants.push_back(bench::ParseSparseVariant(spec, base));

      for (const std::string& estimator : bench::Split(estimators_arg)) {
        if (estimator != "gather" && estimator != "path")
          throw std::invalid_argument("--estimators: gather or path, not " + estimator);
        const bool path = estimator == "path";
        // ---- brute force of this estimator
        Transport brute;
        brute.direct = &brute_direct;
        std::vector<double> brute_phase_s;
        double brute_ind_cpu = 0;
        BounceGatherOptions go;
        go.paths = gather_paths;
        go.seed = scene.sampling.seed;
        go.indirect_n = m;
        go.near_field = scene.sampling.near_field;
        const BounceGatherer gatherer(embree, surfaces, go);
        PathTraceOptions po;
        po.bounces = bounces;
        po.paths = path_paths;
        po.rays_per_texel = so.rays_per_texel;
        po.path_rays_per_texel = 1;
        po.seed = scene.sampling.seed;
        uint64_t brute_ind_elements = 0;
        c0 = bench::CpuSeconds();
        if (!path) {
          brute.indirect = GatherBounces(gatherer, samples, fine, coarse, brute_direct, bounces, C,
                                         nullptr, &brute_phase_s);
          brute.indirect_cols = mcols;
          brute_ind_elements = V * mcols * bounces;
        } else {
          const PathTraceReference full(embree, surfaces, n, po);
          brute.indirect.assign(1, std::vector<float>(static_cast<std::size_t>(C) * V * cols));
          brute.indirect_cols = cols;
          const auto tp = Clock::now();
          tbb::parallel_for(uint64_t{0}, V, [&](uint64_t v) {
            thread_local std::vector<float> row;
            row.resize(static_cast<std::size_t>(C) * cols);
            full.ComputeIndirect(samples[v], v, C, {}, row.data());
            for (int c = 0; c < C; ++c)
              std::copy_n(row.data() + c * cols, cols,
                          brute.indirect[0].data() + (c * V + v) * cols);
          });
          brute_phase_s.push_back(Seconds(tp));
          brute_ind_elements = V * cols;
        }
        brute_ind_cpu = bench::CpuSeconds() - c0;
        double brute_ind_s = 0;
        for (double s : brute_phase_s) brute_ind_s += s;
        const double brute_s = brute_direct_s + brute_ind_s;
        const double brute_cpu = brute_direct_cpu + brute_ind_cpu;
        std::printf("brute %s: T0 %.2f s + indirect", estimator.c_str(), brute_direct_s);
        for (double s : brute_phase_s) std::printf(" %.2f s", s);
        std::printf(" = %.2f s wall (%.2f s CPU)\n", brute_s, brute_cpu);
        coarse_for(path ? fine : coarse);
        std::vector<std::vector<float>> ref_b;
        for (const Light& l : lights)
          ref_b.push_back(Relit(geometry, brute, C, cols, l.cube, l.coarse));
        const double brute_elements = double(bst.texels_traced) + double(brute_ind_elements);
        for (std::size_t l = 0; l < lights.size(); ++l) {
          const double rm = picked.empty() ? 0 : ref_error(ref_b[l], l, true);
          const double rg = picked.empty() ? 0 : ref_error(ref_b[l], l, false);
          csv << name << "," << n << "," << estimator << ",brute,," << brute_s << "," << brute_cpu
              << ",1,1,1,1,1," << lights[l].name << ",0,0," << rm << "," << rg << "\n";
          if (!picked.empty())
            std::printf("    brute %-9s vs reference: model %.4f ground %.4f\n",
                        lights[l].name.c_str(), rm, rg);
        }
        pareto << name << "-" << estimator << "-brute " << brute_s << " "
               << (picked.empty() ? 0 : ref_error(ref_b[0], 0, true)) << "\n";

        // ---- the sparse method, per variant
        for (std::size_t vi = 0; vi < variants.size(); ++vi) {
          const bench::SparseVariant& var = variants[vi];
          SparseIndirectOptions io = IndirectOptionsOf(var.plan, n, m);
          if (var.indirect_features > 0) io.features = var.indirect_features;
          // Gathering: the T⁰ combination by default (its cost is rays, not texels); path
          // tracing: the features (its cost is texels).
          io.direct_weights = var.direct_weights >= 0 ? var.direct_weights == 1 : !path;
          std::vector<float> sparse_direct(V * cols, 0.0f);
          Transport sparse;
          sparse.direct = &sparse_direct;
          sparse.indirect_cols = mcols;
          std::vector<SparseIndirectStats> ist;
          SparseReport rep;
          const auto ts = Clock::now();
          const double cs = bench::CpuSeconds();
          RunSparsePrecomputation(sampler, samples, var.plan, rep, sparse_direct.data());
          const double direct_s = Seconds(ts);
          if (!path) {
            std::vector<float> previous(V * mcols);
            tbb::parallel_for(uint64_t{0}, V, [&](uint64_t v) {
              CoarsenRow(fine, coarse, sparse_direct.data() + v * cols,
                         previous.data() + v * mcols);
            });
            int prev_channels = 1;
            for (int k = 1; k <= bounces; ++k) {
              std::vector<float> rows(static_cast<std::size_t>(C) * V * mcols);
              const GatheredBounce component(gatherer, k, C, previous.data(), V, prev_channels,
                                             mcols);
              // feature_paths: the sparse vertices gather their features with fewer directions.
              std::unique_ptr<BounceGatherer> few;
              std::unique_ptr<GatheredBounce> few_component;
              if (var.feature_paths > 0) {
                BounceGatherOptions fo = go;
                fo.paths = var.feature_paths;
                few = std::make_unique<BounceGatherer>(embree, surfaces, fo);
                few_component = std::make_unique<GatheredBounce>(*few, k, C, previous.data(), V,
                                                                 prev_channels, mcols);
              }
              SparseIndirectStats st;
              RunSparseIndirect(component, samples, rep.is_dense, var.plan.radius,
                                var.plan.max_neighbors, io, rows.data(), st, rep.combination,
                                few_component.get());
              ist.push_back(st);
              previous = rows;
              prev_channels = C;
              sparse.indirect.push_back(std::move(rows));
            }
          } else {
            PathTraceOptions pc = po;
            const PathTraceReference on_grid(embree, surfaces, m, pc);
            const PathTracedIndirect component(on_grid, C);
            std::vector<float> rows(static_cast<std::size_t>(C) * V * mcols);
            SparseIndirectStats st;
            RunSparseIndirect(component, samples, rep.is_dense, var.plan.radius,
                              var.plan.max_neighbors, io, rows.data(), st, rep.combination);
            ist.push_back(st);
            sparse.indirect.push_back(std::move(rows));
          }
          const double sec = Seconds(ts), cpu = bench::CpuSeconds() - cs;
          // Rates (Figure 9) and phases (Figure 10).
          const double dense_spatial =
              double(rep.dense_initial + rep.dense_by_rank + rep.dense_fallback) / double(V);
          auto dense_in = [&](std::size_t first, std::size_t last) {
            std::size_t c = 0;
            for (std::size_t i = first; i < last; ++i) c += rep.is_dense[i];
            return last > first ? double(c) / double(last - first) : 0.0;
          };
          const double dense_ang =
              double(rep.dense_angular.trace.texels_traced) /
              double(std::max<uint64_t>(1, rep.dense_angular.texels_above_horizon));
          const double sparse_ang =
              double(rep.sparse_stats.trace.texels_traced) /
              double(std::max<uint64_t>(1, rep.sparse_stats.texels_above_horizon));
          double sampled =
              double(rep.dense_angular.trace.texels_traced + rep.sparse_stats.trace.texels_traced);
          for (const SparseIndirectStats& st : ist) sampled += double(st.texels_evaluated);
          const double samples_rate = sampled / brute_elements;
          std::printf(
              "%s sparse [%s]: %.2f s wall = %.3f× brute (CPU %.3f×); T0 alone %.2f s = %.3f× "
              "brute T0 (dense %.2f rank %.2f sparse %.2f s)\n",
              estimator.c_str(), var.name.c_str(), sec, sec / brute_s, cpu / brute_cpu, direct_s,
              direct_s / brute_direct_s, rep.seconds_dense, rep.seconds_rank, rep.seconds_sparse);
          std::printf(
              "    dense vertices %llu = %.1f%% (model %.1f%%, ground %.1f%%; %llu initial, %llu "
              "by "
              "rank, %llu fallbacks); T0: dense angular %.1f%%, sparse angular %.1f%%, T0 "
              "sampled %.1f%%\n",
              static_cast<unsigned long long>(rep.dense_initial + rep.dense_by_rank +
                                              rep.dense_fallback),
              100 * dense_spatial, 100 * dense_in(ranges.model_first, ranges.model_last),
              100 * dense_in(ranges.ground_first, ranges.ground_last),
              static_cast<unsigned long long>(rep.dense_initial),
              static_cast<unsigned long long>(rep.dense_by_rank),
              static_cast<unsigned long long>(rep.dense_fallback), 100 * dense_ang,
              100 * sparse_ang, 100 * rep.SampledFraction());
          for (std::size_t k = 0; k < ist.size(); ++k) {
            const SparseIndirectStats& st = ist[k];
            const double brute_k = brute_phase_s[std::min(k, brute_phase_s.size() - 1)];
            std::printf(
                "    %s: dense %.2f s + sparse %.2f s (brute %.2f s: %.3f×); %.1f%% of its "
                "elements (%s), %llu reconstructed, fallbacks %llu/%llu/%llu "
                "(neighbours/solve/fit)\n",
                path ? "paths" : ("bounce " + std::to_string(k + 1)).c_str(), st.seconds_dense,
                st.seconds_sparse, brute_k, (st.seconds_dense + st.seconds_sparse) / brute_k,
                100 * st.SampledFraction(),
                io.direct_weights ? "T0's combination"
                                  : (std::to_string(io.features) + " features").c_str(),
                static_cast<unsigned long long>(st.reconstructed),
                static_cast<unsigned long long>(st.fallback_too_few_neighbors),
                static_cast<unsigned long long>(st.fallback_solve_failed),
                static_cast<unsigned long long>(st.fallback_poor_fit));
          }
          std::printf("    samples: %.1f%% of brute force's elements\n", 100 * samples_rate);
          coarse_for(coarse);
          Transport sparse_direct_only;
          sparse_direct_only.direct = &sparse_direct;
          for (std::size_t l = 0; l < lights.size(); ++l) {
            const std::vector<float> b =
                Relit(geometry, sparse, C, cols, lights[l].cube, lights[l].coarse);
            const double em =
                bench::RelativeRmsError(b, ref_b[l], ranges.model_first, ranges.model_last);
            const double eg =
                bench::RelativeRmsError(b, ref_b[l], ranges.ground_first, ranges.ground_last);
            const double rm = picked.empty() ? 0 : ref_error(b, l, true);
            const double rg = picked.empty() ? 0 : ref_error(b, l, false);
            // The direct part alone against brute force's T⁰ (the direct-only case).
            const std::vector<float> bd =
                Relit(geometry, sparse_direct_only, C, cols, lights[l].cube, lights[l].coarse);
            const std::vector<float> rd =
                Relit(geometry, brute_direct_only, C, cols, lights[l].cube, lights[l].coarse);
            std::printf(
                "    %-9s vs brute: model %.4f ground %.4f | vs reference: model %.4f ground "
                "%.4f | T0 alone vs brute T0: model %.4f ground %.4f\n",
                lights[l].name.c_str(), em, eg, rm, rg,
                bench::RelativeRmsError(bd, rd, ranges.model_first, ranges.model_last),
                bench::RelativeRmsError(bd, rd, ranges.ground_first, ranges.ground_last));
            csv << name << "," << n << "," << estimator << ",sparse,\"" << var.name << "\"," << sec
                << "," << cpu << "," << sec / brute_s << "," << cpu / brute_cpu << ","
                << direct_s / brute_direct_s << "," << samples_rate << "," << dense_spatial << ","
                << lights[l].name << "," << em << "," << eg << "," << rm << "," << rg << "\n";
            if (l == 0) {
              pareto << name << "-" << estimator << "-sparse[" << var.name << "] " << sec << " "
                     << rm << "\n";
              if (vi == 0) {
                try {
                  const ImageRgb a =
                      bench::RenderVertexColours(scene, geometry, b, &lights[l].cube);
                  const ImageRgb r =
                      bench::RenderVertexColours(scene, geometry, ref_b[l], &lights[l].cube);
                  WritePng(SideBySide(a, r, true, 10.0),
                           out_dir + "/" + name + "-" + estimator + "_sparse_brute_diff10.png");
                } catch (const std::exception& ex) {
                  std::printf("    image not written: %s\n", ex.what());
                }
              }
            }
          }
          if (vi == 0 && estimator == bench::Split(estimators_arg)[0]) {
            try {
              WritePng(bench::RenderVertexColours(
                           scene, geometry, bench::DenseVertexColours(rep.is_dense, rep.local_rank),
                           nullptr),
                       out_dir + "/" + name + "_dense.png");
            } catch (const std::exception& ex) {
              std::printf("    image not written: %s\n", ex.what());
            }
          }
        }
      }
    }
    pareto.close();
    const std::string cmd =
        "gnuplot -e \"set terminal pngcairo size 800,500; set output '" + out_dir +
        "/pareto.png'; set logscale xy; set xlabel 'precomputation wall s (2 cores)'; set ylabel "
        "'relative RMS error of the model vs the path-traced reference, first light'; set key "
        "off; plot '" +
        out_dir + "/pareto.dat' using 2:3:1 with labels point pt 7 offset 1,0.5 font ',7'\" " +
        "2>/dev/null";
    if (std::system(cmd.c_str()) != 0) std::printf("(gnuplot not available: no pareto.png)\n");
    std::printf("\nwrote %s/results.csv, pareto.dat/.png and images\n", out_dir.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-sparse-gi-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
