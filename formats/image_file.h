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
  std::size_t pixels() const { return static_cast<std::size_t>(camera.width) * camera.height; }
  std::size_t background_pixels() const { return BackgroundPixels(pixel_mesh); }
};

// Each pixel's albedo: its mesh's (mesh_albedo[m]), 0 for background. The caller has checked the
// indices (ParseImageSamples does).
inline std::vector<Rgb> PixelAlbedo(const ImageSamplesInfo& info,
                                    std::span<const Rgb> mesh_albedo) {
  std::vector<Rgb> out;
  out.reserve(info.pixel_mesh.size());
  for (uint32_t m : info.pixel_mesh)
    out.push_back(m == kImageBackground ? Rgb{0.f, 0.f, 0.f} : mesh_albedo[m]);
  return out;
}

std::string SerializeImageSamples(const ImageSamplesInfo& info);
// Throws InputError naming `name` on a bad magic, checksum, size, non-finite camera, or a pixel
// naming a mesh ≥ mesh_count.
ImageSamplesInfo ParseImageSamples(std::string_view bytes, const std::string& name,
                                   uint32_t mesh_count);
void WriteImageSamplesFile(const std::string& path, const ImageSamplesInfo& info);
ImageSamplesInfo ReadImageSamplesFile(const std::string& path, uint32_t mesh_count);

}  // namespace prt
