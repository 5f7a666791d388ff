// supersample_bench: what `[camera] supersample = k` removes and what it costs
// (docs/image-relighting.md, "Supersampling"). Given image runs of one scene that differ only in
// k (uncompressed rows kept: `prt-farm … --no-compress`), one of them the reference (k = 16),
// it relights every run's transport.prtt under each environment map as the viewer does,
//   B_c(p) = w_c(p) · Σ_j T[p][j]·L_c[j] + (1 − coverage(p)) · E_c(p)
// (w and coverage from image.prti: PixelAlbedo and PixelEnvironmentShare; L the map resampled to
// the cubemap; E the map along the pixel's centre ray, EnvironmentLookup), and prints the
// relative RMS of each run's image against the reference's over the edge pixels (those whose
// 3×3 neighbourhood in the reference sees more than one mesh, or background) and over the
// interior surface pixels, with the rows' seconds from each run's report.json (the `brute` or
// `sparse` phase).
//
// Usage: supersample_bench --reference RUN16 RUN1 RUN2 RUN4 [--env file]... [--dump PREFIX]
// (--dump writes each image relit under the first map, for comparing with prt-view's EXRs.)
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "formats/geometry_file.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "viewer/environment_background.h"
#include "vocabulary/camera_projection.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"

#ifndef PRT_DATA_DIR
#define PRT_DATA_DIR "data"
#endif

