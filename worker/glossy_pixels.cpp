// Glossy pixels of image relighting (worker/glossy_pixels.h).
#include "worker/glossy_pixels.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <type_traits>

#include "formats/image_file.h"
#include "vocabulary/errors.h"

namespace prt {

bool GlossyPixels::any() const {
  return std::find(glossy.begin(), glossy.end(), uint8_t{1}) != glossy.end();
}

GlossyPixels ResolveGlossyPixels(const SceneDescription& scene, const SceneGeometry& geometry) {
  if (scene.samples != SpatialSamples::kCameraPixels) {
    GlossyPixels out;
    for (const SceneMesh& sm : geometry.meshes) {
      out.materials.emplace_back();
      out.glossy.push_back(0);
      out.weight.push_back(sm.albedo);
    }
    return out;
  }
  return ResolveGlossyMaterials(scene, geometry);
}

GlossyPixels ResolveGlossyMaterials(const SceneDescription& scene, const SceneGeometry& geometry) {
  GlossyPixels out;
  const std::size_t count = geometry.meshes.size();
  out.materials.resize(count);
  out.glossy.assign(count, 0);
  out.weight.resize(count);
  for (std::size_t i = 0; i < count; ++i) {
    const SceneMesh& sm = geometry.meshes[i];
    out.weight[i] = sm.albedo;
    const GlossyMaterialSettings* g = nullptr;
    std::string what;
    if (sm.is_ground) {
      g = &scene.ground.glossy;
      what = "[ground]";
    } else if (i < scene.meshes.size()) {
      g = &scene.meshes[i].glossy;
      what = "[[mesh]] '" + scene.meshes[i].name + "' (line " +
             std::to_string(scene.meshes[i].line) + ")";
    }
    if (g == nullptr) continue;
    Material m;
    try {
      m = MaterialOfSettings(*g, sm.albedo);
    } catch (const std::invalid_argument& e) {
      throw InputError(scene.file, what + ": " + e.what());
    }
    if (!HasSpecular(m)) continue;
    // albedo = k_d·w, specular = k_s·w with w = albedo + specular (> 0 where either is).
    Rgb w{};
    double kd = -1;
    bool proportional = true;
    for (int c = 0; c < 3; ++c) {
      w[c] = m.diffuse[c] + m.specular[c];
      if (!(w[c] > 0)) continue;
      const double k = m.diffuse[c] / static_cast<double>(w[c]);
      if (kd < 0) kd = k;
      if (std::abs(k - kd) > 1e-4) proportional = false;
    }
    if (!proportional)
      throw InputError(
          scene.file,
          what +
              ": a glossy mesh needs `specular` proportional to `albedo` (both grey, or the "
              "same hue): one row per pixel (per vertex and term) carries both lobes and one "
              "colour. A lobe coloured unlike the diffuse part needs a row per colour channel "
              "(3× the rows, the farm's time and the pack's bytes), which prtfarm does not "
              "build: make `specular` proportional to `albedo`, or set brdf = \"lambert\" for "
              "a diffuse mesh");
    const double ks = 1.0 - kd;
    m.diffuse = {static_cast<float>(kd), static_cast<float>(kd), static_cast<float>(kd)};
    m.specular = {static_cast<float>(ks), static_cast<float>(ks), static_cast<float>(ks)};
    out.materials[i] = m;
    out.glossy[i] = 1;
    out.weight[i] = w;
  }
  return out;
}

std::vector<Rgb> BounceAlbedo(const GlossyPixels& glossy, const SceneGeometry& geometry) {
  std::vector<Rgb> out;
  for (std::size_t m = 0; m < geometry.meshes.size(); ++m) {
    Rgb a = geometry.meshes[m].albedo;
    if (m < glossy.glossy.size() && glossy.glossy[m]) {
      const Material& mat = glossy.materials[m];
      const double r = mat.diffuse[0] + mat.specular[0] * LobeReflectance(mat);
      for (int c = 0; c < 3; ++c) a[c] = static_cast<float>(glossy.weight[m][c] * r);
    }
    out.push_back(a);
  }
  return out;
}

void MarkGlossyPixels(const GlossyPixels& glossy, std::span<const uint32_t> pixel_mesh,
                      std::vector<SpatialSample>& samples) {
  for (std::size_t p = 0; p < pixel_mesh.size() && p < samples.size(); ++p) {
    const uint32_t m = pixel_mesh[p];
    if (m != kImageBackground && m < glossy.glossy.size() && glossy.glossy[m])
      samples[p].glossy_material = m;
  }
}

static_assert(std::is_trivially_copyable_v<Material> && std::is_trivially_copyable_v<Rgb>);

std::string SerializeGlossyPixels(const GlossyPixels& glossy) {
  const uint64_t n = glossy.materials.size();
  std::string out(sizeof n + n * (sizeof(Material) + 1 + sizeof(Rgb)), '\0');
  char* p = out.data();
  std::memcpy(p, &n, sizeof n);
  p += sizeof n;
  std::memcpy(p, glossy.materials.data(), n * sizeof(Material));
  p += n * sizeof(Material);
  std::memcpy(p, glossy.glossy.data(), n);
  p += n;
  std::memcpy(p, glossy.weight.data(), n * sizeof(Rgb));
  return out;
}

GlossyPixels ParseGlossyPixels(const std::string& bytes) {
  uint64_t n = 0;
  if (bytes.size() < sizeof n) throw std::runtime_error("glossy pixels: truncated");
  std::memcpy(&n, bytes.data(), sizeof n);
  if (bytes.size() != sizeof n + n * (sizeof(Material) + 1 + sizeof(Rgb)))
    throw std::runtime_error("glossy pixels: size does not fit");
  GlossyPixels g;
  g.materials.resize(n);
  g.glossy.resize(n);
  g.weight.resize(n);
  const char* p = bytes.data() + sizeof n;
  std::memcpy(g.materials.data(), p, n * sizeof(Material));
  p += n * sizeof(Material);
  std::memcpy(g.glossy.data(), p, n);
  p += n;
  std::memcpy(g.weight.data(), p, n * sizeof(Rgb));
  return g;
}

}  // namespace prt
