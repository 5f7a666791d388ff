// The background at the environment image's own resolution (environment_background.h): the
// image's values at pixel centres, bilinear between them, within a cube face, agreeing with the
// lighting cubemap on average, and rotated exactly as the lighting is.
#include "viewer/environment_background.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

// A lat-long image whose pixels follow no smooth rule: every value differs from its neighbours
// (so a lookup that read the wrong pixel, or the wrong weights, shows).
EnvironmentImage PatternLatLong(int w, int h) {
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i = e.Index(x, y);
      e.r[i] = 1.0f + static_cast<float>((x * 7 + y * 3) % 11);
      e.g[i] = 0.5f + 0.25f * static_cast<float>(y) + 0.125f * static_cast<float>(x % 5);
      e.b[i] = 3.0f + static_cast<float>((x * x + y) % 13) / 8.0f;
    }
  return e;
}

// f(d) > 0, smooth: the image holds f at its pixel centres.
double Smooth(const Vec3& d, int c) {
  return 2.0 + 0.8 * d.x + 0.5 * d.y * (c + 1) + 0.3 * d.z * d.x - 0.2 * c * d.z;
}

Rgb Pixel(const EnvironmentImage& e, int x, int y) {
  const std::size_t i = e.Index(x, y);
  return {e.r[i], e.g[i], e.b[i]};
}

TEST(EnvironmentBackground, LatLongPixelCentresAreExactAndBetweenThemBilinear) {
  const int w = 64, h = 32;
  const EnvironmentImage e = PatternLatLong(w, h);
  const EnvironmentLookup lookup(e);
  // At every pixel centre off the poles, the pixel's own value (both seam columns included).
  for (int y = 1; y < h - 1; ++y)
    for (int x = 0; x < w; ++x) {
      const Rgb v = lookup.Radiance(LatLongDirection(w, h, x, y));
      const Rgb p = Pixel(e, x, y);
      for (int c = 0; c < 3; ++c) ASSERT_EQ(v[c], p[c]) << x << "," << y << " channel " << c;
    }
  // Between centres: bilinear in the image's pixel positions.
  for (const auto& [px, py] : std::vector<std::pair<double, double>>{
           {10.5, 7.0}, {10.0, 7.5}, {10.25, 7.75}, {33.9, 20.1}, {0.5, 15.5}, {62.5, 4.25}}) {
    const int x0 = static_cast<int>(std::floor(px)), y0 = static_cast<int>(std::floor(py));
    const double fx = px - x0, fy = py - y0;
    const Rgb v = lookup.Radiance(LatLongDirection(w, h, px, py));
    for (int c = 0; c < 3; ++c) {
      const double expected =
          (1 - fx) * (1 - fy) * Pixel(e, x0, y0)[c] + fx * (1 - fy) * Pixel(e, x0 + 1, y0)[c] +
          (1 - fx) * fy * Pixel(e, x0, y0 + 1)[c] + fx * fy * Pixel(e, x0 + 1, y0 + 1)[c];
      EXPECT_NEAR(v[c], expected, 1e-5 * expected) << px << "," << py << " channel " << c;
    }
  }
  // The poles: every column of row 0 is the north pole; OpenEXR's mapping reads the pole at
  // longitude 0, column (w − 1)/2 = 31.5, between columns 31 and 32 of the pole's row.
  const Rgb north = lookup.Radiance({0, 1, 0});
  const Rgb south = lookup.Radiance({0, -1, 0});
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(north[c], 0.5 * (Pixel(e, 31, 0)[c] + Pixel(e, 32, 0)[c]), 1e-5);
    EXPECT_NEAR(south[c], 0.5 * (Pixel(e, 31, h - 1)[c] + Pixel(e, 32, h - 1)[c]), 1e-5);
  }
  // Beyond the last row's centre there is nothing to interpolate with: clamped, not wrapped.
  const Rgb near_pole = lookup.Radiance(LatLongDirection(w, h, 5.0, 0.01));
  EXPECT_NEAR(near_pole[0], 0.99 * Pixel(e, 5, 0)[0] + 0.01 * Pixel(e, 5, 1)[0], 1e-5);
}

