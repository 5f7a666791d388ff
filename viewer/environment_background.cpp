// The environment image as a frame's background (see environment_background.h).
#include "viewer/environment_background.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
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

namespace {

// Bilinear between the pixel centres around (px, py), the four pixels (x0, x0 + 1) × (y0, y0 + 1)
// with x0 ∈ [x_lo, x_hi − 1] and y0 ∈ [y_lo, y_hi − 1], so that the lookup stays inside that
// block (a cube face, or the whole lat-long image). A block one pixel wide or high uses its one
// column or row. Inlined into Radiance and into both builds of RadianceBatch, which therefore
// round alike.
[[gnu::always_inline]] inline Rgb BilinearAt(const EnvironmentImage& image, double px, double py,
                                             int x_lo, int x_hi, int y_lo, int y_hi) {
  px = std::clamp(px, static_cast<double>(x_lo), static_cast<double>(x_hi));
  py = std::clamp(py, static_cast<double>(y_lo), static_cast<double>(y_hi));
  const int x0 = std::min(static_cast<int>(std::floor(px)), std::max(x_lo, x_hi - 1));
  const int y0 = std::min(static_cast<int>(std::floor(py)), std::max(y_lo, y_hi - 1));
  const int x1 = std::min(x0 + 1, x_hi), y1 = std::min(y0 + 1, y_hi);
  const double fx = px - x0, fy = py - y0;
  const double w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  const std::size_t i00 = image.Index(x0, y0), i10 = image.Index(x1, y0), i01 = image.Index(x0, y1),
                    i11 = image.Index(x1, y1);
  Rgb out;
  for (int c = 0; c < 3; ++c) {
    const float* v = image.Channel(c).data();
    // A convex combination of finite floats (checked at construction): finite, and within the
    // four values' range up to rounding, so the float it rounds to is finite too.
    out[static_cast<std::size_t>(c)] =
        static_cast<float>(w00 * v[i00] + w10 * v[i10] + w01 * v[i01] + w11 * v[i11]);
  }
  return out;
}

}  // namespace

Rgb EnvironmentLookup::Bilinear(double px, double py, int x_lo, int x_hi, int y_lo,
                                int y_hi) const {
  return BilinearAt(image_, px, py, x_lo, x_hi, y_lo, y_hi);
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

namespace {

// LatLongPixelPosition (vocabulary/envmap.cpp) and the bilinear lookup for n ≤ kBatch
// directions rotated by (cos_y, sin_y) about +Y, `atan2` evaluating four (y, x) pairs at a time
// from arrays padded to a multiple of 4.
constexpr std::size_t kBatch = 64;

template <typename Atan2x4>
[[gnu::always_inline]] inline void LatLongBatch(const EnvironmentImage& image, const Vec3* dirs,
                                                std::size_t n, bool rotate, double cos_y,
                                                double sin_y, Rgb* out, Atan2x4 atan2x4) {
  constexpr double kPi = std::numbers::pi;
  alignas(32) double ys[kBatch], rs[kBatch], xs[kBatch], zs[kBatch], lat[kBatch], lon[kBatch];
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3& d0 = dirs[i];
    const Vec3 d =
        rotate ? Vec3{cos_y * d0.x + sin_y * d0.z, d0.y, -sin_y * d0.x + cos_y * d0.z} : d0;
    xs[i] = d.x;
    ys[i] = d.y;
    zs[i] = d.z;
    rs[i] = std::sqrt(d.z * d.z + d.x * d.x);
  }
  const std::size_t padded = (n + 3) / 4 * 4;
  for (std::size_t i = n; i < padded; ++i) xs[i] = ys[i] = zs[i] = rs[i] = 1.0;
  for (std::size_t i = 0; i < padded; i += 4) {
    atan2x4(ys + i, rs + i, lat + i);
    atan2x4(xs + i, zs + i, lon + i);
  }
  const int w = image.width, h = image.height;
  for (std::size_t i = 0; i < n; ++i) {
    const double lo = (zs[i] == 0 && xs[i] == 0) ? 0.0 : lon[i];
    const double px = (lo / (-2 * kPi) + 0.5) * (w - 1);
    const double py = (lat[i] / -kPi + 0.5) * (h - 1);
    out[i] = BilinearAt(image, px, py, 0, w - 1, 0, h - 1);
  }
}

void LatLongBatchScalar(const EnvironmentImage& image, const Vec3* dirs, std::size_t n, bool rotate,
                        double cos_y, double sin_y, Rgb* out) {
  LatLongBatch(image, dirs, n, rotate, cos_y, sin_y, out,
               [](const double* y, const double* x, double* r) {
                 for (int k = 0; k < 4; ++k) r[k] = std::atan2(y[k], x[k]);
               });
}

#if defined(__x86_64__) && defined(PRT_HAVE_LIBMVEC)
using Double4 = double __attribute__((vector_size(32)));
extern "C" Double4 _ZGVdN4vv_atan2(Double4 y, Double4 x);  // glibc ≥ 2.35 libmvec, AVX2

// The same compiled for AVX2 (no FMA: every product and sum rounds as in the scalar build), with
// libmvec's atan2 of four pairs.
__attribute__((target("avx2"))) void LatLongBatchAvx2(const EnvironmentImage& image,
                                                      const Vec3* dirs, std::size_t n, bool rotate,
                                                      double cos_y, double sin_y, Rgb* out) {
  LatLongBatch(
      image, dirs, n, rotate, cos_y, sin_y, out,
      [](const double* y, const double* x, double* r) __attribute__((target("avx2"))) {
        Double4 vy, vx;
        std::memcpy(&vy, y, sizeof vy);
        std::memcpy(&vx, x, sizeof vx);
        const Double4 a = _ZGVdN4vv_atan2(vy, vx);
        std::memcpy(r, &a, sizeof a);
      });
}

const bool g_atan2_avx2 = [] {
  __builtin_cpu_init();  // a static initializer may run before the one that fills the CPU model
  return __builtin_cpu_supports("avx2") != 0;
}();
#endif

}  // namespace