namespace {

struct Run {
  prt::ImageSamplesInfo image;
  std::vector<prt::Rgb> weight;
  std::vector<float> share;
  std::string path;
  double rows_seconds = 0;
};

Run OpenRun(const std::string& path) {
  using namespace prt;
  Run r;
  r.path = path;
  const SceneGeometry g = ReadSceneGeometryFile(path + "/" + kGeometryFileName);
  r.image =
      ReadImageSamplesFile(path + "/" + kImageFileName, static_cast<uint32_t>(g.meshes.size()));
  std::vector<Rgb> albedo;
  for (const SceneMesh& m : g.meshes) albedo.push_back(m.albedo);
  r.weight = PixelAlbedo(r.image, albedo);
  r.share = PixelEnvironmentShare(r.image);
  const nlohmann::json rep = nlohmann::json::parse(ReadWholeFile(path + "/report.json"));
  for (const auto& p : rep["phases"])
    if (p["name"] == "brute" || p["name"] == "sparse")
      r.rows_seconds += p["wall_seconds"].get<double>();
  return r;
}

// B of every pixel (3 per pixel) under `light` and the environment `env`.
std::vector<double> Relit(const Run& run, const prt::CubemapRgb& light,
                          const prt::EnvironmentLookup& env) {
  using namespace prt;
  const TransportFileReader r(run.path + "/transport.prtt");
  const std::size_t cols = r.info().cols(), rows = r.info().rows;
  const std::size_t step = r.info().rows_per_block;
  std::vector<float> block(step * cols);
  std::vector<double> out(3 * rows);
  const Camera& cam = run.image.camera;
  const CameraProjection proj(cam);
  for (std::size_t first = 0; first < rows; first += step) {
    const std::size_t count = std::min(step, rows - first);
    r.ReadRows(first, count, block.data());
    for (std::size_t i = 0; i < count; ++i) {
      const std::size_t p = first + i;
      const float* row = block.data() + i * cols;
      const Rgb e = run.share[p] > 0
                        ? env.Radiance(proj.PixelDirection(
                              static_cast<double>(p % static_cast<std::size_t>(cam.width)) + 0.5,
                              static_cast<double>(p / static_cast<std::size_t>(cam.width)) + 0.5))
                        : Rgb{0.f, 0.f, 0.f};
      for (int c = 0; c < 3; ++c) {
        double b = 0;
        for (std::size_t j = 0; j < cols; ++j) b += row[j] * light.Channel(c)[j];
        out[3 * p + c] = run.weight[p][c] * b + run.share[p] * e[c];
      }
    }
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace prt;
  std::vector<std::string> envs = {std::string(PRT_DATA_DIR) + "/envmaps/sunrise.exr",
                                   std::string(PRT_DATA_DIR) + "/envmaps/city.exr"};
  std::string reference;
  std::vector<std::string> runs;
  CLI::App app{"supersample_bench: edge and interior error of supersampled image runs"};
  app.add_option("--env", envs, "environment maps (lat-long)");
  app.add_option("--reference", reference, "the reference run (k = 16)")->required();
  app.add_option("runs", runs, "image runs of the same scene and camera")->required();
  std::string dump;
  app.add_option("--dump", dump,
                 "write each run's relit image under the first map as PREFIX<i>.f32 (3 float32 per "
                 "pixel, raster order; i = 0 the reference, then the runs in order)");
  CLI11_PARSE(app, argc, argv);
  try {
    const Run ref = OpenRun(reference);
    const int w = ref.image.camera.width, h = ref.image.camera.height;
    // Edge pixels: the reference's 3×3 neighbourhood sees more than one mesh (or background).
    std::vector<uint8_t> edge(ref.image.pixels(), 0);
    std::size_t edges = 0, interior = 0;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t p = static_cast<std::size_t>(y) * w + x;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int u = x + dx, v = y + dy;
            if (u >= 0 && v >= 0 && u < w && v < h &&
                ref.image.pixel_mesh[static_cast<std::size_t>(v) * w + u] !=
                    ref.image.pixel_mesh[p])
              edge[p] = 1;
          }
        if (edge[p])
          ++edges;
        else if (ref.image.pixel_mesh[p] != kImageBackground)
          ++interior;
      }
    std::vector<Run> rs;
    for (const std::string& r : runs) {
      rs.push_back(OpenRun(r));
      if (rs.back().image.pixels() != ref.image.pixels()) {
        std::fprintf(stderr, "%s is not the reference's image size\n", r.c_str());
        return 1;
      }
    }
    std::printf(
        "edge pixels %zu, interior surface pixels %zu (of %d×%d); reference k = %d, rows "
        "%.1f s\n",
        edges, interior, w, h, ref.image.supersample, ref.rows_seconds);
    std::printf("%-12s %4s %10s %12s %14s %16s\n", "map", "k", "rows [s]", "edge RMS",
                "interior RMS", "interior ratio");
    for (const std::string& path : envs) {
      const EnvironmentImage image = ReadEnvironment(path);
      const TransportFileReader probe(reference + "/transport.prtt");
      const CubemapRgb light = ResampleToCubemap(image, static_cast<int>(probe.info().cubemap_n));
      const EnvironmentLookup env(image, path);
      const std::vector<double> b_ref = Relit(ref, light, env);
      const std::string name = path.substr(path.find_last_of('/') + 1);
      auto write = [&](const std::vector<double>& b, std::size_t i) {
        if (dump.empty() || path != envs.front()) return;
        std::vector<float> f(b.begin(), b.end());
        std::FILE* out = std::fopen((dump + std::to_string(i) + ".f32").c_str(), "wb");
        if (out == nullptr) throw std::runtime_error("cannot write " + dump);
        std::fwrite(f.data(), sizeof(float), f.size(), out);
        std::fclose(out);
      };
      write(b_ref, 0);
      std::size_t index = 0;
      for (const Run& r : rs) {
        const std::vector<double> b = Relit(r, light, env);
        write(b, ++index);
        double en = 0, ed = 0, in = 0, id = 0, is = 0, irs = 0;
        for (std::size_t p = 0; p < edge.size(); ++p) {
          const bool is_edge = edge[p] != 0;
          if (!is_edge && ref.image.pixel_mesh[p] == kImageBackground) continue;
          for (int c = 0; c < 3; ++c) {
            const double d = b[3 * p + c] - b_ref[3 * p + c];
            (is_edge ? en : in) += d * d;
            (is_edge ? ed : id) += b_ref[3 * p + c] * b_ref[3 * p + c];
            if (!is_edge) {
              is += b[3 * p + c];
              irs += b_ref[3 * p + c];
            }
          }
        }
        // interior ratio: Σ B / Σ B_ref over the interior pixels (a bias).
        std::printf("%-12s %4d %10.1f %11.2f%% %13.2f%% %16.4f\n", name.c_str(),
                    r.image.supersample, r.rows_seconds, ed > 0 ? 100 * std::sqrt(en / ed) : 0.0,
                    id > 0 ? 100 * std::sqrt(in / id) : 0.0, irs > 0 ? is / irs : 0.0);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "supersample_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