// Longitude wraps through OpenEXR's seam: column 0 (φ = +π) and column w − 1 (φ = −π) are one
// meridian, so directions just either side of −Z read columns 0–1 and w−2 – w−1, and a
// direction exactly on it reads one of the two columns there (equal in a seamless image).
TEST(EnvironmentBackground, LatLongSeamIsContinuousForASeamlessImage) {
  const int w = 129, h = 65;
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 d = LatLongDirection(w, h, x, y);
      for (int c = 0; c < 3; ++c) e.Channel(c)[e.Index(x, y)] = static_cast<float>(Smooth(d, c));
    }
  const EnvironmentLookup lookup(e);
  for (double lat : {-1.2, -0.3, 0.0, 0.4, 1.1}) {
    for (double eps : {-1e-3, -1e-9, 0.0, 1e-9, 1e-3}) {
      const Vec3 d{std::sin(eps) * std::cos(lat), std::sin(lat), -std::cos(eps) * std::cos(lat)};
      const Rgb v = lookup.Radiance(d);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(v[c], Smooth(d, c), 2e-3) << lat << " " << eps;
    }
  }
}

// A cube image whose faces hold different constants: every direction reads its own face's
// constant exactly (the interpolation never reaches into a neighbouring face's block), and
// inside a face pixel centres are exact.
TEST(EnvironmentBackground, CubeImageStaysOnTheFaceOfTheDirection) {
  const int s = 16;
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kCube, s, 6 * s);
  for (int y = 0; y < 6 * s; ++y)
    for (int x = 0; x < s; ++x)
      for (int c = 0; c < 3; ++c)
        e.Channel(c)[e.Index(x, y)] = static_cast<float>(1 + y / s + 10 * c);
  const EnvironmentLookup faces(e);
  uint64_t state = 12345;
  const auto uniform = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) / 9007199254740992.0 * 2.0 - 1.0;
  };
  for (int k = 0; k < 20000; ++k) {
    Vec3 d{uniform(), uniform(), uniform()};
    if (k % 4 == 0) d.x = std::copysign(std::max(std::abs(d.y), std::abs(d.z)), d.x);  // edges
    int face;
    double u, v;
    CubemapLayout::DirectionToFace(d, face, u, v);
    const Rgb r = faces.Radiance(d);
    for (int c = 0; c < 3; ++c) ASSERT_EQ(r[c], static_cast<float>(1 + face + 10 * c)) << k;
  }
  // A pattern: interior pixel centres (edge pixels repeat a neighbouring face's directions).
  for (int y = 0; y < 6 * s; ++y)
    for (int x = 0; x < s; ++x) e.r[e.Index(x, y)] = static_cast<float>(1 + (x * 5 + y * 3) % 17);
  const EnvironmentLookup pattern(e);
  for (int y = 0; y < 6 * s; ++y) {
    if (y % s == 0 || y % s == s - 1) continue;
    for (int x = 1; x < s - 1; ++x)
      ASSERT_EQ(pattern.Radiance(CubeImageDirection(s, x, y))[0], e.r[e.Index(x, y)])
          << x << "," << y;
  }
}