void EnvironmentLookup::RadianceBatch(std::span<const Vec3> directions, double cos_y, double sin_y,
                                      std::span<Rgb> out) const {
  if (out.size() != directions.size())
    throw std::invalid_argument(
        "EnvironmentLookup::RadianceBatch: " + std::to_string(directions.size()) + " directions, " +
        std::to_string(out.size()) + " outputs");
  const bool rotate = !(cos_y == 1.0 && sin_y == 0.0);
  if (image_.layout != EnvmapLayout::kLatLong) {
    for (std::size_t i = 0; i < directions.size(); ++i) {
      const Vec3& d = directions[i];
      out[i] =
          Radiance(rotate ? Vec3{cos_y * d.x + sin_y * d.z, d.y, -sin_y * d.x + cos_y * d.z} : d);
    }
    return;
  }
  for (std::size_t b = 0; b < directions.size(); b += kBatch) {
    const std::size_t n = std::min(kBatch, directions.size() - b);
#if defined(__x86_64__) && defined(PRT_HAVE_LIBMVEC)
    if (g_atan2_avx2) {
      LatLongBatchAvx2(image_, directions.data() + b, n, rotate, cos_y, sin_y, out.data() + b);
      continue;
    }
#endif
    LatLongBatchScalar(image_, directions.data() + b, n, rotate, cos_y, sin_y, out.data() + b);
  }
}

BackgroundFunction EnvironmentBackground(std::shared_ptr<const EnvironmentLookup> lookup,
                                         double rotation_y) {
  if (lookup == nullptr) throw std::invalid_argument("EnvironmentBackground: no environment");
  if (!std::isfinite(rotation_y))
    throw std::invalid_argument("EnvironmentBackground: rotation must be finite");
  // The batch (RadianceBatch) serves the rasteriser, a run of pixels at a time.
  if (rotation_y == 0.0)
    return BackgroundFunction([lookup](const Vec3& d) { return lookup->Radiance(d); },
                              [lookup](std::span<const Vec3> d, std::span<Rgb> out) {
                                lookup->RadianceBatch(d, 1.0, 0.0, out);
                              });
  // The lighting of the rotated environment is L'(d) = L(R⁻¹d) (envmap.h RotateAboutY,
  // cubemap_resample.cpp): the same inverse rotation here, RotateAboutY(d, −θ) with its cosine
  // and sine computed once instead of per pixel.
  const double c = std::cos(-rotation_y), s = std::sin(-rotation_y);
  return BackgroundFunction(
      [lookup, c, s](const Vec3& d) {
        return lookup->Radiance({c * d.x + s * d.z, d.y, -s * d.x + c * d.z});
      },
      [lookup, c, s](std::span<const Vec3> d, std::span<Rgb> out) {
        lookup->RadianceBatch(d, c, s, out);
      });
}

}  // namespace prt
