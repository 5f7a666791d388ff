#include "bench/glossy_bench_scene.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>

#include "bench/bench_scene.h"
#include "viewer/rasterizer.h"
#include "vocabulary/errors.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"
#include "worker/visibility_sampler.h"

namespace prt::bench {

GlossyBenchScene LoadGlossyBenchScene(const std::string& name, int n,
                                      const std::string& cache_dir) {
  GlossyBenchScene out;
  out.name = name;
  out.scene = BenchScene(name, n);
  const SceneGeometry geometry = BuildSceneGeometry(out.scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
  // Traced maps are cached (block-coded) in the cache folder; a rerun decodes them instead.
  std::filesystem::create_directories(cache_dir);
  const std::string cache = cache_dir + "/" + name + "_n" + std::to_string(n) + ".visb";
  if (std::filesystem::exists(cache + ".time")) {
    std::ifstream in(cache, std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
    out.visibility = DecodeVisibilityBlocks(bytes, cache);
    std::ifstream(cache + ".time") >> out.trace_seconds >> out.rays_traced;
    out.from_cache = true;
    std::printf("[%s] %zu vertices: maps from %s (traced earlier in %.1f s)\n", name.c_str(),
                samples.size(), cache.c_str(), out.trace_seconds);
  } else {
    std::printf("[%s] %zu vertices: tracing %d² visibility maps…\n", name.c_str(), samples.size(),
                n);
    std::fflush(stdout);
    const EmbreeScene embree(geometry);
    const VisibilitySampler sampler(embree, {.n = n});
    VisibilitySamplerStats vst;
    const auto t0 = std::chrono::steady_clock::now();
    out.visibility = sampler.ComputeBlocks(samples, &vst);
    out.trace_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out.rays_traced = vst.rays_traced;
    const std::vector<uint8_t> bytes = EncodeVisibilityBlocks(out.visibility);
    std::ofstream(cache, std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
    std::ofstream(cache + ".time") << out.trace_seconds << " " << out.rays_traced << "\n";
  }
  if (out.visibility.vertex_count != samples.size())
    throw InputError(cache, "cached maps are for another scene");
  for (const SceneMesh& m : geometry.meshes) {
    const auto base = static_cast<uint32_t>(out.positions.size());
    for (const auto& t : m.mesh.triangles)
      out.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
    out.positions.insert(out.positions.end(), m.mesh.positions.begin(), m.mesh.positions.end());
    out.material_index.insert(out.material_index.end(), m.mesh.positions.size(),
                              m.is_ground ? 1 : 0);
  }
  for (const SpatialSample& s : samples) out.normals.push_back(s.normal);
  out.model_albedo = geometry.meshes.front().albedo;
  out.ground_albedo = geometry.meshes.back().albedo;
  return out;
}

// A flyby: the scene camera's eye turned about the vertical through its target.
std::vector<Camera> Flyby(const Camera& base, int views) {
  std::vector<Camera> out;
  for (int i = 0; i < views; ++i) {
    const double a = views == 1 ? 0.0 : (-50.0 + 100.0 * i / (views - 1)) * std::numbers::pi / 180;
    Camera c = base;
    const Vec3 d = base.eye - base.target;
    c.eye = base.target + Vec3{d.x * std::cos(a) + d.z * std::sin(a),
                               d.y * (1.0 + 0.25 * std::sin(2 * a)),
                               -d.x * std::sin(a) + d.z * std::cos(a)};
    out.push_back(c);
  }
  return out;
}

std::vector<Camera> Orbit(const Camera& base, int frames) {
  std::vector<Camera> out;
  for (int i = 0; i < frames; ++i) {
    const double a = 2.0 * std::numbers::pi * i / frames;
    Camera c = base;
    const Vec3 d = base.eye - base.target;
    c.eye = base.target + Vec3{d.x * std::cos(a) + d.z * std::sin(a), d.y,
                               -d.x * std::sin(a) + d.z * std::cos(a)};
    out.push_back(c);
  }
  return out;
}

GlossyFrame RenderGlossyFrame(const Camera& cam, const std::vector<Vec3>& positions,
                              const std::vector<std::array<uint32_t, 3>>& triangles,
                              const std::vector<float>& rgb) {
  const RasterImage r = RasterizeTriangles(cam, positions, triangles, rgb);
  GlossyFrame f{ImageRgb(r.width, r.height), std::vector<uint8_t>(r.triangle.size())};
  f.image.pixels = r.rgb;
  for (std::size_t i = 0; i < r.triangle.size(); ++i) f.covered[i] = r.triangle[i] >= 0;
  return f;
}

namespace {
double PsnrOf(double se, std::size_t count, double peak) {
  return se == 0 ? 99.0 : 10 * std::log10(peak * peak * static_cast<double>(count) / se);
}

}  // namespace

PsnrSet Psnr(const GlossyFrame& test, const GlossyFrame& ref, double exposure) {
  double se = 0, se_lin = 0, peak = 0;
  std::size_t count = 0;
  for (std::size_t p = 0; p < ref.covered.size(); ++p) {
    if (!ref.covered[p]) continue;
    for (int c = 0; c < 3; ++c) {
      const double x = test.image.pixels[p * 3 + c], y = ref.image.pixels[p * 3 + c];
      const double a = SrgbEncode(std::clamp(x * exposure, 0.0, 1.0));
      const double b = SrgbEncode(std::clamp(y * exposure, 0.0, 1.0));
      se += (a - b) * (a - b);
      se_lin += (x - y) * (x - y);
      peak = std::max(peak, y);
      ++count;
    }
  }
  return {PsnrOf(se, count, 1.0), PsnrOf(se, ref.covered.size() * 3, 1.0),
          PsnrOf(se_lin, count, peak)};
}

double ExposureOf(const GlossyFrame& ref) {
  std::vector<float> v;
  for (std::size_t p = 0; p < ref.covered.size(); ++p)
    if (ref.covered[p])
      v.push_back(std::max(
          {ref.image.pixels[p * 3], ref.image.pixels[p * 3 + 1], ref.image.pixels[p * 3 + 2]}));
  if (v.empty()) return 1.0;
  std::nth_element(v.begin(), v.begin() + v.size() * 99 / 100, v.end());
  const double p99 = v[v.size() * 99 / 100];
  return p99 > 0 ? 1.0 / p99 : 1.0;
}

}  // namespace prt::bench
