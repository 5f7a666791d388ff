// glossy_pixel_bench: how well does a glossy pixel's row (docs/image-relighting.md, "Glossy
// pixels") resolve its lobe at the lighting cubemap's resolution? For GGX at several roughnesses
// and cubemap sizes n, unoccluded pixels (random normals within 60° of +Y, random views with
// n·ω_o in [0.2, 1]) are relit two ways under real environment maps:
//   row:        B = Σ_j T_j · L_j, T from TransportSampler (rays_per_texel jittered rays per
//               texel, the farm's estimator) and L the map resampled to the cubemap (texel
//               averages, as the viewer relights);
//   reference:  B = Σ_pixels L(ω) · f_s(ω, ω_o) · max(0, n·ω) · Ω over the map's own lat-long
//               pixels, 2×2 points per pixel (independent of the cubemap).
// and the relative RMS of the difference over the pixels is printed per map, roughness, n and
// rays per texel, for the pure lobe (k_d = 0, k_s = 1: the worst case; a diffuse part adds
// error-free-ish energy).
//
// With --compare RUN_A RUN_B (two image runs of one scene, e.g. the sparse method and brute
// force, or a glossy and a diffuse material) it instead relights both runs' uncompressed rows
// (transport.prtt) under each map, every pixel weighted as the viewer weighs it (PixelAlbedo:
// albedo, or a glossy pixel's weight), and prints the relative RMS of A against B over each
// mesh's pixels: the sparse method's error on glossy and on diffuse pixels of one image.
//
// Usage: glossy_pixel_bench [--env file]... [--configs 40]
//        glossy_pixel_bench --compare run_a run_b [--env file]...
#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "runtime/brdf.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "formats/geometry_file.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

#ifndef PRT_DATA_DIR
#define PRT_DATA_DIR "data"
#endif

