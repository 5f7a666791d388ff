// prt-raster-bench: the software rasteriser (viewer/rasterizer.h) against the one it replaced
// (viewer/rasterizer_reference.h) on real packs at 640×480 over the environment image, on one
// thread and on two (TBB), old and new interleaved rep by rep so that the machine's drift hits
// both alike (docs/viewer.md, "Rasteriser speed"). The camera orbits the pack's target by 3° per
// rep, as the glossy window's does, so nothing can be reused from one frame to the next. Before
// timing, each pack's frame is compared pixel for pixel: the visible triangle must be the same
// everywhere and colours agree within 1e-5 relative.
//
//   prt-raster-bench --glossy /tmp/g41/glossy.prtpack --demo demo-out/default.prtpack
//                    --env build/data/envmaps/city.exr [--reps 15] [--threads 1,2]
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "runtime/lighting.h"
#include "viewer/environment_background.h"
#include "viewer/glossy_session.h"
#include "viewer/rasterizer.h"
#include "viewer/rasterizer_reference.h"
#include "viewer/viewer_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/tbb_parallel.h"

namespace prt {
namespace {

using Clock = std::chrono::steady_clock;

struct Mesh {
  std::string name;
  Camera camera;
  std::vector<Vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<float> rgb;
};

Mesh LoadGlossy(const std::string& path, const EnvironmentImage& env) {
  const auto s = GlossySession::Open(path);
  Mesh m{path,
         s->camera(),
         {s->positions().begin(), s->positions().end()},
         {s->triangles().begin(), s->triangles().end()},
         {}};
  const BlockLighting light = s->Lighting(ResampleToCubemap(env, s->cubemap_n()));
  m.rgb.resize(3 * s->sample_count());
  s->Relight(light, m.camera.eye, m.rgb);
  return m;
}

Mesh LoadDemo(const std::string& path, const EnvironmentImage& env) {
  const auto s = ViewerSession::Open(path);
  Mesh m{path,
         s->camera(),
         {s->positions().begin(), s->positions().end()},
         {s->triangles().begin(), s->triangles().end()},
         {}};
  const CubemapRgb cube = ResampleToCubemap(env, s->cubemap_n());
  m.rgb = s->Shade(s->RelightExact(ProjectLighting(cube)));
  return m;
}

// The camera turned by `deg` about the vertical through its target.
Camera Orbit(Camera c, double deg) {
  const double a = deg * 3.14159265358979323846 / 180.0, ca = std::cos(a), sa = std::sin(a);
  const Vec3 d = c.eye - c.target;
  c.eye = c.target + Vec3{ca * d.x + sa * d.z, d.y, -sa * d.x + ca * d.z};
  return c;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

double Min(const std::vector<double>& v) {
  return *std::min_element(v.begin(), v.end());
}

// CPU time of the whole process (every thread), ms.
double CpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

// Coverage identical, colours within 1e-5 relative (of max(1, |old|)); prints what differs.
bool SamePicture(const RasterImage& a, const RasterImage& b) {
  std::size_t cover = 0, colour = 0, drawn = 0;
  double worst = 0;
  for (std::size_t p = 0; p < a.triangle.size(); ++p) {
    if (a.triangle[p] != b.triangle[p]) ++cover;
    drawn += a.triangle[p] >= 0;
    for (int c = 0; c < 3; ++c) {
      const double x = a.rgb[3 * p + c], y = b.rgb[3 * p + c];
      const double rel = std::abs(x - y) / std::max(1.0, std::abs(x));
      worst = std::max(worst, rel);
      if (rel > 1e-5) ++colour;
    }
  }
  std::printf(
      "  picture check: %zu of %zu pixels covered, %zu differ in coverage, %zu colour "
      "values beyond 1e-5 relative (worst %.3g)\n",
      drawn, a.triangle.size(), cover, colour, worst);
  return cover == 0 && colour == 0;
}

int Run(int argc, char** argv) {
  std::string glossy, demo, env_path, threads = "1,2";
  int reps = 15, width = 640, height = 480;
  CLI::App app{"prt-raster-bench: the tiled rasteriser against the old one (docs/viewer.md)"};
  app.add_option("--glossy", glossy, "glossy (visibility) pack");
  app.add_option("--demo", demo, "diffuse pack");
  app.add_option("--env", env_path, "environment map (the background)")->required();
  app.add_option("--reps", reps, "frames per setting (median reported)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--threads", threads, "comma-separated TBB thread counts");
  app.add_option("--width", width)->check(CLI::Range(1, 16384));
  app.add_option("--height", height)->check(CLI::Range(1, 16384));
  CLI11_PARSE(app, argc, argv);
  UseTbbParallelism();
  const auto lookup =
      std::make_shared<const EnvironmentLookup>(ReadEnvironment(env_path), env_path);
  std::vector<Mesh> meshes;
  if (!glossy.empty()) meshes.push_back(LoadGlossy(glossy, lookup->image()));
  if (!demo.empty()) meshes.push_back(LoadDemo(demo, lookup->image()));
  std::vector<int> thread_counts;
  {
    std::stringstream ss(threads);
    for (std::string t; std::getline(ss, t, ',');) thread_counts.push_back(std::stoi(t));
  }
  RasterOptions opt;
  opt.background = EnvironmentBackground(lookup, 0.3);
  bool ok = true;
  std::printf(
      "# prt-raster-bench: %dx%d over %s, %d frames per setting, camera orbiting 3°/frame.\n"
      "# wall ms: median (min) of the frames; CPU ms: the process's CPU time per frame (all its\n"
      "# threads), median; old/new: ratio of the median wall times, old and new alternating\n"
      "# frame by frame so that the machine's drift hits both\n",
      width, height, env_path.c_str(), reps);
  std::vector<std::string> rows;
  for (Mesh& m : meshes) {
    m.camera.width = width;
    m.camera.height = height;
    {
      std::printf("%s: %zu triangles\n", m.name.c_str(), m.triangles.size());
      const RasterImage a =
          RasterizeTrianglesReference(m.camera, m.positions, m.triangles, m.rgb, opt);
      const RasterImage b = RasterizeTriangles(m.camera, m.positions, m.triangles, m.rgb, opt);
      ok = SamePicture(a, b) && ok;
    }
    for (int t : thread_counts) {
      tbb::global_control gc(tbb::global_control::max_allowed_parallelism, t);
      std::vector<double> old_ms, new_ms, bare_ms, old_cpu, new_cpu;
      const auto ms = [](Clock::time_point a, Clock::time_point b) {
        return std::chrono::duration<double, std::milli>(b - a).count();
      };
      for (int r = -1; r < reps; ++r) {  // r = −1: warm-up
        const Camera cam = Orbit(m.camera, 3.0 * r);
        const double c0 = CpuMs();
        const auto t0 = Clock::now();
        const RasterImage a =
            RasterizeTrianglesReference(cam, m.positions, m.triangles, m.rgb, opt);
        const auto t1 = Clock::now();
        const double c1 = CpuMs();
        const RasterImage b = RasterizeTriangles(cam, m.positions, m.triangles, m.rgb, opt);
        const auto t2 = Clock::now();
        const double c2 = CpuMs();
        const RasterImage c = RasterizeTriangles(cam, m.positions, m.triangles, m.rgb);
        const auto t3 = Clock::now();
        if (r < 0) continue;
        old_ms.push_back(ms(t0, t1));
        new_ms.push_back(ms(t1, t2));
        bare_ms.push_back(ms(t2, t3));
        old_cpu.push_back(c1 - c0);
        new_cpu.push_back(c2 - c1);
      }
      char row[512];
      std::snprintf(row, sizeof row,
                    "| %s | %d | %.2f (%.2f) | %.2f (%.2f) | %.2f | %.2f | %.2f | %.2f (%.2f) |",
                    m.name.c_str(), t, Median(old_ms), Min(old_ms), Median(new_ms), Min(new_ms),
                    Median(old_ms) / Median(new_ms), Median(old_cpu), Median(new_cpu),
                    Median(bare_ms), Min(bare_ms));
      rows.push_back(row);
    }
  }
  std::printf(
      "\n| pack | threads | old wall ms | new wall ms | old/new | old CPU ms | new CPU ms | new "
      "without background, wall ms |\n|---|---|---|---|---|---|---|---|\n");
  for (const std::string& r : rows) std::printf("%s\n", r.c_str());
  if (!ok) std::printf("PICTURES DIFFER\n");
  return ok ? 0 : 1;
}

}  // namespace
}  // namespace prt

int main(int argc, char** argv) {
  try {
    return prt::Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-raster-bench: %s\n", e.what());
    return 1;
  }
}
