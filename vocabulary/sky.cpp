// A procedural sky with a sun, for tests and demos (see sky.h).
#include "vocabulary/sky.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

constexpr double kPi = std::numbers::pi;

}  // namespace

// ---- Procedural sky ----

std::array<float, 3> SkyRadiance(const SkySunParams& p, const Vec3& dir) {
  const Vec3 d = Normalize(dir);
  const Vec3 sun = Normalize(p.sun_direction);
  std::array<float, 3> out;
  const double glow = std::pow(std::max(0.0, Dot(d, sun)), 4.0);
  for (int c = 0; c < 3; ++c) {
    double v;
    if (d.y >= 0) {
      const double t = (1 - std::exp(-3 * d.y)) / (1 - std::exp(-3.0));
      v = p.horizon[c] + (p.zenith[c] - p.horizon[c]) * t;
    } else {
      v = p.ground[c] + (p.horizon[c] - p.ground[c]) * std::exp(8 * d.y);
    }
    v *= 1 + 0.5 * glow;
    out[c] = static_cast<float>(v);
  }
  return out;
}

EnvironmentImage SampleEnvironment(EnvmapLayout layout, int width, int height,
                                   const std::function<std::array<float, 3>(const Vec3&)>& f) {
  ValidateEnvironmentShape("<procedural>", layout, width, height);
  EnvironmentImage img = EnvironmentImage::Zero(layout, width, height);
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const Vec3 d = layout == EnvmapLayout::kLatLong ? LatLongDirection(width, height, x, y)
                                                      : CubeImageDirection(width, x, y);
      const std::array<float, 3> v = f(Normalize(d));
      for (int c = 0; c < 3; ++c) img.Channel(c)[img.Index(x, y)] = v[c];
    }
  });
  return img;
}

EnvironmentImage MakeSkyWithSun(EnvmapLayout layout, int width, int height,
                                const SkySunParams& params, int supersamples) {
  EnvironmentImage img = SampleEnvironment(layout, width, height,
                                           [&](const Vec3& d) { return SkyRadiance(params, d); });
  const Vec3 sun = Normalize(params.sun_direction);
  const double cos_r = std::cos(params.sun_angular_radius);
  const int ss = std::max(1, supersamples);
  // Bound on a pixel cell's angular radius, to skip pixels far from the disc.
  const double cell = layout == EnvmapLayout::kLatLong
                          ? 2 * kPi / (width - 1) + kPi / (height - 1)
                          : 2.0 * (width > 1 ? 2.0 / (width - 1) : 2.0);
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const Vec3 c =
          Normalize(layout == EnvmapLayout::kLatLong ? LatLongDirection(width, height, x, y)
                                                     : CubeImageDirection(width, x, y));
      if (std::acos(std::clamp(Dot(c, sun), -1.0, 1.0)) > params.sun_angular_radius + cell)
        continue;
      // Box filter over the cell: fraction of the cell's solid angle inside the disc.
      double in = 0, all = 0;
      if (layout == EnvmapLayout::kLatLong) {
        const PixelInterval ph = LatLongColumnCell(width, x), th = LatLongRowCell(height, y);
        for (int j = 0; j < ss; ++j) {
          const double t = th.lo + (j + 0.5) * (th.hi - th.lo) / ss;
          for (int i = 0; i < ss; ++i) {
            const double f = ph.lo + (i + 0.5) * (ph.hi - ph.lo) / ss;
            const Vec3 d{std::sin(f) * std::cos(t), std::sin(t), std::cos(f) * std::cos(t)};
            all += std::cos(t);
            if (Dot(d, sun) >= cos_r) in += std::cos(t);
          }
        }
      } else {
        int face, fi, fj;
        CubePixelToFace(width, x, y, face, fi, fj);
        const PixelInterval cu = CubeCell(width, fi), cv = CubeCell(width, fj);
        for (int j = 0; j < ss; ++j) {
          const double v = cv.lo + (j + 0.5) * (cv.hi - cv.lo) / ss;
          for (int i = 0; i < ss; ++i) {
            const double u = cu.lo + (i + 0.5) * (cu.hi - cu.lo) / ss;
            const double wgt = std::pow(1 + u * u + v * v, -1.5);
            all += wgt;
            if (Dot(CubemapLayout::FaceDirection(face, u, v), sun) >= cos_r) in += wgt;
          }
        }
      }
      if (in <= 0) continue;
      const double frac = in / all;
      for (int ch = 0; ch < 3; ++ch) {
        img.Channel(ch)[img.Index(x, y)] += static_cast<float>(frac * params.sun_radiance[ch]);
      }
    }
  });
  return img;
}

}  // namespace prt