// The lighting cubemap is the solid-angle average of the image (cubemap_resample.h); the
// background interpolates the same pixels, so its average over each texel is the texel's value
// up to the difference between bilinear and piecewise-constant pixels (second order in the
// pixel size for a smooth image), and the two carry the same power.
TEST(EnvironmentBackground, AgreesWithTheLightingCubemapOnAverage) {
  const int w = 512, h = 256, n = 8;
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 d = LatLongDirection(w, h, x, y);
      for (int c = 0; c < 3; ++c) e.Channel(c)[e.Index(x, y)] = static_cast<float>(Smooth(d, c));
    }
  const CubemapRgb cube = ResampleToCubemap(e, n);
  const BackgroundFunction background =
      EnvironmentBackground(std::make_shared<const EnvironmentLookup>(e));
  const CubemapLayout layout(n);
  const int k = 24;  // samples per texel side (midpoint rule, weighted by solid angle)
  std::array<double, 3> power_bg{}, power_cube{};
  double worst = 0;
  for (std::size_t j = 0; j < layout.texel_count(); ++j) {
    std::array<double, 3> sum{};
    double weight = 0;
    for (int b = 0; b < k; ++b)
      for (int a = 0; a < k; ++a) {
        const Vec3 p = layout.TexelDirection(j, (a + 0.5) / k, (b + 0.5) / k);
        // Solid-angle density of the face point (1, u, v): (1 + u² + v²)^(−3/2).
        int face;
        double u, v;
        CubemapLayout::DirectionToFace(p, face, u, v);
        const double dw = std::pow(1 + u * u + v * v, -1.5);
        const Rgb r = background(p);
        for (int c = 0; c < 3; ++c) sum[c] += dw * r[c];
        weight += dw;
      }
    for (int c = 0; c < 3; ++c) {
      const double mean = sum[c] / weight, texel = cube.Channel(c)[j];
      worst = std::max(worst, std::abs(mean - texel) / texel);
      power_bg[c] += mean * layout.TexelSolidAngle(j);
      power_cube[c] += texel * layout.TexelSolidAngle(j);
    }
  }
  EXPECT_LT(worst, 1e-3);  // measured 2.0e-4
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(power_bg[c] / power_cube[c], 1.0, 1e-5) << c;  // 3e-7
  // The cubemap background is the texel average itself, so nearest-texel lookups differ from the
  // image by the variation inside a texel; the image background does not.
  const BackgroundFunction blocky = CubemapBackground(cube);
  const Vec3 d = Normalize(Vec3{0.9, 0.35, 0.2});
  EXPECT_NEAR(background(d)[0], Smooth(d, 0), 1e-4);       // 2.1e-5
  EXPECT_GT(std::abs(blocky(d)[0] - Smooth(d, 0)), 1e-2);  // 1.8e-2
}

// The lighting of a frame rotated by θ is ResampleToCubemap(env, n, θ): a sun at direction s
// lights from R_θ·s. The background of that frame must show the sun there too, and not at
// R_θ⁻¹·s (the opposite rotation).
TEST(EnvironmentBackground, RotatesWithTheLighting) {
  const int w = 256, h = 128, n = 32;
  EnvironmentImage e = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int c = 0; c < 3; ++c) std::fill(e.Channel(c).begin(), e.Channel(c).end(), 0.1f);
  const int sx = 150, sy = 45;  // a 3×3-pixel sun, off every axis
  for (int y = sy - 1; y <= sy + 1; ++y)
    for (int x = sx - 1; x <= sx + 1; ++x)
      for (int c = 0; c < 3; ++c) e.Channel(c)[e.Index(x, y)] = 1000.0f;
  const Vec3 sun = LatLongDirection(w, h, sx, sy);
  const auto lookup = std::make_shared<const EnvironmentLookup>(e);
  const CubemapLayout layout(n);
  // prt-view's rotation frames (5°/frame, frame 7), a quarter turn, and angles of both signs.
  for (double theta : {0.0, 7 * 5 * std::numbers::pi / 180, std::numbers::pi / 2, 0.7, -2.1}) {
    const CubemapRgb cube = ResampleToCubemap(e, n, theta);
    const Vec3 lit_from = RotateAboutY(sun, theta);
    // Where the lighting's sun is: the power-weighted mean direction of the texels above the sky
    // (the sun spans about 4°, a texel 2–3°), and the texel holding its centre is bright.
    Vec3 centroid{0, 0, 0};
    for (std::size_t j = 0; j < layout.texel_count(); ++j)
      centroid = centroid + (cube.r[j] - 0.1) * layout.TexelSolidAngle(j) * layout.TexelCenter(j);
    const double off = std::acos(std::clamp(Dot(Normalize(centroid), lit_from), -1.0, 1.0));
    EXPECT_LT(off * 180 / std::numbers::pi, 0.5) << theta;  // measured 0.06–0.19°
    EXPECT_GT(cube.r[layout.TexelOf(lit_from)], 300.0f) << theta;
    // The background shows the sun at that same direction, and sky where the opposite rotation
    // would have put it.
    const BackgroundFunction background = EnvironmentBackground(lookup, theta);
    EXPECT_EQ(background(lit_from)[0], 1000.0f) << theta;
    if (theta != 0.0) {
      EXPECT_EQ(background(RotateAboutY(sun, -theta))[0], 0.1f) << theta;
    }
  }
}

