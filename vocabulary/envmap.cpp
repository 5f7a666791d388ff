// Environment images: layouts, pixel cells, directions (OpenEXR ImfEnvmap.h) and power; see
// envmap.h and docs/conventions.md.
#include "vocabulary/envmap.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>

#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

constexpr double kPi = std::numbers::pi;
// Largest image a reader accepts (pixels): 2^28 ≈ 16k × 16k, 3 GiB of float RGB.
constexpr std::int64_t kMaxPixels = std::int64_t{1} << 28;

}  // namespace

// ---- Shape validation ----

void ValidateEnvironmentShape(const std::string& path, EnvmapLayout layout, std::int64_t w,
                              std::int64_t h) {
  if (w <= 0 || h <= 0 || w > (1 << 20) || h > (1 << 20) || w * h > kMaxPixels) {
    throw InputError(path, "image size " + std::to_string(w) + "x" + std::to_string(h) +
                               " is empty or too large");
  }
  if (layout == EnvmapLayout::kLatLong && (w < 2 || h < 2)) {
    throw InputError(path, "a lat-long map needs at least 2x2 pixels, got " + std::to_string(w) +
                               "x" + std::to_string(h));
  }
  if (layout == EnvmapLayout::kCube && h != 6 * w) {
    throw InputError(path, "a cube map must be w x 6w (faces +X -X +Y -Y +Z -Z stacked), got " +
                               std::to_string(w) + "x" + std::to_string(h));
  }
}

// ---- Pixel cells ----
// OpenEXR places pixel centres on the poles, on both ends of the longitude range and on cube
// face edges. A pixel's cell reaches half way to its neighbours, clipped at those ends; see
// docs/conventions.md.

// Latitude interval of lat-long row y (θ grows upwards; row 0 is the north pole).
PixelInterval LatLongRowCell(int h, int y) {
  const double d = kPi / (h - 1);
  const double c = kPi * (0.5 - static_cast<double>(y) / (h - 1));
  return {std::max(-kPi / 2, c - d / 2), std::min(kPi / 2, c + d / 2)};
}
// Longitude interval of lat-long column x (φ decreases with x from π to −π).
PixelInterval LatLongColumnCell(int w, int x) {
  const double d = 2 * kPi / (w - 1);
  const double c = kPi - 2 * kPi * static_cast<double>(x) / (w - 1);
  return {std::max(-kPi, c - d / 2), std::min(kPi, c + d / 2)};
}

// Cube image pixel → face and integer position in face (Imf::CubeMap::pixelPosition inverted).
void CubePixelToFace(int s, int px, int py, int& face, int& pifx, int& pify) {
  face = py / s;
  const int ly = py - face * s;  // row inside the face's block
  switch (face) {
    case 0:
      pifx = s - 1 - ly;
      pify = px;
      break;
    case 1:
      pifx = s - 1 - ly;
      pify = s - 1 - px;
      break;
    case 2:
      pifx = px;
      pify = s - 1 - ly;
      break;
    case 3:
      pifx = px;
      pify = ly;
      break;
    case 4:
      pifx = s - 1 - px;
      pify = s - 1 - ly;
      break;
    default:
      pifx = px;
      pify = s - 1 - ly;
      break;
  }
}
// Face-coordinate interval (u or v ∈ [−1, 1]) of integer position i on a face of s pixels.
PixelInterval CubeCell(int s, int i) {
  if (s == 1) return {-1.0, 1.0};
  const double k = 2.0 / (s - 1);
  return {std::max(-1.0, -1 + k * (i - 0.5)), std::min(1.0, -1 + k * (i + 0.5))};
}

EnvironmentImage EnvironmentImage::Zero(EnvmapLayout layout, int width, int height) {
  EnvironmentImage img;
  img.layout = layout;
  img.width = width;
  img.height = height;
  for (int c = 0; c < 3; ++c) img.Channel(c).assign(img.PixelCount(), 0.0f);
  return img;
}

// ---- Directions ----

