// prt-tp-bench (issue 41): per-block triple products (Inger, Farbman & Lischinski 2013,
// Algorithm 1) per frame, with the camera orbiting and the lighting rotating, on the glossy
// scene's materials (scenes/glossy.toml: a Phong 100 model, an Ashikhmin–Shirley 10×200 ground)
// over benchmark scenes with real meshes. Prints, per scene:
//   - relight ms per frame on 1 thread (the thread's CPU time) and 2 threads (wall), scaled to
//     100k vertices, for the kernel before
//     issue 41 (TripleProductOptions::generic), the optimised kernel, and the optimised kernel
//     with each speedup turned off alone (what each pays on its own); all timings interleaved
//     round by round, the median of the rounds, so that load on the shared machine lands on every
//     variant alike;
//   - the image PSNR (the paper's Figure 5 convention, glossy_bench_scene.h) of both kernels
//     against the pixel-basis reference (the BRDF at every texel centre);
//   - the whole frame on 2 threads (lighting blocks for the rotated map, relight, rasterise at the
//     scene camera's 640×480 over the environment) in ms and fps, against the paper's 17 fps at
//     113k vertices on 4 cores.
// Writes <out>/results.md and one PNG per scene (reference | optimised | 10× |difference|).
//
//   prt-tp-bench [--scenes default,armadillo,dragon] [--n 64] [--frames 8] [--rounds 5]
//                [--env sunrise] [--cache bench-out/glossy] [--out bench-out/tp]
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_scene.h"
#include "bench/bench_scenes.h"
#include "bench/glossy_bench_scene.h"
#include "runtime/block_lighting.h"
#include "runtime/brdf.h"
#include "runtime/triple_product.h"
#include "viewer/environment_background.h"
#include "viewer/rasterizer.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/image_io.h"
#include "vocabulary/tbb_parallel.h"

namespace prt {
namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

// CPU seconds of the calling thread: one-thread timings do not count time the thread waited
// for a core on the shared machine.
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// scenes/glossy.toml's materials: the model Phong (s = 100), the ground Ashikhmin–Shirley.
std::vector<Material> GlossyTomlMaterials() {
  Material model;
  model.model = BrdfModel::kPhong;
  model.diffuse = {0.45f, 0.4f, 0.35f};
  model.specular = {0.5f, 0.5f, 0.5f};
  model.exponent = 100;
  Material ground;
  ground.model = BrdfModel::kAshikhminShirley;
  ground.diffuse = {0.5f, 0.5f, 0.5f};
  ground.specular = {0.3f, 0.3f, 0.3f};
  ground.exponent = 10;
  ground.exponent_v = 200;
  return {model, ground};
}

struct Variant {
  std::string name;
  TripleProductOptions options;
};

std::vector<Variant> Variants(bool exact) {
  std::vector<Variant> v = {
      {"before issue 41 (block by block)", {.exact_cosine = exact, .generic = true}},
      {"optimised", {.exact_cosine = exact}}};
  for (uint32_t bit = 1; bit & kAllSpeedups; bit <<= 1)
    v.push_back({std::string("optimised without ") + TripleProductSpeedupName(bit),
                 {.exact_cosine = exact, .disable = bit}});
  return v;
}

// Runs f with the runtime's loops on a TBB arena of `threads` threads.
template <class F>
void OnThreads(int threads, F&& f) {
  tbb::task_arena arena(threads);
  arena.execute([&] {
    UseTbbParallelism();
    f();
  });
}

}  // namespace
}  // namespace prt

