// prt-gi-bench (scripts/bench.sh gi; docs/interreflection.md, "Measured"): interreflection by
// bounce gathering against the per-element path-traced reference, on one scene, in one process.
//
// 1. T⁰ for every vertex (TransportSampler, the farm's direct rows, 4 rays per texel).
// 2. K bounces gathered (worker/bounce_gather.h) on the indirect grid; wall time per bounce.
// 3. The reference (worker/path_trace_reference.h) on S random vertices of the model and S of
//    the ground, with the same seed, so that its direct term is the gather's bit for bit: the
//    difference is the indirect estimator's alone. Each reference vertex gives, per light and
//    colour, each bounce's relit share and its standard error.
// 4. For K = 1 … Kmax, per light (uniform sky and the real environments) and per group (model,
//    ground): the relative RMS error of relit B = ρ ⊙ (T·L) of the gather against the
//    reference, the reference's own noise (RMS of its standard errors over RMS B), and how far
//    the direct-only T is from the reference (the size of what interreflection adds).
// 5. --images DIR: the scene from its camera under the first environment — direct only, with
//    K bounces, and the indirect part alone ×4 — and the per-bounce energy (Σ T per channel over
//    the scene) as a table and, with gnuplot, a plot.
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/bench_scenes.h"
#include "vocabulary/hash.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/bounce_gather.h"
#include "worker/path_trace_reference.h"