Vec3 LatLongDirection(int width, int height, double px, double py) {
  const double lat = height > 1 ? -kPi * (py / (height - 1) - 0.5) : 0.0;
  const double lon = width > 1 ? -2 * kPi * (px / (width - 1) - 0.5) : 0.0;
  return {std::sin(lon) * std::cos(lat), std::sin(lat), std::cos(lon) * std::cos(lat)};
}

void LatLongPixelPosition(int width, int height, const Vec3& d, double& px, double& py) {
  const double r = std::sqrt(d.z * d.z + d.x * d.x);
  const double lat = std::atan2(d.y, r);
  const double lon = (d.z == 0 && d.x == 0) ? 0.0 : std::atan2(d.x, d.z);
  px = (lon / (-2 * kPi) + 0.5) * (width - 1);
  py = (lat / -kPi + 0.5) * (height - 1);
}

Vec3 CubeImageDirection(int face_size, double px, double py) {
  const int s = face_size;
  const int face = std::clamp(static_cast<int>(std::floor(py / s)), 0, 5);
  const double ly = py - face * s, m = s - 1;
  double x = 0, y = 0;
  switch (face) {
    case 0:
      x = m - ly;
      y = px;
      break;
    case 1:
      x = m - ly;
      y = m - px;
      break;
    case 2:
      x = px;
      y = m - ly;
      break;
    case 3:
      x = px;
      y = ly;
      break;
    case 4:
      x = m - px;
      y = m - ly;
      break;
    default:
      x = px;
      y = m - ly;
      break;
  }
  const double u = s > 1 ? x / m * 2 - 1 : 0.0, v = s > 1 ? y / m * 2 - 1 : 0.0;
  return CubemapLayout::FacePoint(face, u, v);
}

void CubeImagePixelPosition(int face_size, const Vec3& d, double& px, double& py) {
  const int s = face_size;
  int face;
  double u, v;
  CubemapLayout::DirectionToFace(d, face, u, v);
  const double m = s - 1, x = (u + 1) / 2 * m, y = (v + 1) / 2 * m;
  const double y0 = face * s, y1 = face * s + m;
  switch (face) {
    case 0:
      px = y;
      py = y1 - x;
      break;
    case 1:
      px = m - y;
      py = y1 - x;
      break;
    case 2:
      px = x;
      py = y1 - y;
      break;
    case 3:
      px = x;
      py = y0 + y;
      break;
    case 4:
      px = m - x;
      py = y1 - y;
      break;
    default:
      px = x;
      py = y1 - y;
      break;
  }
}

Vec3 RotateAboutY(const Vec3& d, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * d.x + s * d.z, d.y, -s * d.x + c * d.z};
}

double PixelSolidAngle(const EnvironmentImage& image, int x, int y) {
  if (image.layout == EnvmapLayout::kLatLong) {
    const PixelInterval ph = LatLongColumnCell(image.width, x);
    const PixelInterval th = LatLongRowCell(image.height, y);
    return (ph.hi - ph.lo) * (std::sin(th.hi) - std::sin(th.lo));
  }
  int face, i, j;
  CubePixelToFace(image.width, x, y, face, i, j);
  const PixelInterval cu = CubeCell(image.width, i), cv = CubeCell(image.width, j);
  return FaceRectSolidAngle(cu.lo, cu.hi, cv.lo, cv.hi);
}

std::array<double, 3> EnvironmentPower(const EnvironmentImage& image) {
  std::array<double, 3> p{0, 0, 0};
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const double w = PixelSolidAngle(image, x, y);
      for (int c = 0; c < 3; ++c) p[c] += w * image.Channel(c)[image.Index(x, y)];
    }
  }
  return p;
}

std::array<double, 3> CubemapPower(const CubemapRgb& cube) {
  const CubemapLayout layout(cube.n);
  std::array<double, 3> p{0, 0, 0};
  for (std::size_t t = 0; t < layout.texel_count(); ++t) {
    const double w = layout.TexelSolidAngle(t);
    for (int c = 0; c < 3; ++c) p[c] += w * cube.Channel(c)[t];
  }
  return p;
}

}  // namespace prt
