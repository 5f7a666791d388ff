#include "bench/bench_scenes.h"

#include <cmath>
#include <cstdlib>

#include "viewer/rasterizer.h"
#include "vocabulary/errors.h"

namespace prt::bench {

#ifndef PRT_SHARED_DATA_DIR
#define PRT_SHARED_DATA_DIR "../shared/data"
#endif

std::string DataDir() {
  if (const char* d = std::getenv("PRT_DATA_DIR"); d != nullptr && *d != '\0') return d;
  return PRT_DATA_DIR;
}

SceneDescription BenchScene(const std::string& name, int n) {
  std::string text = DefaultSceneText();
  auto replace = [&](const std::string& from, const std::string& to) {
    const auto pos = text.find(from);
    if (pos == std::string::npos) throw InputError("<bench scene>", "default scene lacks " + from);
    text.replace(pos, from.size(), to);
  };
  if (name == "armadillo") {
    replace("name = \"bunny\"\n", "name = \"armadillo\"\n");
    replace("meshes/bunny00.off", "meshes/armadillo.off");
  } else if (name == "dragon") {
    replace("name = \"bunny\"\n", "name = \"dragon\"\n");
    replace("meshes/bunny00.off", "meshes/ChineseDragon-10kv.off");
  } else if (name == "camel") {
    replace("name = \"bunny\"\n", "name = \"camel\"\n");
    replace("meshes/bunny00.off", "meshes/camel.off");
  } else if (name == "horse") {  // ../shared/data only; Z up, wound inward (mesh-import.md)
    replace("name = \"bunny\"\n", "name = \"horse\"\n");
    replace("meshes/bunny00.off", "meshes/horse_cyberware.ply");
    replace("up = \"+y\" }", "up = \"+z\" }\nflip_winding = true");
  } else if (name == "teapot") {  // ../shared/data only; Z up
    replace("name = \"bunny\"\n", "name = \"teapot\"\n");
    replace("meshes/bunny00.off", "meshes/utah_teapot_24x24.obj");
    replace("up = \"+y\" }", "up = \"+z\" }");
  } else if (name != "default" && name != "bunny") {
    throw InputError("<bench scene>", "unknown benchmark scene '" + name +
                                          "' (default, armadillo, dragon, camel, horse, teapot)");
  }
  SceneDescription scene =
      ParseScene(text, "<bench scene " + name + ">", "", {DataDir(), PRT_SHARED_DATA_DIR});
  if (n > 0) scene.cubemap_n = n;
  return scene;
}

std::vector<NamedEnvironment> BenchEnvironments(int n, const std::vector<std::string>& names) {
  std::vector<NamedEnvironment> out;
  for (const std::string& e : names) {
    const EnvironmentImage img = ReadEnvironment(DataDir() + "/envmaps/" + e + ".exr");
    out.push_back({e, ResampleToCubemap(img, n)});
  }
  return out;
}

std::vector<float> RelitRadiance(const SceneGeometry& geometry, const std::vector<float>& rows,
                                 const CubemapRgb& light) {
  const std::size_t T = light.TexelCount();
  const std::size_t N = rows.size() / T;
  std::vector<float> out(N * 3);
  std::size_t s = 0;
  for (const SceneMesh& m : geometry.meshes) {
    for (std::size_t v = 0; v < m.mesh.positions.size() && s < N; ++v, ++s) {
      const float* row = rows.data() + s * T;
      double acc[3] = {0, 0, 0};
      for (std::size_t j = 0; j < T; ++j) {
        acc[0] += static_cast<double>(row[j]) * light.r[j];
        acc[1] += static_cast<double>(row[j]) * light.g[j];
        acc[2] += static_cast<double>(row[j]) * light.b[j];
      }
      for (int c = 0; c < 3; ++c) out[s * 3 + c] = static_cast<float>(m.albedo[c] * acc[c]);
    }
  }
  return out;
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

}  // namespace prt::bench
