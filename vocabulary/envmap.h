// Environment maps as images: lat-long and cube layouts, their pixel cells and directions
// (OpenEXR's ImfEnvmap.h exactly; docs/conventions.md writes the mappings, the pixel cells and
// the units down), and the lighting vector's cubemap type. Reading and writing them:
// environment_io.h; resampling to the lighting vector: cubemap_resample.h; a procedural sky:
// sky.h.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

enum class EnvmapLayout {
  kLatLong,  // OpenEXR ENVMAP_LATLONG: width × height, usually 2:1, top row = +Y (zenith)
  kCube,  // OpenEXR ENVMAP_CUBE: faces +X −X +Y −Y +Z −Z stacked vertically, width × 6·width
};

// An environment image in OpenEXR's envmap layout: planar linear float RGB, row-major from the
// top row, pixel (x, y) at index y·width + x. Radiance in the file's units (W·sr⁻¹·m⁻² or any
// consistent relative unit); prtfarm never rescales it.
struct EnvironmentImage {
  EnvmapLayout layout = EnvmapLayout::kLatLong;
  int width = 0;
  int height = 0;
  std::vector<float> r, g, b;

  std::size_t PixelCount() const { return static_cast<std::size_t>(width) * height; }
  std::size_t Index(int x, int y) const { return static_cast<std::size_t>(y) * width + x; }
  const std::vector<float>& Channel(int c) const { return c == 0 ? r : (c == 1 ? g : b); }
  std::vector<float>& Channel(int c) { return c == 0 ? r : (c == 1 ? g : b); }
  // Allocates width·height zero pixels.
  static EnvironmentImage Zero(EnvmapLayout layout, int width, int height);
};

// What a reader found besides the pixels.
struct EnvironmentLoadInfo {
  bool layout_from_attribute = false;  // false: inferred from the aspect ratio (logged)
  std::size_t negatives_clamped = 0;   // pixel channels < 0 set to 0 (logged as a warning)
  double most_negative = 0;            // the smallest value clamped (≤ 0)
};

// ---- Directions (OpenEXR ImfEnvmap.h, in double precision) ----

// Imf::LatLongMap::direction for a w × h map with data window (0,0)–(w−1,h−1): pixel position
// (px, py) → latitude θ = π(½ − py/(h−1)), longitude φ = −2π(px/(w−1) − ½),
// direction (sin φ cos θ, sin θ, cos φ cos θ). Unit length.
Vec3 LatLongDirection(int width, int height, double px, double py);
// Imf::LatLongMap::pixelPosition(dataWindow, direction): the inverse of LatLongDirection.
void LatLongPixelPosition(int width, int height, const Vec3& d, double& px, double& py);
// Imf::CubeMap: the direction (unnormalised point on the unit cube, as CubeMap::direction) of
// pixel (px, py) of a cube map image with faces of s × s pixels (image s × 6s).
Vec3 CubeImageDirection(int face_size, double px, double py);
// Imf::CubeMap::faceAndPixelPosition followed by CubeMap::pixelPosition: image pixel position.
void CubeImagePixelPosition(int face_size, const Vec3& d, double& px, double& py);

// Rotation of a direction by `angle` radians about +Y, right-handed (+Z turns towards +X): the
// longitude atan2(x, z) grows by angle. Rotating an environment by angle means L'(d) = L(R⁻¹d).
Vec3 RotateAboutY(const Vec3& d, double angle);

// Solid angle of the pixel's cell. OpenEXR's maps put pixel CENTRES on the poles and on both
// ends of the longitude range (and, for cubes, on the face edges), so a pixel's cell reaches half
// way to its neighbours and is clipped there: first/last rows and columns are half cells.
// The cells tile the sphere exactly (they sum to 4π).
double PixelSolidAngle(const EnvironmentImage& image, int x, int y);
// Σ radiance × cell solid angle over the image, per channel (double).
std::array<double, 3> EnvironmentPower(const EnvironmentImage& image);

// ---- Pixel cells (docs/conventions.md) ----
// OpenEXR places pixel centres on the poles, on both ends of the longitude range and on cube
// face edges. A pixel's cell reaches half way to its neighbours, clipped at those ends.

struct PixelInterval {
  double lo, hi;
};
// Latitude interval of lat-long row y of h (θ grows upwards; row 0 is the north pole).
PixelInterval LatLongRowCell(int h, int y);
// Longitude interval of lat-long column x of w (φ decreases with x from π to −π).
PixelInterval LatLongColumnCell(int w, int x);
// Cube image pixel → face and integer position in face (Imf::CubeMap::pixelPosition inverted).
void CubePixelToFace(int s, int px, int py, int& face, int& pifx, int& pify);
// Face-coordinate interval (u or v ∈ [−1, 1]) of integer position i on a face of s pixels.
PixelInterval CubeCell(int s, int i);

// Throws InputError(path) unless a w × h image is a valid `layout` map of at most 2^28 pixels.
void ValidateEnvironmentShape(const std::string& path, EnvmapLayout layout, std::int64_t w,
                              std::int64_t h);

// ---- The lighting vector ----

// Average radiance over each texel of a cubemap (vocabulary/cubemap.h layout: texel index =
// face·n² + y·n + x, OpenEXR face order), three planar channels of 6·n² floats.
struct CubemapRgb {
  int n = 0;
  std::vector<float> r, g, b;
  std::size_t TexelCount() const { return static_cast<std::size_t>(6) * n * n; }
  const std::vector<float>& Channel(int c) const { return c == 0 ? r : (c == 1 ? g : b); }
  std::vector<float>& Channel(int c) { return c == 0 ? r : (c == 1 ? g : b); }
};
// Σ texel average × exact texel solid angle, per channel (double).
std::array<double, 3> CubemapPower(const CubemapRgb& cube);

}  // namespace prt
