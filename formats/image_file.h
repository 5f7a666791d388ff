// run/image.prti (docs/transport-format.md, "image.prti"): an image-relighting run's pixels — the
// camera, the image size and, per pixel, the mesh it sees (its material) or background. The rows
// of T are the pixels in raster order (row-major from the top-left), so this is what turns rows
// back into an image; prt-pack copies it into the pack's IMGE section (docs/prtpack-format.md).
// Little-endian, XXH64 at the end; the parser is safe on untrusted input.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/scene.h"

namespace prt {

// pixel_mesh value of a pixel that sees the environment (worker/camera_samples.h).
inline constexpr uint32_t kImageBackground = 0xFFFFFFFFu;
// Largest image side and pixel count a reader accepts (a 16k × 16k image).
inline constexpr uint32_t kMaxImageSide = 16384;

// How many of `pixel_mesh` are kImageBackground.
inline std::size_t BackgroundPixels(std::span<const uint32_t> pixel_mesh) {
  return static_cast<std::size_t>(
      std::count(pixel_mesh.begin(), pixel_mesh.end(), kImageBackground));
}

struct ImageSamplesInfo {
  Camera camera;                     // width and height are the image's
  std::vector<uint32_t> pixel_mesh;  // width·height, mesh index or kImageBackground
  // Glossy pixels (PRTIMG02; docs/image-relighting.md, "Glossy pixels"), one entry per mesh, or
  // both empty (PRTIMG01: every pixel diffuse). glossy_mesh[m] = 1: the rows of the pixels that
  // see mesh m hold its whole BRDF (diffuse and specular, the view from the camera), and their
  // relit radiance is glossy_weight[m] ⊙ (T·L) instead of albedo ⊙ (T·L).
  std::vector<uint8_t> glossy_mesh{};
  std::vector<Rgb> glossy_weight{};
  // Supersampled pixels (PRTIMG03; docs/image-relighting.md, "Supersampling"): k = supersample
  // > 1, and per pixel its coverage (the fraction of its k² rays that hit a surface) and its
  // weight w_c(p) = (1/k²) Σ_s a_c(s); both empty when supersample is 1. A pixel's relit
  // radiance is w_c(p)·(T·L)_c + (1 − coverage)·E_c, E the environment along its ray.
  int supersample = 1;
  std::vector<float> coverage{};
  std::vector<Rgb> pixel_weight{};
  std::size_t pixels() const { return static_cast<std::size_t>(camera.width) * camera.height; }
  std::size_t background_pixels() const { return BackgroundPixels(pixel_mesh); }
  bool has_glossy_pixels() const {
    return std::find(glossy_mesh.begin(), glossy_mesh.end(), uint8_t{1}) != glossy_mesh.end();
  }
};

// Each pixel's weight of T·L: its mesh's albedo (mesh_albedo[m]), or its glossy_weight for a
// glossy mesh; 0 for background; a supersampled image's own per-pixel weight. The caller has
// checked the indices (ParseImageSamples does).
inline std::vector<Rgb> PixelAlbedo(const ImageSamplesInfo& info,
                                    std::span<const Rgb> mesh_albedo) {
  if (info.supersample > 1 && info.pixel_weight.size() == info.pixel_mesh.size())
    return info.pixel_weight;
  std::vector<Rgb> out;
  out.reserve(info.pixel_mesh.size());
  for (uint32_t m : info.pixel_mesh) {
    if (m == kImageBackground)
      out.push_back(Rgb{0.f, 0.f, 0.f});
    else if (m < info.glossy_mesh.size() && info.glossy_mesh[m])
      out.push_back(info.glossy_weight[m]);
    else
      out.push_back(mesh_albedo[m]);
  }
  return out;
}

// Each pixel's share of the environment seen along its ray: 1 − coverage for a supersampled
// image, else 1 for background and 0 for surface pixels.
inline std::vector<float> PixelEnvironmentShare(const ImageSamplesInfo& info) {
  std::vector<float> out(info.pixel_mesh.size());
  const bool ss = info.supersample > 1 && info.coverage.size() == info.pixel_mesh.size();
  for (std::size_t p = 0; p < out.size(); ++p)
    out[p] = ss ? 1.0f - info.coverage[p] : (info.pixel_mesh[p] == kImageBackground ? 1.f : 0.f);
  return out;
}

// PRTIMG03 when supersample > 1 (the mesh table, possibly all diffuse, then k, coverage and
// weights); else PRTIMG01 when no mesh is glossy (glossy_mesh all 0 or empty: the bytes of before
// glossy pixels), else PRTIMG02 with the per-mesh table.
std::string SerializeImageSamples(const ImageSamplesInfo& info);
// Throws InputError naming `name` on a bad magic, checksum, size, non-finite camera, a pixel
// naming a mesh ≥ mesh_count, or (PRTIMG02) a mesh table whose size is not mesh_count or whose
// flags are not 0/1 or weights outside [0, 1]; (PRTIMG03) k outside 2…16, a coverage outside
// [0, 1] or 0 on a surface pixel / non-zero on a background one, a pixel weight not finite or
// outside [0, 1].
ImageSamplesInfo ParseImageSamples(std::string_view bytes, const std::string& name,
                                   uint32_t mesh_count);
void WriteImageSamplesFile(const std::string& path, const ImageSamplesInfo& info);
ImageSamplesInfo ReadImageSamplesFile(const std::string& path, uint32_t mesh_count);

}  // namespace prt
