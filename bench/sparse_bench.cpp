// prt-sparse-bench: sparse precomputation (Huang & Ramamoorthi 2010) against brute force on real
// meshes, in one run on one machine. Prints, per scene:
//   - sampling rates like the paper's Figure 9 (dense spatial %, dense angular %, sparse
//     angular %, total %) and wall time per phase like Figure 10, next to brute force;
//   - relative RMS error of relit radiance against brute force under real environment maps,
//     separately for the model and the ground;
//   - L1 against least squares, visibility against transport interpolation, error against radius
//     (Figure 6);
// and writes images: relit sparse | brute force | 10× difference, and where the dense vertices
// went with their local rank (Figure 2). Usage: prt-sparse-bench [--scenes a,b] [--n 32]
// [--out DIR] [--quick]
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "bench/bench_scenes.h"
#include "bench/sparse_variant.h"
#include "vocabulary/hash.h"
#include "vocabulary/image_io.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/embree_scene.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_sampler.h"

namespace {
using namespace prt;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}
using Variant = bench::SparseVariant;

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  CLI::App app{"prt-sparse-bench: sparse precomputation against brute force"};
  std::string scenes_arg = "default,armadillo,dragon";
  std::string out_dir = "bench-out/sparse";
  int n = 32;
  bool quick = false;
  int threads = 0;
  app.add_option("--scenes", scenes_arg,
                 "comma-separated: default, armadillo, dragon, camel, lion, horse, teapot");
  app.add_option("--n", n, "cubemap resolution");
  app.add_option("--out", out_dir, "folder for the CSV, summary and images");
  app.add_option("--threads", threads, "TBB threads (0: all cores)");
  app.add_flag("--quick", quick, "only the default variant per scene (no L1/LS or radius sweep)");
  std::string brute_cache;
  app.add_option("--brute-cache", brute_cache,
                 "folder to keep brute-force rows in between runs (exploration only: the timings "
                 "of a cached brute force are those of the run that computed it)");
  std::vector<std::string> variant_specs;
  app.add_option("--variant", variant_specs,
                 "extra variant after the default, \"key=value;...\" (budget, initial, "
                 "iterations, radius (x scene), features, min_features, window, lambda, "
                 "normal_cos, empty_weight, mode, solver, unity, max_residual); repeatable; "
                 "replaces the built-in "
                 "sweep");
  CLI11_PARSE(app, argc, argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // progress lines while redirected to a file
  std::unique_ptr<tbb::global_control> gc;
  if (threads > 0)
    gc = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               threads);
  std::filesystem::create_directories(out_dir);
  std::ofstream csv(out_dir + "/sparse.csv");
  csv << "scene,variant,radius,features,solver,mode,seconds,brute_seconds,cpu_ratio,"
         "dense_spatial,dense_angular,sparse_angular,total_sampled,fallbacks,env,err_model,err_"
         "ground\n";
  std::ostringstream md;

  for (const std::string& name : bench::Split(scenes_arg)) {
    const SceneDescription scene = bench::BenchScene(name, n);
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    const EmbreeScene embree(geometry);
    TransportSamplerOptions so;
    so.rays_per_texel = scene.sampling.rays_per_texel;
    so.seed = scene.sampling.seed;
    TransportSampler sampler(embree, n, so);
    const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
    const std::size_t T = sampler.layout().texel_count();
    const bench::SampleRanges ranges = bench::RangesOf(geometry);
    std::printf("\n== %s: %zu samples (%zu model, %zu ground), %zu triangles, n = %d ==\n",
                name.c_str(), samples.size(), ranges.model_last - ranges.model_first,
                ranges.ground_last - ranges.ground_first, embree.triangle_count(), n);

    std::vector<float> brute(samples.size() * T);
    double brute_s = 0, brute_cpu = 0;
    SampleStats bst;
    const std::string cache_file = brute_cache.empty()
                                       ? std::string()
                                       : brute_cache + "/" + name + "_n" + std::to_string(n) +
                                             "_r" + std::to_string(so.rays_per_texel) + "_s" +
                                             std::to_string(so.seed) + ".bin";
    bool cached = false;
    if (!cache_file.empty()) {
      std::ifstream in(cache_file, std::ios::binary);
      in.read(reinterpret_cast<char*>(&brute_s), sizeof brute_s);
      in.read(reinterpret_cast<char*>(&brute_cpu), sizeof brute_cpu);
      in.read(reinterpret_cast<char*>(&bst), sizeof bst);
      in.read(reinterpret_cast<char*>(brute.data()),
              static_cast<std::streamsize>(brute.size() * sizeof(float)));
      cached = static_cast<bool>(in);
    }
    if (!cached) {
      auto t0 = Clock::now();
      double c0 = bench::CpuSeconds();
      bst = sampler.ComputeRows(samples, 0, brute.data());
      brute_s = Seconds(t0);
      brute_cpu = bench::CpuSeconds() - c0;
      if (!cache_file.empty()) {
        std::filesystem::create_directories(brute_cache);
        std::ofstream out(cache_file, std::ios::binary);
        out.write(reinterpret_cast<const char*>(&brute_s), sizeof brute_s);
        out.write(reinterpret_cast<const char*>(&brute_cpu), sizeof brute_cpu);
        out.write(reinterpret_cast<const char*>(&bst), sizeof bst);
        out.write(reinterpret_cast<const char*>(brute.data()),
                  static_cast<std::streamsize>(brute.size() * sizeof(float)));
      }
    }
    std::printf(
        "brute force%s: %.2f s wall, %.2f s CPU, %llu texels, %.3g rays (%.2f Mrays/s wall)\n",
        cached ? " (cached)" : "", brute_s, brute_cpu,
        static_cast<unsigned long long>(bst.texels_traced), static_cast<double>(bst.rays_traced),
        static_cast<double>(bst.rays_traced) / brute_s * 1e-6);
    const auto envs = bench::BenchEnvironments(n);
    std::vector<std::vector<float>> ref;
    for (const auto& e : envs) ref.push_back(bench::RelitRadiance(geometry, brute, e.cube));

    const SparsePlan base = PlanFromSettings(scene.sparse, geometry.diagonal(), n);
    std::printf(
        "plan: dense budget %.3f, initial %.3f, radius %.4f, features %d (min extra %d), "
        "window %d, lambda %g\n",
        base.dense_budget, base.initial_fraction, base.radius, base.sparse.features,
        std::min(base.sparse.min_features, base.sparse.features), base.angular.window,
        base.sparse.lambda);
    std::vector<Variant> variants{{"default (L1, visibility)", base, 0, -1, 0}};
    for (const std::string& spec : variant_specs)
      variants.push_back(bench::ParseSparseVariant(spec, base));
    if (!quick && variant_specs.empty()) {
      Variant ls{"least squares", base, 0, -1, 0};
      ls.plan.sparse.solver = SolverKind::kLeastSquares;
      Variant tm{"L1, transport interp.", base, 0, -1, 0};
      tm.plan.sparse.mode = InterpolationMode::kTransport;
      variants.push_back(ls);
      variants.push_back(tm);
      for (double f : {0.5, 2.0}) {
        for (SolverKind sk : {SolverKind::kL1, SolverKind::kLeastSquares}) {
          Variant v{std::string(sk == SolverKind::kL1 ? "L1" : "LS") + " radius ×" +
                        std::to_string(f).substr(0, 3),
                    base, 0, -1, 0};
          v.plan.radius = base.radius * f;
          v.plan.sparse.solver = sk;
          variants.push_back(v);
        }
      }
      // Dense budget and feature count: the operating points a user picks from.
      for (double budget : {0.10, 0.15}) {
        for (double ffrac : {1.0, 0.7}) {
          Variant v{"dense " + std::to_string(static_cast<int>(budget * 100)) + "%, features ×" +
                        std::to_string(ffrac).substr(0, 3),
                    base, 0, -1, 0};
          v.plan.dense_budget = budget;
          v.plan.sparse.features = static_cast<int>(base.sparse.features * ffrac);
          variants.push_back(v);
        }
      }
    }

    md << "\n### " << name << " (" << samples.size() << " samples, n = " << n << ")\n\n"
       << "Brute force: " << brute_s << " s wall, " << brute_cpu << " s CPU.\n\n"
       << "| variant | radius | wall s | CPU ×brute | dense spatial | dense angular | sparse "
          "angular | "
          "total | fallbacks |";
    for (const auto& e : envs) md << " " << e.name << " model | " << e.name << " ground |";
    md << "\n|---|---|---|---|---|---|---|---|---|";
    for (std::size_t i = 0; i < envs.size(); ++i) md << "---|---|";
    md << "\n";

    for (std::size_t vi = 0; vi < variants.size(); ++vi) {
      const Variant& v = variants[vi];
      SparseReport rep;
      // Allocated and touched before the clock starts, as brute force's output is.
      std::vector<float> rows(brute.size(), 0.0f);
      sampler.MeasureTraceCpu(true);
      const auto t0 = Clock::now();
      const double c0 = bench::CpuSeconds();
      RunSparsePrecomputation(sampler, samples, v.plan, rep, rows.data());
      const double sec = Seconds(t0);
      const double cpu = bench::CpuSeconds() - c0;
      const double trace_cpu = sampler.trace_cpu_seconds();
      sampler.MeasureTraceCpu(false);
      const double dense_n =
          static_cast<double>(rep.dense_initial + rep.dense_by_rank + rep.dense_fallback);
      const double dense_spatial = dense_n / static_cast<double>(samples.size());
      auto dense_in = [&](std::size_t first, std::size_t last) {
        std::size_t c = 0;
        for (std::size_t i = first; i < last; ++i) c += rep.is_dense[i];
        return last > first ? 100.0 * static_cast<double>(c) / static_cast<double>(last - first)
                            : 0.0;
      };
      const double dense_ang =
          static_cast<double>(rep.dense_angular.trace.texels_traced) /
          static_cast<double>(std::max<uint64_t>(1, rep.dense_angular.texels_above_horizon));
      const double sparse_ang =
          static_cast<double>(rep.sparse_stats.trace.texels_traced) /
          static_cast<double>(std::max<uint64_t>(1, rep.sparse_stats.texels_above_horizon));
      std::printf(
          "%-26s r=%.4f %.2f s wall, CPU %.3f× brute (wall %.3f×; dense %.2f rank %.2f sparse %.2f "
          "s)"
          "  dense %.1f%%  "
          "dense-ang %.1f%%  sparse-ang %.1f%%  total %.1f%%  fallbacks %llu (model dense "
          "%.1f%%, ground dense %.1f%%)\n",
          v.name.c_str(), v.plan.radius, sec, cpu / brute_cpu, sec / brute_s, rep.seconds_dense,
          rep.seconds_rank, rep.seconds_sparse, 100 * dense_spatial, 100 * dense_ang,
          100 * sparse_ang, 100 * rep.SampledFraction(),
          static_cast<unsigned long long>(rep.dense_fallback),
          dense_in(ranges.model_first, ranges.model_last),
          dense_in(ranges.ground_first, ranges.ground_last));
      // The floor any implementation of this sampling pays: the CPU time inside the sampler
      // (rays and the estimator around them) against brute force's whole CPU time, and what a
      // traced texel cost against brute force's average texel.
      const uint64_t traced =
          rep.dense_angular.trace.texels_traced + rep.sparse_stats.trace.texels_traced;
      std::printf(
          "    tracing CPU %.2f s = %.3f× brute (a traced texel %.2f× brute force's average), "
          "the rest %.3f×\n",
          trace_cpu, trace_cpu / brute_cpu,
          (trace_cpu / static_cast<double>(std::max<uint64_t>(1, traced))) /
              (brute_cpu / static_cast<double>(std::max<uint64_t>(1, bst.texels_traced))),
          (cpu - trace_cpu) / brute_cpu);
      // A fingerprint of the rows (the transport file's block checksum): optimisations that
      // must not change them compare it.
      std::printf("    rows fingerprint %016llx\n", static_cast<unsigned long long>(Checksum64(
                                                        rows.data(), rows.size() * sizeof(float))));
      md << "| " << v.name << " | " << v.plan.radius << " | " << sec << " | " << cpu / brute_cpu
         << " | " << 100 * dense_spatial << "% | " << 100 * dense_ang << "% | " << 100 * sparse_ang
         << "% | " << 100 * rep.SampledFraction() << "% | " << rep.dense_fallback << " |";
      for (std::size_t e = 0; e < envs.size(); ++e) {
        const std::vector<float> b = bench::RelitRadiance(geometry, rows, envs[e].cube);
        const double em = bench::RelativeRmsError(b, ref[e], ranges.model_first, ranges.model_last);
        const double eg =
            bench::RelativeRmsError(b, ref[e], ranges.ground_first, ranges.ground_last);
        std::printf("    %-9s model %.4f  ground %.4f", envs[e].name.c_str(), em, eg);
        if (e == 0) {
          // Where the error comes from: the same measure with only the dense rows' error (the
          // sparse vertices given brute force's radiance) and with only the reconstructed rows'.
          // Radiance is per vertex, so mixing the relit results mixes the rows.
          std::vector<float> only_dense = ref[e], only_sparse = ref[e];
          for (std::size_t s = 0; s < samples.size(); ++s)
            for (int c = 0; c < 3; ++c)
              (rep.is_dense[s] ? only_dense : only_sparse)[s * 3 + c] = b[s * 3 + c];
          std::printf(
              "  (dense rows alone: model %.4f ground %.4f; reconstructed alone: model %.4f "
              "ground %.4f)",
              bench::RelativeRmsError(only_dense, ref[e], ranges.model_first, ranges.model_last),
              bench::RelativeRmsError(only_dense, ref[e], ranges.ground_first, ranges.ground_last),
              bench::RelativeRmsError(only_sparse, ref[e], ranges.model_first, ranges.model_last),
              bench::RelativeRmsError(only_sparse, ref[e], ranges.ground_first,
                                      ranges.ground_last));
        }
        std::printf("\n");
        md << " " << 100 * em << "% | " << 100 * eg << "% |";
        csv << name << ",\"" << v.name << "\"," << v.plan.radius << "," << v.plan.sparse.features
            << "," << (v.plan.sparse.solver == SolverKind::kL1 ? "L1" : "LS") << ","
            << (v.plan.sparse.mode == InterpolationMode::kVisibility ? "visibility" : "transport")
            << "," << sec << "," << brute_s << "," << cpu / brute_cpu << "," << dense_spatial << ","
            << dense_ang << "," << sparse_ang << "," << rep.SampledFraction() << ","
            << rep.dense_fallback << "," << envs[e].name << "," << em << "," << eg << "\n";
        if (vi == 0 && e == 0) {
          // Relit sparse | brute force | 10× difference, under the first environment. An image
          // that fails is reported; the figures above it stand.
          try {
            const ImageRgb a = bench::RenderVertexColours(scene, geometry, b, &envs[e].cube);
            const ImageRgb r = bench::RenderVertexColours(scene, geometry, ref[e], &envs[e].cube);
            WritePng(SideBySide(a, r, true, 10.0),
                     out_dir + "/" + name + "_sparse_brute_diff10.png");
          } catch (const std::exception& ex) {
            std::printf("    image not written: %s\n", ex.what());
          }
        }
      }
      md << "\n";
      if (vi == 0) {
        // Figure 2: where the dense vertices went, coloured by the local rank estimated there
        // (initial random dense vertices, with no rank estimate, in white; sparse in grey).
        const std::vector<float> colours = bench::DenseVertexColours(rep.is_dense, rep.local_rank);
        try {
          WritePng(bench::RenderVertexColours(scene, geometry, colours, nullptr),
                   out_dir + "/" + name + "_dense_vertices_rank.png");
        } catch (const std::exception& ex) {
          std::printf("    image not written: %s\n", ex.what());
        }
      }
    }
  }
  std::ofstream(out_dir + "/sparse.md") << "# Sparse precomputation against brute force\n"
                                        << md.str();
  std::printf("\nwrote %s/sparse.csv, %s/sparse.md and images\n", out_dir.c_str(), out_dir.c_str());
  return 0;
}
