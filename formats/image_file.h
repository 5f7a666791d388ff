// run/image.prti (docs/transport-format.md, "image.prti"): an image-relighting run's pixels — the
// camera, the image size and, per pixel, the mesh it sees (its material) or background. The rows
// of T are the pixels in raster order (row-major from the top-left), so this is what turns rows
// back into an image; prt-pack copies it into the pack's IMGE section (docs/prtpack-format.md).
// Little-endian, XXH64 at the end; the parser is safe on untrusted input.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "vocabulary/scene.h"

namespace prt {

// pixel_mesh value of a pixel that sees the environment (worker/camera_samples.h).
inline constexpr uint32_t kImageBackground = 0xFFFFFFFFu;
// Largest image side and pixel count a reader accepts (a 16k × 16k image).
inline constexpr uint32_t kMaxImageSide = 16384;

struct ImageSamplesInfo {
  Camera camera;                     // width and height are the image's
  std::vector<uint32_t> pixel_mesh;  // width·height, mesh index or kImageBackground
  std::size_t pixels() const { return static_cast<std::size_t>(camera.width) * camera.height; }
};

std::string SerializeImageSamples(const ImageSamplesInfo& info);
// Throws InputError naming `name` on a bad magic, checksum, size, non-finite camera, or a pixel
// naming a mesh ≥ mesh_count.
ImageSamplesInfo ParseImageSamples(std::string_view bytes, const std::string& name,
                                   uint32_t mesh_count);
void WriteImageSamplesFile(const std::string& path, const ImageSamplesInfo& info);
ImageSamplesInfo ReadImageSamplesFile(const std::string& path, uint32_t mesh_count);

}  // namespace prt