namespace {

struct Config {
  prt::Vec3 normal, view;
};

struct EnvPoint {
  prt::Vec3 dir;
  double weight;  // Ω/4
  float rgb[3];
};

// Relit radiance of every pixel of an image run under `light` (channel c), weighted.
std::vector<double> RelitImage(const std::string& run, const prt::CubemapRgb& light,
                               std::vector<uint32_t>& pixel_mesh, std::size_t& meshes) {
  using namespace prt;
  const SceneGeometry g = ReadSceneGeometryFile(run + "/" + kGeometryFileName);
  const ImageSamplesInfo im =
      ReadImageSamplesFile(run + "/" + kImageFileName, static_cast<uint32_t>(g.meshes.size()));
  std::vector<Rgb> mesh_albedo;
  for (const SceneMesh& m : g.meshes) mesh_albedo.push_back(m.albedo);
  const std::vector<Rgb> w = PixelAlbedo(im, mesh_albedo);
  const TransportFileReader r(run + "/transport.prtt");
  const std::size_t cols = r.info().cols(), rows = r.info().rows;
  // A block of rows at a time (a packed file decodes whole blocks).
  const std::size_t step = r.info().rows_per_block;
  std::vector<float> block(step * cols);
  std::vector<double> out(3 * rows);
  for (std::size_t first = 0; first < rows; first += step) {
    const std::size_t count = std::min(step, rows - first);
    r.ReadRows(first, count, block.data());
    for (std::size_t i = 0; i < count; ++i) {
      const float* row = block.data() + i * cols;
      for (int c = 0; c < 3; ++c) {
        double b = 0;
        for (std::size_t j = 0; j < cols; ++j) b += row[j] * light.Channel(c)[j];
        out[3 * (first + i) + c] = w[first + i][c] * b;
      }
    }
  }
  pixel_mesh = im.pixel_mesh;
  meshes = g.meshes.size();
  return out;
}

int CompareRuns(const std::string& a, const std::string& b, const std::vector<std::string>& envs) {
  using namespace prt;
  std::printf("%-12s %-10s %8s %12s\n", "map", "mesh", "pixels", "rel. RMS");
  for (const std::string& path : envs) {
    const EnvironmentImage env = ReadEnvironment(path);
    const TransportFileReader ra(a + "/transport.prtt");
    const CubemapRgb light = ResampleToCubemap(env, static_cast<int>(ra.info().cubemap_n));
    std::vector<uint32_t> pm, pm_b;
    std::size_t meshes = 0, meshes_b = 0;
    const std::vector<double> ba = RelitImage(a, light, pm, meshes);
    const std::vector<double> bb = RelitImage(b, light, pm_b, meshes_b);
    if (ba.size() != bb.size() || pm != pm_b) {
      std::fprintf(stderr, "%s and %s are not the same image\n", a.c_str(), b.c_str());
      return 1;
    }
    const std::string name = path.substr(path.find_last_of('/') + 1);
    const SceneGeometry g = ReadSceneGeometryFile(a + "/" + kGeometryFileName);
    for (std::size_t m = 0; m < meshes; ++m) {
      double num = 0, den = 0;
      std::size_t count = 0;
      for (std::size_t p = 0; p < pm.size(); ++p) {
        if (pm[p] != m) continue;
        ++count;
        for (int c = 0; c < 3; ++c) {
          const double d = ba[3 * p + c] - bb[3 * p + c];
          num += d * d;
          den += bb[3 * p + c] * bb[3 * p + c];
        }
      }
      std::printf("%-12s %-10s %8zu %11.3f%%\n", name.c_str(), g.meshes[m].name.c_str(), count,
                  den > 0 ? 100 * std::sqrt(num / den) : 0.0);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace prt;
  std::vector<std::string> envs = {std::string(PRT_DATA_DIR) + "/envmaps/sunrise.exr",
                                   std::string(PRT_DATA_DIR) + "/envmaps/city.exr"};
  int configs = 40;
  CLI::App app{"glossy_pixel_bench: a glossy pixel's row against a per-pixel reference"};
  app.add_option("--env", envs, "environment maps (lat-long)");
  app.add_option("--configs", configs, "random (normal, view) pairs per setting");
  std::vector<std::string> compare;
  app.add_option("--compare", compare, "two image run folders: A's relit error against B's")
      ->expected(2);
  CLI11_PARSE(app, argc, argv);
  if (!compare.empty()) return CompareRuns(compare[0], compare[1], envs);

  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Config> cs;
  for (int i = 0; i < configs; ++i) {
    // Normal within 60° of +Y; view with n·ω_o in [0.2, 1].
    const double ct = 0.5 + 0.5 * u(rng), phi = 2 * std::numbers::pi * u(rng);
    const double st = std::sqrt(1 - ct * ct);
    const Vec3 n{st * std::cos(phi), ct, st * std::sin(phi)};
    Vec3 t, b;
    OrthonormalBasis(n, t, b);
    const double cv = 0.2 + 0.8 * u(rng), pv = 2 * std::numbers::pi * u(rng);
    const double sv = std::sqrt(1 - cv * cv);
    cs.push_back({n, n * cv + t * (sv * std::cos(pv)) + b * (sv * std::sin(pv))});
  }
  const EmbreeScene none{SceneGeometry{}};
  std::printf("%-12s %9s %4s %6s %12s %12s\n", "map", "roughness", "n", "rays", "rel. RMS",
              "mean |B|");
  for (const std::string& path : envs) {
    const EnvironmentImage env = ReadEnvironment(path);
    if (env.layout != EnvmapLayout::kLatLong) {
      std::fprintf(stderr, "%s: not lat-long, skipped\n", path.c_str());
      continue;
    }
    std::vector<EnvPoint> points;
    points.reserve(env.PixelCount() * 4);
    for (int y = 0; y < env.height; ++y) {
      for (int x = 0; x < env.width; ++x) {
        const double omega = PixelSolidAngle(env, x, y);
        const std::size_t i = env.Index(x, y);
        for (int s = 0; s < 4; ++s) {
          const double px = std::clamp(x + ((s & 1) ? 0.25 : -0.25), 0.0, env.width - 1.0);
          const double py = std::clamp(y + ((s & 2) ? 0.25 : -0.25), 0.0, env.height - 1.0);
          points.push_back({LatLongDirection(env.width, env.height, px, py), omega / 4,
                            {env.r[i], env.g[i], env.b[i]}});
        }
      }
    }
    const std::string name = path.substr(path.find_last_of('/') + 1);
    for (double r : {0.2, 0.35, 0.5, 0.8}) {
      Material m;
      m.model = BrdfModel::kGgx;
      m.roughness = r;
      m.diffuse = {0, 0, 0};
      m.specular = {1, 1, 1};
      // The reference, once per config.
      std::vector<std::array<double, 3>> ref(cs.size());
      for (std::size_t k = 0; k < cs.size(); ++k) {
        const ShadingFrame f = MakeShadingFrame(cs[k].normal, cs[k].view);
        std::array<double, 3> acc{0, 0, 0};
        for (const EnvPoint& p : points) {
          const double w = SpecularLobe(m, f, p.dir);
          if (w == 0) continue;
          for (int c = 0; c < 3; ++c) acc[c] += w * p.weight * p.rgb[c];
        }
        ref[k] = acc;
      }
      for (int n : {16, 32, 64}) {
        const CubemapRgb light = ResampleToCubemap(env, n);
        for (int rays : {4, 64}) {
          TransportSamplerOptions o;
          o.rays_per_texel = rays;
          double num = 0, den = 0, mean = 0;
          for (std::size_t k = 0; k < cs.size(); ++k) {
            // The point is the origin: ω_o = eye.
            const TransportSampler sampler(none, n, o, {{m}, cs[k].view});
            SpatialSample s;
            s.normal = s.geometric_normal = cs[k].normal;
            s.glossy_material = 0;
            std::vector<float> row(sampler.layout().texel_count());
            sampler.ComputeRow(s, k, row.data());
            for (int c = 0; c < 3; ++c) {
              double b = 0;
              for (std::size_t j = 0; j < row.size(); ++j) b += row[j] * light.Channel(c)[j];
              num += (b - ref[k][c]) * (b - ref[k][c]);
              den += ref[k][c] * ref[k][c];
              mean += std::abs(ref[k][c]) / (3.0 * static_cast<double>(cs.size()));
            }
          }
          std::printf("%-12s %9.2f %4d %6d %11.3f%% %12.4g\n", name.c_str(), r, n, rays,
                      100 * std::sqrt(num / den), mean);
          std::fflush(stdout);
        }
      }
    }
  }
  return 0;
}