int main(int argc, char** argv) {
  using namespace prt;
  std::string scenes_arg = "default,armadillo,dragon", env_name = "sunrise";
  std::string cache = "bench-out/glossy", out_dir = "bench-out/tp";
  int n = 64, frames = 8, rounds = 5;
  CLI::App app{"prt-tp-bench: triple products per frame, per speedup and per thread count"};
  app.add_option("--scenes", scenes_arg, "comma-separated benchmark scenes");
  app.add_option("--n", n, "visibility cubemap resolution");
  app.add_option("--frames", frames, "frames of the orbit (camera 360°, lighting 360°)");
  app.add_option("--rounds", rounds, "timing rounds (the median is printed)");
  app.add_option("--env", env_name, "environment map name (data folder)");
  app.add_option("--cache", cache, "folder of traced visibility (shared with glossy_bench)");
  app.add_option("--out", out_dir, "output folder");
  int only = -1;
  app.add_option("--only", only, "time only this variant (0: before, 1: optimised, …; profiling)");
  bool timing_only = false;
  app.add_flag("--timing-only", timing_only,
               "only the relight timings (no accuracy or whole frame; for a profiler)");
  bool paper_cosine = false;
  app.add_flag(
      "--paper-cosine", paper_cosine,
      "the paper's constant diffuse term per block instead of the exact cosine (prt-view's "
      "default)");
  CLI11_PARSE(app, argc, argv);
  const bool exact = !paper_cosine;
  std::filesystem::create_directories(out_dir);
  const std::vector<std::string> scenes = bench::Split(scenes_arg);
  const auto env = std::make_shared<const EnvironmentLookup>(
      ReadEnvironment(bench::DataDir() + "/envmaps/" + env_name + ".exr"), env_name);
  const CubemapBlocks blocks(n);
  const std::vector<Material> materials = GlossyTomlMaterials();
  const std::vector<Variant> variants = Variants(exact);

  std::ostringstream speed, quality, whole;
  speed
      << "| scene | vertices | kernel | 1 thread ms (CPU) | 2 threads ms | 2 threads at 100k ms | "
         "fps at 100k (2 threads) | 2-thread scaling | speed-up (2 threads) |\n"
         "|---|---|---|---|---|---|---|---|---|\n";
  quality << "| scene | view | PSNR dB before | PSNR dB optimised | rel. max difference |\n"
             "|---|---|---|---|---|\n";
  whole << "| scene | vertices | lighting ms | relight ms | rasterise ms | frame ms | fps | fps "
           "scaled to 113k relight |\n|---|---|---|---|---|---|---|---|\n";
  char line[512];
  for (const std::string& name : scenes) {
    const bench::GlossyBenchScene gs = bench::LoadGlossyBenchScene(name, n, cache);
    const std::size_t nv = gs.positions.size();
    const GlossyScene scene{gs.positions, gs.normals, gs.material_index, materials, &gs.visibility};
    const std::vector<Camera> cams = bench::Orbit(gs.scene.camera, frames);
    std::vector<double> rotation(frames);
    std::vector<BlockLighting> light(frames);
    for (int f = 0; f < frames; ++f) {
      rotation[f] = 2.0 * std::numbers::pi * f / frames;
      UpdateBlockLighting(ResampleToCubemap(env->image(), n, rotation[f]), blocks, light[f]);
    }
    std::vector<float> rgb(nv * 3);
    // Timing: rounds × variants × {1, 2} threads, interleaved.
    std::vector<std::vector<double>> t1(variants.size()), t2(variants.size());
    for (int r = 0; r < rounds; ++r)
      for (std::size_t v = 0; v < variants.size(); ++v)
        for (int threads : {1, 2}) {
          if (only >= 0 && static_cast<int>(v) != only) continue;
          OnThreads(threads, [&] {
            const auto t0 = Clock::now();
            const double c0 = ThreadCpuSeconds();
            for (int f = 0; f < frames; ++f)
              RelightTripleProduct(scene, blocks, light[f], cams[f].eye, rgb, variants[v].options);
            if (threads == 1)
              t1[v].push_back((ThreadCpuSeconds() - c0) / frames);
            else
              t2[v].push_back(Seconds(t0) / frames);
          });
        }
    const double base2 = Median(t2[0]);
    for (std::size_t v = 0; v < variants.size(); ++v) {
      const double a = Median(t1[v]), b = Median(t2[v]);
      const double at100k = b * 100000.0 / static_cast<double>(nv);
      std::snprintf(line, sizeof line,
                    "| %s | %zu | %s | %.1f | %.1f | %.1f | %.1f | %.2f× | %.2f× |\n", name.c_str(),
                    nv, variants[v].name.c_str(), 1e3 * a, 1e3 * b, 1e3 * at100k, 1.0 / at100k,
                    a / b, base2 / b);
      speed << line;
      std::printf("%s", line);
    }
    std::fflush(stdout);

    if (timing_only) continue;
    // Accuracy against the pixel basis at two views.
    OnThreads(2, [&] {
      for (int f : {0, frames / 2}) {
        std::vector<float> ref(nv * 3), before(nv * 3), after(nv * 3);
        RelightPixelBasisReference(scene, blocks, light[f], cams[f].eye, ref, true);
        RelightTripleProduct(scene, blocks, light[f], cams[f].eye, before, variants[0].options);
        RelightTripleProduct(scene, blocks, light[f], cams[f].eye, after, variants[1].options);
        double max_diff = 0, max_val = 0;
        for (std::size_t i = 0; i < after.size(); ++i) {
          max_diff = std::max(max_diff, static_cast<double>(std::abs(after[i] - before[i])));
          max_val = std::max(max_val, static_cast<double>(std::abs(before[i])));
        }
        const bench::GlossyFrame fr =
            bench::RenderGlossyFrame(cams[f], gs.positions, gs.triangles, ref);
        const bench::GlossyFrame fb =
            bench::RenderGlossyFrame(cams[f], gs.positions, gs.triangles, before);
        const bench::GlossyFrame fa =
            bench::RenderGlossyFrame(cams[f], gs.positions, gs.triangles, after);
        const double exposure = bench::ExposureOf(fr);
        std::snprintf(line, sizeof line, "| %s | %d | %.2f | %.2f | %.1e |\n", name.c_str(), f,
                      bench::Psnr(fb, fr, exposure).covered, bench::Psnr(fa, fr, exposure).covered,
                      max_val > 0 ? max_diff / max_val : 0.0);
        quality << line;
        std::printf("%s", line);
        if (f == 0) {
          ImageRgb x = fa.image, y = fr.image;
          for (float& p : x.pixels) p = static_cast<float>(p * exposure);
          for (float& p : y.pixels) p = static_cast<float>(p * exposure);
          WritePng(SideBySide(y, x, true, 10.0), out_dir + "/" + name + ".png");
        }
      }
    });

    // The whole frame on 2 threads: the map rotated (the runtime's interactive rotation about +Y,
    // PeriodicLatLongResampler) and projected, the frame relit, rasterised.
    OnThreads(2, [&] {
      std::vector<double> tl, tr, tz;
      BlockLighting bl;
      const PeriodicLatLongResampler rotator(env->image(), n, 16 * n);
      for (int r = 0; r < rounds; ++r)
        for (int f = 0; f < frames; ++f) {
          auto t0 = Clock::now();
          UpdateBlockLighting(rotator.Resample(rotation[f]), blocks, bl);
          tl.push_back(Seconds(t0));
          t0 = Clock::now();
          RelightTripleProduct(scene, blocks, bl, cams[f].eye, rgb, variants[1].options);
          tr.push_back(Seconds(t0));
          t0 = Clock::now();
          RasterOptions ro;
          ro.background = EnvironmentBackground(env, rotation[f]);
          const RasterImage img = RasterizeTriangles(cams[f], gs.positions, gs.triangles, rgb, ro);
          tz.push_back(Seconds(t0));
        }
      const double l = Median(tl), rl = Median(tr), z = Median(tz);
      const double rl113 = rl * 113000.0 / static_cast<double>(nv);
      std::snprintf(line, sizeof line, "| %s | %zu | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f |\n",
                    name.c_str(), nv, 1e3 * l, 1e3 * rl, 1e3 * z, 1e3 * (l + rl + z),
                    1.0 / (l + rl + z), 1.0 / (l + rl113 + z));
      whole << line;
      std::printf("%s", line);
    });
    std::fflush(stdout);
  }
  std::ostringstream md;
  md << "# prt-tp-bench: triple products per frame (Inger et al. 2013, Algorithm 1)\n\n"
     << "n = " << n << ", env " << env_name << ", " << frames
     << " frames (camera orbiting 360°, lighting rotating 360°), median of " << rounds
     << " interleaved rounds; scenes/glossy.toml's materials (Phong 100 model, "
        "Ashikhmin–Shirley 10×200 ground); diffuse term: "
     << (exact ? "the exact cosine (prt-view's default)" : "the paper's constant per block")
     << ".\n\n## Relight per frame\n\n"
     << speed.str()
     << "\n## Accuracy against the pixel basis (image PSNR, the paper's Figure 5 convention; "
        "max |optimised − before| / max |before| over vertex radiance)\n\n"
     << quality.str()
     << "\n## The whole frame on 2 threads (lighting blocks of the rotated map, relight, "
        "rasterise 640×480 over the environment); the paper: 17 fps at 113k vertices on 4 "
        "cores\n\n"
     << whole.str();
  std::ofstream(out_dir + "/results.md") << md.str();
  std::printf("\n%s\nwrote %s/results.md\n", md.str().c_str(), out_dir.c_str());
  return 0;
}