namespace {

using namespace prt;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  std::string scene_name = "default", out_dir = "gi-bench", ground_albedo;
  int n = 32, bounces = 2, paths = 1024, indirect_n = 0, ref_paths = 256, threads = 0;
  std::size_t ref_vertices = 64;
  bool images = false, worst = false;
  double near_field = 1.0;
  int near_rows = 32;
  CLI::App app("prt-gi-bench: bounce gathering against the path-traced reference");
  app.add_option("--scene", scene_name, "benchmark scene (bench_scene.h: default, dragon, …)");
  app.add_option("--n", n, "cubemap n")->capture_default_str();
  app.add_option("--bounces", bounces, "largest K (every K from 1 is reported)")
      ->check(CLI::Range(1, 8))
      ->capture_default_str();
  app.add_option("--paths", paths, "gather: directions per vertex and bounce")
      ->capture_default_str();
  app.add_option("--indirect-n", indirect_n, "the bounce rows' n (0: n/4)")->capture_default_str();
  app.add_option("--ref-paths", ref_paths, "reference: paths per vertex")->capture_default_str();
  app.add_option("--ref-vertices", ref_vertices, "reference vertices per group (model, ground)")
      ->capture_default_str();
  app.add_option("--ground-albedo", ground_albedo, "r,g,b: a coloured ground (colour bleeding)");
  int ground_resolution = 0;
  app.add_option("--ground-resolution", ground_resolution,
                 "ground grid vertices per side (0: the scene's)");
  app.add_option("--threads", threads, "TBB threads (0: all)");
  app.add_option("--out", out_dir, "output folder (results.json, images)")->capture_default_str();
  app.add_flag("--images", images, "write images and the per-bounce energy plot");
  app.add_option("--near-field", near_field,
                 "bounce 1 traces T0 at hits closer than this × their triangle's longest edge "
                 "(0: interpolate every hit)")
      ->capture_default_str();
  app.add_option("--near-rows", near_rows,
                 "near-field rows traced per vertex, about (the rest weighted in)")
      ->capture_default_str();
  app.add_flag("--worst", worst, "list the 5 worst reference vertices per light and group");
  CLI11_PARSE(app, argc, argv);
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  threads);
  try {
    std::filesystem::create_directories(out_dir);
    SceneDescription scene = bench::BenchScene(scene_name, n);
    if (!ground_albedo.empty()) {
      float r = 0, g = 0, b = 0;
      if (std::sscanf(ground_albedo.c_str(), "%f,%f,%f", &r, &g, &b) != 3)
        throw std::invalid_argument("--ground-albedo wants r,g,b");
      scene.ground.albedo = {r, g, b};
    }
    if (ground_resolution > 0) scene.ground.resolution = ground_resolution;
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
    const uint64_t V = samples.size();
    const int m = indirect_n > 0 ? indirect_n : std::max(1, n / 4);
    const int C = HasColouredAlbedo(geometry) ? 3 : 1;
    const EmbreeScene embree(geometry);
    const SceneSurfaces surfaces(geometry);
    const CubemapLayout fine(n), coarse(m);
    const std::size_t cols = fine.texel_count(), mcols = coarse.texel_count();
    std::printf(
        "prt-gi-bench: %s, %llu vertices, n = %d, indirect n = %d, K <= %d, %d gather "
        "directions, %d reference paths, %d channel(s)\n",
        scene_name.c_str(), static_cast<unsigned long long>(V), n, m, bounces, paths, ref_paths, C);

    // 1. T⁰.
    TransportSamplerOptions to;
    to.rays_per_texel = 4;
    to.seed = 1;
    const TransportSampler sampler(embree, n, to);
    std::vector<float> direct(V * cols);
    auto t0 = Clock::now();
    sampler.ComputeRows(samples, 0, direct.data());
    const double direct_s = Seconds(t0);

    // 2. The bounces, with their wall times.
    BounceGatherOptions go;
    go.paths = paths;
    go.seed = 1;
    go.indirect_n = m;
    go.near_field = near_field;
    go.near_rows = near_rows;
    const BounceGatherer gatherer(embree, surfaces, go);
    std::vector<double> bounce_s;
    std::vector<GatherStats> bounce_stats;
    const std::vector<std::vector<float>> bounce_rows = GatherBounces(
        gatherer, samples, fine, coarse, direct, bounces, C, &bounce_stats, &bounce_s);
    for (int k = 1; k <= bounces; ++k) {
      const GatherStats& st = bounce_stats[k - 1];
      std::printf("bounce %d: %.1f rays per vertex, %.2f%% of the directions in the near field\n",
                  k, double(st.rays_traced) / double(V),
                  100.0 * double(st.near_hits) / (double(V) * paths));
    }

    // Lights: a uniform sky and the real environments.
    std::vector<bench::NamedEnvironment> lights;
    {
      bench::NamedEnvironment uniform;
      uniform.name = "uniform";
      uniform.cube.n = n;
      for (int c = 0; c < 3; ++c) uniform.cube.Channel(c).assign(cols, 1.0f);
      lights.push_back(std::move(uniform));
      for (auto& e : bench::BenchEnvironments(n, {"sunrise", "city", "studio"}))
        lights.push_back(std::move(e));
    }
    const std::size_t NL = lights.size();
    std::vector<std::array<std::vector<float>, 3>> coarse_light(NL);
    for (std::size_t l = 0; l < NL; ++l)
      for (int c = 0; c < 3; ++c)
        coarse_light[l][c] = CoarsenLight(fine, coarse, lights[l].cube.Channel(c));
    // Relit without albedo: D[l][v][c], I[k][l][v][c].
    auto direct_relit = [&](std::size_t l, uint64_t v, int c) {
      return bench::DotRow(direct.data() + v * cols, lights[l].cube.Channel(c).data(), cols);
    };
    auto bounce_relit = [&](int k, std::size_t l, uint64_t v, int c) {
      const int tc = C == 1 ? 0 : c;
      return bench::DotRow(bounce_rows[k - 1].data() + (tc * V + v) * mcols,
                           coarse_light[l][c].data(), mcols);
    };

    // 3. The reference on S vertices of each group.
    const bench::SampleRanges ranges = bench::RangesOf(geometry);
    const std::vector<uint64_t> model =
        bench::PickVertices(ranges.model_first, ranges.model_last, ref_vertices, 11);
    const std::vector<uint64_t> ground =
        bench::PickVertices(ranges.ground_first, ranges.ground_last, ref_vertices, 12);
    std::vector<uint64_t> picked = model;
    picked.insert(picked.end(), ground.begin(), ground.end());
    PathTraceOptions po;
    po.bounces = bounces;
    po.paths = ref_paths;
    po.rays_per_texel = 4;
    po.path_rays_per_texel = 1;
    po.seed = 1;
    const PathTraceReference reference(embree, surfaces, n, po);
    std::vector<CubemapRgb> light_cubes;
    for (const auto& l : lights) light_cubes.push_back(l.cube);
    std::vector<RelitEstimate> relit(picked.size() * NL * 3);
    t0 = Clock::now();
    tbb::parallel_for(std::size_t{0}, picked.size(), [&](std::size_t i) {
      thread_local std::vector<float> row;
      row.resize(C * cols);
      PathTraceExtras ex;
      ex.lights = light_cubes;
      ex.relit = relit.data() + i * NL * 3;
      reference.ComputeRow(samples[picked[i]], picked[i], C, row.data(), ex);
    });
    const double reference_s = Seconds(t0);

    // 4. Errors per K, light and group.
    nlohmann::ordered_json results;
    results["scene"] = scene_name;
    results["vertices"] = V;
    results["n"] = n;
    results["indirect_n"] = m;
    results["channels"] = C;
    results["gather_paths"] = paths;
    results["reference_paths"] = ref_paths;
    results["reference_vertices_per_group"] = ref_vertices;
    results["seconds"] = {{"direct", direct_s},
                          {"bounces", bounce_s},
                          {"reference_per_vertex", reference_s / double(picked.size())}};
    std::printf("\ntime (wall, this process): direct T0 %.1f s; gather per bounce", direct_s);
    for (double s : bounce_s) std::printf(" %.2f s", s);
    std::printf(" (%.2fx of the direct for K = %d); reference %.3f s per vertex\n",
                std::accumulate(bounce_s.begin(), bounce_s.end(), 0.0) / direct_s, bounces,
                reference_s / double(picked.size()));
    std::printf("\n%-2s %-9s %-7s %10s %10s %10s %10s %9s %9s\n", "K", "light", "group", "gather",
                "ref noise", "direct-only", "indirect", "err/noise", "bias");
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (int K = 1; K <= bounces; ++K) {
      for (std::size_t l = 0; l < NL; ++l) {
        for (int g = 0; g < 2; ++g) {
          const std::size_t first = g == 0 ? 0 : model.size();
          const std::size_t last = g == 0 ? model.size() : picked.size();
          double diff2 = 0, ref2 = 0, noise2 = 0, direct2 = 0, ind = 0, tot = 0, signed_diff = 0,
                 ref_sum = 0;
          for (std::size_t i = first; i < last; ++i) {
            const uint64_t v = picked[i];
            const Rgb& rho = geometry.meshes[geometry.MeshOfVertex(v)].albedo;
            for (int c = 0; c < 3; ++c) {
              const RelitEstimate& r = relit[(i * NL + l) * 3 + c];
              double ref = r.bounce[0], se2 = 0;
              for (int k = 1; k <= K; ++k) {
                ref += r.bounce[k];
                se2 += r.bounce_standard_error[k] * r.bounce_standard_error[k];
              }
              double gathered = direct_relit(l, v, c), indirect = 0;
              for (int k = 1; k <= K; ++k) indirect += bounce_relit(k, l, v, c);
              gathered += indirect;
              diff2 += rho[c] * rho[c] * (gathered - ref) * (gathered - ref);
              signed_diff += rho[c] * (gathered - ref);
              ref_sum += rho[c] * ref;
              ref2 += rho[c] * rho[c] * ref * ref;
              noise2 += rho[c] * rho[c] * se2;
              direct2 += rho[c] * rho[c] * (r.bounce[0] - ref) * (r.bounce[0] - ref);
              ind += rho[c] * indirect;
              tot += rho[c] * gathered;
            }
          }
          if (worst && K == bounces) {
            std::vector<std::pair<double, std::size_t>> order;
            for (std::size_t i = first; i < last; ++i) {
              const RelitEstimate& r = relit[(i * NL + l) * 3];
              double ref = r.bounce[0], gathered = direct_relit(l, picked[i], 0);
              for (int k = 1; k <= K; ++k) {
                ref += r.bounce[k];
                gathered += bounce_relit(k, l, picked[i], 0);
              }
              order.push_back({std::abs(gathered - ref), i});
            }
            std::sort(order.rbegin(), order.rend());
            for (std::size_t w = 0; w < 5 && w < order.size(); ++w) {
              const std::size_t i = order[w].second;
              const SpatialSample& s = samples[picked[i]];
              const RelitEstimate& r = relit[(i * NL + l) * 3];
              std::printf(
                  "   worst %s %s: vertex %llu at (%.3f, %.3f, %.3f) normal (%.2f, %.2f, "
                  "%.2f): |gather - ref| %.4f, ref direct %.4f indirect %.4f +- %.4f\n",
                  lights[l].name.c_str(), g == 0 ? "model" : "ground",
                  static_cast<unsigned long long>(picked[i]), s.position.x, s.position.y,
                  s.position.z, s.normal.x, s.normal.y, s.normal.z, order[w].first, r.bounce[0],
                  r.total() - r.bounce[0], r.indirect_standard_error);
            }
          }
          const double err = std::sqrt(diff2 / ref2), noise = std::sqrt(noise2 / ref2),
                       direct_err = std::sqrt(direct2 / ref2);
          const char* group = g == 0 ? "model" : "ground";
          const double bias = ref_sum > 0 ? signed_diff / ref_sum : 0.0;
          std::printf("%-2d %-9s %-7s %9.2f%% %9.2f%% %10.2f%% %9.1f%% %9.2f %+8.2f%%\n", K,
                      lights[l].name.c_str(), group, 100 * err, 100 * noise, 100 * direct_err,
                      tot > 0 ? 100 * ind / tot : 0.0, noise > 0 ? err / noise : 0.0, 100 * bias);
          rows.push_back({{"bounces", K},
                          {"light", lights[l].name},
                          {"group", group},
                          {"gather_error", err},
                          {"gather_bias", bias},
                          {"reference_noise", noise},
                          {"direct_only_error", direct_err},
                          {"indirect_share", tot > 0 ? ind / tot : 0.0}});
        }
      }
    }
    results["errors"] = rows;

    // Per-bounce energy: Σ T per channel over the scene (bounce 0: the direct rows).
    nlohmann::ordered_json energy = nlohmann::ordered_json::array();
    {
      double e0 = 0;
      for (float x : direct) e0 += x;
      energy.push_back({{"bounce", 0}, {"energy", e0}});
      for (int k = 1; k <= bounces; ++k) {
        double e = 0;
        for (uint64_t i = 0; i < V * mcols; ++i) e += bounce_rows[k - 1][i];  // channel 0
        energy.push_back({{"bounce", k}, {"energy", e}});
      }
    }
    results["energy"] = energy;
    std::printf("\nenergy (sum of T over the scene, channel r):");
    for (const auto& e : energy)
      std::printf("  T%d %.1f", e["bounce"].get<int>(), e["energy"].get<double>());
    std::printf("\n");

    // 5. Images under the first real environment.
    if (images) {
      const std::size_t l = 1;
      std::vector<float> d(V * 3), t(V * 3), ind(V * 3);
      tbb::parallel_for(uint64_t{0}, V, [&](uint64_t v) {
        const Rgb& rho = geometry.meshes[geometry.MeshOfVertex(v)].albedo;
        for (int c = 0; c < 3; ++c) {
          double i = 0;
          for (int k = 1; k <= bounces; ++k) i += bounce_relit(k, l, v, c);
          const double dd = direct_relit(l, v, c);
          d[v * 3 + c] = static_cast<float>(rho[c] * dd);
          t[v * 3 + c] = static_cast<float>(rho[c] * (dd + i));
          ind[v * 3 + c] = static_cast<float>(4 * rho[c] * i);
        }
      });
      const std::string base = out_dir + "/" + scene_name + "-" + lights[l].name;
      WritePng(bench::RenderVertexColours(scene, geometry, d, &lights[l].cube),
               base + "-direct.png");
      WritePng(bench::RenderVertexColours(scene, geometry, t, &lights[l].cube),
               base + "-K" + std::to_string(bounces) + ".png");
      WritePng(bench::RenderVertexColours(scene, geometry, ind, nullptr),
               base + "-indirect-x4.png");
      std::ofstream dat(out_dir + "/" + scene_name + "-energy.dat");
      for (const auto& e : energy)
        dat << e["bounce"].get<int>() << " " << e["energy"].get<double>() << "\n";
      dat.close();
      const std::string plot = out_dir + "/" + scene_name + "-energy.png";
      const std::string cmd =
          "gnuplot -e \"set terminal pngcairo size 640,400; set output '" + plot +
          "'; set logscale y; set xlabel 'bounce k'; set xtics 1; set ylabel 'energy (sum of "
          "T^k)'; set "
          "title 'per-bounce energy, " +
          scene_name + "'; plot '" + out_dir + "/" + scene_name +
          "-energy.dat' using 1:2 with linespoints lw 2 title 'T^k'\" 2>/dev/null";
      if (std::system(cmd.c_str()) != 0) std::printf("(gnuplot not available: no energy plot)\n");
      std::printf("images: %s-{direct,K%d,indirect-x4}.png, %s\n", base.c_str(), bounces,
                  plot.c_str());
    }
    std::ofstream(out_dir + "/" + scene_name + ".json") << results.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-gi-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
