#include "bench/bench_scenes.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <sstream>

#include "viewer/rasterizer.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt::bench {

std::vector<NamedEnvironment> BenchEnvironments(int n, const std::vector<std::string>& names) {
  std::vector<NamedEnvironment> out;
  for (const std::string& e : names) {
    const EnvironmentImage img = ReadEnvironment(DataDir() + "/envmaps/" + e + ".exr");
    out.push_back({e, ResampleToCubemap(img, n)});
  }
  return out;
}

std::vector<float> RelitRadiance(std::span<const Rgb> albedo, const std::vector<float>& rows,
                                 const CubemapRgb& light) {
  const std::size_t T = light.TexelCount();
  const std::size_t N = rows.size() / T;
  std::vector<float> out(N * 3);
  for (std::size_t s = 0; s < N && s < albedo.size(); ++s) {
    const float* row = rows.data() + s * T;
    double acc[3] = {0, 0, 0};
    for (std::size_t j = 0; j < T; ++j) {
      acc[0] += static_cast<double>(row[j]) * light.r[j];
      acc[1] += static_cast<double>(row[j]) * light.g[j];
      acc[2] += static_cast<double>(row[j]) * light.b[j];
    }
    for (int c = 0; c < 3; ++c) out[s * 3 + c] = static_cast<float>(albedo[s][c] * acc[c]);
  }
  return out;
}

std::vector<float> RelitRadiance(const SceneGeometry& geometry, const std::vector<float>& rows,
                                 const CubemapRgb& light) {
  std::vector<Rgb> albedo;  // the meshes' vertices in order
  for (const SceneMesh& m : geometry.meshes)
    albedo.insert(albedo.end(), m.mesh.positions.size(), m.albedo);
  return RelitRadiance(albedo, rows, light);
}

double RelativeRmsError(const std::vector<float>& b, const std::vector<float>& ref,
                        std::size_t first, std::size_t last) {
  double num = 0, den = 0;
  for (std::size_t i = first * 3; i < last * 3; ++i) {
    const double d = static_cast<double>(b[i]) - ref[i];
    num += d * d;
    den += static_cast<double>(ref[i]) * ref[i];
  }
  return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

SampleRanges RangesOf(const SceneGeometry& geometry) {
  SampleRanges r;
  std::size_t s = 0;
  for (const SceneMesh& m : geometry.meshes) {
    if (m.is_ground) {
      r.ground_first = s;
      r.ground_last = s + m.mesh.positions.size();
    } else {
      r.model_last = s + m.mesh.positions.size();
    }
    s += m.mesh.positions.size();
  }
  return r;
}

ImageRgb RenderVertexColours(const SceneDescription& scene, const SceneGeometry& geometry,
                             const std::vector<float>& rgb, const CubemapRgb* background) {
  std::vector<Vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  for (const SceneMesh& m : geometry.meshes) {
    const auto base = static_cast<uint32_t>(positions.size());
    positions.insert(positions.end(), m.mesh.positions.begin(), m.mesh.positions.end());
    for (const auto& t : m.mesh.triangles)
      triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
  }
  RasterOptions opt;
  if (background != nullptr) opt.background = CubemapBackground(*background);
  const RasterImage r = RasterizeTriangles(scene.camera, positions, triangles, rgb, opt);
  ImageRgb img(r.width, r.height);
  img.pixels = r.rgb;
  return img;
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

double CpuSeconds() {
  return static_cast<double>(std::clock()) / CLOCKS_PER_SEC;
}

double DotRow(const float* a, const float* b, std::size_t n) {
  double s = 0;
  for (std::size_t i = 0; i < n; ++i) s += double(a[i]) * b[i];
  return s;
}

std::vector<uint64_t> PickVertices(uint64_t first, uint64_t last, std::size_t count,
                                   uint64_t seed) {
  std::vector<uint64_t> all;
  for (uint64_t v = first; v < last; ++v) all.push_back(v);
  for (std::size_t i = 0; i < all.size() && i < count; ++i) {
    const uint64_t j = i + SplitMix64(seed ^ (0x9E37ull * (i + 1))) % (all.size() - i);
    std::swap(all[i], all[j]);
  }
  all.resize(std::min(count, all.size()));
  std::sort(all.begin(), all.end());
  return all;
}

std::vector<float> DenseVertexColours(const std::vector<uint8_t>& is_dense,
                                      const std::vector<int>& local_rank) {
  int max_rank = 1;
  for (int r : local_rank) max_rank = std::max(max_rank, r);
  std::vector<float> colours(is_dense.size() * 3, 0.25f);
  for (std::size_t s = 0; s < is_dense.size(); ++s) {
    if (!is_dense[s]) continue;
    std::array<float, 3> c{1.0f, 1.0f, 1.0f};
    if (s < local_rank.size() && local_rank[s] >= 0)
      c = FalseColour(static_cast<double>(local_rank[s]) / max_rank);
    for (int k = 0; k < 3; ++k) colours[s * 3 + k] = c[k];
  }
  return colours;
}

}  // namespace prt::bench