TEST(EnvironmentBackground, RejectsNonFiniteAndMalformedImages) {
  EnvironmentImage e = PatternLatLong(16, 8);
  e.g[e.Index(3, 5)] = std::numeric_limits<float>::infinity();
  try {
    EnvironmentLookup bad(e, "sky.exr");
    FAIL() << "an Inf pixel was accepted";
  } catch (const NumericalError& err) {
    EXPECT_NE(std::string(err.what()).find("sky.exr: Inf at pixel (x=3, y=5, channel G)"),
              std::string::npos)
        << err.what();
  }
  e.g[e.Index(3, 5)] = std::nanf("");
  EXPECT_THROW(EnvironmentLookup{e}, NumericalError);
  EnvironmentImage short_channel = PatternLatLong(16, 8);
  short_channel.b.pop_back();
  EXPECT_THROW(EnvironmentLookup{short_channel}, InputError);
  EXPECT_THROW(EnvironmentLookup{EnvironmentImage::Zero(EnvmapLayout::kCube, 4, 20)}, InputError);
  EXPECT_THROW(EnvironmentBackground(nullptr), std::invalid_argument);
  EXPECT_THROW(EnvironmentBackground(
                   std::make_shared<const EnvironmentLookup>(PatternLatLong(4, 2)), std::nan("")),
               std::invalid_argument);
}

// The batch the rasteriser calls (RadianceBatch, EnvironmentBackground's batch) gives what
// Radiance gives, direction by direction: libmvec's atan2 is within 4 ulp of std::atan2, which
// moves a position by ~1e-13 pixels; with a 10⁴ contrast between neighbouring pixels that is
// still far below float rounding. Pixel centres, the seam, the poles and random directions, with
// and without rotation, lat-long and cube.
TEST(EnvironmentBackground, BatchAgreesWithRadiance) {
  const int w = 64, h = 32;
  EnvironmentImage e = PatternLatLong(w, h);
  e.b[e.Index(20, 9)] = 1e4f;
  const auto lookup = std::make_shared<const EnvironmentLookup>(e);
  std::vector<Vec3> dirs = {{0, 1, 0},           {0, -1, 0}, {0, 0, 1},      {0, 0, -1},
                            {1e-300, 0.3, -0.0}, {0, 0, 0},  {-0.0, 0.2, -1}};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) dirs.push_back(LatLongDirection(w, h, x, y));
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < 3000; ++k) dirs.push_back({n(rng), n(rng), n(rng)});
  std::vector<Rgb> out(dirs.size());
  for (double theta : {0.0, 0.4, -2.5}) {
    lookup->RadianceBatch(dirs, std::cos(-theta), std::sin(-theta), out);
    const BackgroundFunction background = EnvironmentBackground(lookup, theta);
    std::vector<Rgb> via_function(dirs.size());
    background(std::span<const Vec3>(dirs), std::span<Rgb>(via_function));
    for (std::size_t i = 0; i < dirs.size(); ++i) {
      const Rgb want = background(dirs[i]);
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(out[i][c], want[c], 1e-6 * std::abs(want[c])) << i << " theta " << theta;
        EXPECT_EQ(out[i][c], via_function[i][c]) << i;
      }
    }
  }
  // The cube layout goes through Radiance itself: bitwise.
  EnvironmentImage cube = EnvironmentImage::Zero(EnvmapLayout::kCube, 8, 48);
  for (std::size_t i = 0; i < cube.PixelCount(); ++i) {
    cube.r[i] = static_cast<float>(i % 17);
    cube.g[i] = static_cast<float>(i % 5);
    cube.b[i] = 1.0f;
  }
  const EnvironmentLookup cube_lookup(cube);
  std::vector<Rgb> cube_out(dirs.size());
  cube_lookup.RadianceBatch(dirs, 1.0, 0.0, cube_out);
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    EXPECT_EQ(cube_out[i], cube_lookup.Radiance(dirs[i])) << i;
  }
  EXPECT_THROW(lookup->RadianceBatch(dirs, 1.0, 0.0, std::span<Rgb>(out).first(3)),
               std::invalid_argument);
}

}  // namespace
}  // namespace prt
