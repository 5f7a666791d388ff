// The environment image as a frame's background (see environment_background.h).
#include "viewer/environment_background.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"

namespace prt {

EnvironmentLookup::EnvironmentLookup(EnvironmentImage image, const std::string& name)
    : image_(std::move(image)) {
  ValidateEnvironmentShape(name, image_.layout, image_.width, image_.height);
  const char* const channel_name[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& v = image_.Channel(c);
    if (v.size() != image_.PixelCount())
      throw InputError(name, std::string("channel ") + channel_name[c] + " has " +
                                 std::to_string(v.size()) + " values for " +
                                 std::to_string(image_.width) + "×" +
                                 std::to_string(image_.height) + " pixels");
    for (std::size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i]))
        throw NumericalError(name + ": " + (std::isnan(v[i]) ? "NaN" : "Inf") + " at pixel (x=" +
                             std::to_string(i % static_cast<std::size_t>(image_.width)) +
                             ", y=" + std::to_string(i / static_cast<std::size_t>(image_.width)) +
                             ", channel " + channel_name[c] + ")");
  }
}

// Bilinear between the pixel centres around (px, py), the four pixels (x0, x0 + 1) × (y0, y0 + 1)
// with x0 ∈ [x_lo, x_hi − 1] and y0 ∈ [y_lo, y_hi − 1], so that the lookup stays inside that
// block (a cube face, or the whole lat-long image). A block one pixel wide or high uses its one
// column or row.
Rgb EnvironmentLookup::Bilinear(double px, double py, int x_lo, int x_hi, int y_lo,
                                int y_hi) const {
  px = std::clamp(px, static_cast<double>(x_lo), static_cast<double>(x_hi));
  py = std::clamp(py, static_cast<double>(y_lo), static_cast<double>(y_hi));
  const int x0 = std::min(static_cast<int>(std::floor(px)), std::max(x_lo, x_hi - 1));
  const int y0 = std::min(static_cast<int>(std::floor(py)), std::max(y_lo, y_hi - 1));
  const int x1 = std::min(x0 + 1, x_hi), y1 = std::min(y0 + 1, y_hi);
  const double fx = px - x0, fy = py - y0;
  const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  const std::size_t i00 = image_.Index(x0, y0), i10 = image_.Index(x1, y0),
                    i01 = image_.Index(x0, y1), i11 = image_.Index(x1, y1);
  Rgb out;
  for (int c = 0; c < 3; ++c) {
    const float* v = image_.Channel(c).data();
    // A convex combination of finite floats (checked at construction): finite, and within the
    // four values' range up to rounding, so the float it rounds to is finite too.
    out[static_cast<std::size_t>(c)] =
        static_cast<float>(w00 * v[i00] + w10 * v[i10] + w01 * v[i01] + w11 * v[i11]);
  }
  return out;
}

Rgb EnvironmentLookup::Radiance(const Vec3& d) const {
  const int w = image_.width, h = image_.height;
  double px = 0, py = 0;
  if (image_.layout == EnvmapLayout::kLatLong) {
    LatLongPixelPosition(w, h, d, px, py);
    return Bilinear(px, py, 0, w - 1, 0, h - 1);
  }
  int face = 0;
  double u = 0, v = 0;
  CubemapLayout::DirectionToFace(d, face, u, v);
  CubeImagePixelPosition(w, d, px, py);
  return Bilinear(px, py, 0, w - 1, face * w, face * w + w - 1);
}

BackgroundFunction EnvironmentBackground(std::shared_ptr<const EnvironmentLookup> lookup,
                                         double rotation_y) {
  if (lookup == nullptr) throw std::invalid_argument("EnvironmentBackground: no environment");
  if (!std::isfinite(rotation_y))
    throw std::invalid_argument("EnvironmentBackground: rotation must be finite");
  if (rotation_y == 0.0)
    return [lookup = std::move(lookup)](const Vec3& d) { return lookup->Radiance(d); };
  // The lighting of the rotated environment is L'(d) = L(R⁻¹d) (envmap.h RotateAboutY,
  // cubemap_resample.cpp): the same inverse rotation here, RotateAboutY(d, −θ) with its cosine
  // and sine computed once instead of per pixel.
  const double c = std::cos(-rotation_y), s = std::sin(-rotation_y);
  return [lookup = std::move(lookup), c, s](const Vec3& d) {
    return lookup->Radiance({c * d.x + s * d.z, d.y, -s * d.x + c * d.z});
  };
}

}  // namespace prt
