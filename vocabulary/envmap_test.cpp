#include "vocabulary/envmap.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfEnvmap.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <tuple>

#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "vocabulary/sky.h"

namespace prt {
namespace {

constexpr double kPi = std::numbers::pi;
namespace fs = std::filesystem;

fs::path TempDir() {
  const fs::path d = fs::temp_directory_path() / ("prt_envmap_test_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// Writes R, G, B float EXR with no envmap attribute (as many tools do).
void WriteExrNoAttribute(const EnvironmentImage& img, const std::string& path) {
  Imf::Header header(img.width, img.height);
  for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
  Imf::OutputFile file(path.c_str(), header);
  Imf::FrameBuffer fb;
  const std::size_t xs = sizeof(float), ys = xs * img.width;
  fb.insert("R", Imf::Slice::Make(Imf::FLOAT, img.r.data(), header.dataWindow(), xs, ys));
  fb.insert("G", Imf::Slice::Make(Imf::FLOAT, img.g.data(), header.dataWindow(), xs, ys));
  fb.insert("B", Imf::Slice::Make(Imf::FLOAT, img.b.data(), header.dataWindow(), xs, ys));
  file.setFrameBuffer(fb);
  file.writePixels(img.height);
}

EnvironmentImage Constant(EnvmapLayout layout, int w, int h, float v) {
  EnvironmentImage img = EnvironmentImage::Zero(layout, w, h);
  for (int c = 0; c < 3; ++c)
    img.Channel(c).assign(img.PixelCount(), v * (1.0f + 0.5f * static_cast<float>(c)));
  return img;
}

// ---- Directions follow ImfEnvmap.h exactly ----

TEST(Envmap, LatLongDirectionMatchesOpenExr) {
  const int w = 64, h = 32;
  const Imath::Box2i dw(Imath::V2i(0, 0), Imath::V2i(w - 1, h - 1));
  for (double py : {0.0, 0.5, 7.0, 15.5, 31.0}) {
    for (double px : {0.0, 1.0, 16.0, 31.5, 47.25, 63.0}) {
      const Imath::V3f e = Imf::LatLongMap::direction(
          dw, Imath::V2f(static_cast<float>(px), static_cast<float>(py)));
      const Vec3 d = LatLongDirection(w, h, px, py);
      EXPECT_NEAR(d.x, e.x, 1e-6);
      EXPECT_NEAR(d.y, e.y, 1e-6);
      EXPECT_NEAR(d.z, e.z, 1e-6);
      if (py > 0 && py < h - 1 && px > 0 && px < w - 1) {  // away from the seam and the poles
        double qx, qy;
        LatLongPixelPosition(w, h, d, qx, qy);
        EXPECT_NEAR(qx, px, 1e-9);
        EXPECT_NEAR(qy, py, 1e-9);
        const Imath::V2f q = Imf::LatLongMap::pixelPosition(
            dw,
            Imath::V3f(static_cast<float>(d.x), static_cast<float>(d.y), static_cast<float>(d.z)));
        EXPECT_NEAR(q.x, px, 1e-3);
        EXPECT_NEAR(q.y, py, 1e-3);
      }
    }
  }
  // Top row is +Y; the centre column looks down +Z; longitude grows to the left.
  EXPECT_NEAR(LatLongDirection(w, h, 10, 0).y, 1.0, 1e-12);
  EXPECT_NEAR(LatLongDirection(w, h, 31.5, 15.5).z, 1.0, 1e-12);
  EXPECT_NEAR(LatLongDirection(w, h, 15.75, 15.5).x, 1.0, 1e-12);
}

TEST(Envmap, CubeDirectionMatchesOpenExr) {
  const int s = 5;
  const Imath::Box2i dw(Imath::V2i(0, 0), Imath::V2i(s - 1, 6 * s - 1));
  for (int py = 0; py < 6 * s; ++py) {
    for (int px = 0; px < s; ++px) {
      const Vec3 d = CubeImageDirection(s, px, py);
      // OpenEXR: direction → face and position in face → image pixel position.
      const double ax = std::abs(d.x), ay = std::abs(d.y), az = std::abs(d.z);
      if (ax == ay || ay == az || ax == az) continue;  // on a cube edge: the face is ambiguous
      Imf::CubeMapFace face;
      Imath::V2f pif;
      Imf::CubeMap::faceAndPixelPosition(
          Imath::V3f(static_cast<float>(d.x), static_cast<float>(d.y), static_cast<float>(d.z)), dw,
          face, pif);
      ASSERT_EQ(static_cast<int>(face), py / s) << px << "," << py;
      const Imath::V2f pos = Imf::CubeMap::pixelPosition(face, dw, pif);
      EXPECT_NEAR(pos.x, px, 1e-4);
      EXPECT_NEAR(pos.y, py, 1e-4);
      const Imath::V3f e = Imf::CubeMap::direction(face, dw, pif);
      EXPECT_NEAR(d.x, e.x, 1e-5);
      EXPECT_NEAR(d.y, e.y, 1e-5);
      EXPECT_NEAR(d.z, e.z, 1e-5);
      double qx, qy;
      CubeImagePixelPosition(s, d, qx, qy);
      EXPECT_NEAR(qx, px, 1e-9);
      EXPECT_NEAR(qy, py, 1e-9);
    }
  }
}

TEST(Envmap, RotateAboutYGrowsLongitude) {
  const Vec3 d = RotateAboutY({0, 0, 1}, kPi / 2);
  EXPECT_NEAR(d.x, 1, 1e-15);
  EXPECT_NEAR(d.z, 0, 1e-15);
  // On a lat-long map, +90° about +Y moves a feature by −(w−1)/4 columns.
  const int w = 65, h = 33;
  double px, py;
  LatLongPixelPosition(w, h, RotateAboutY(LatLongDirection(w, h, 40, 10), kPi / 2), px, py);
  EXPECT_NEAR(px, 24, 1e-9);
  EXPECT_NEAR(py, 10, 1e-9);
}

// ---- Pixel cells ----

TEST(Envmap, PixelCellsTileTheSphere) {
  for (const auto& [layout, w, h] :
       {std::tuple{EnvmapLayout::kLatLong, 2, 2}, std::tuple{EnvmapLayout::kLatLong, 37, 12},
        std::tuple{EnvmapLayout::kLatLong, 1024, 512}, std::tuple{EnvmapLayout::kCube, 1, 6},
        std::tuple{EnvmapLayout::kCube, 7, 42}}) {
    const EnvironmentImage img = Constant(layout, w, h, 1.0f);
    const std::array<double, 3> p = EnvironmentPower(img);
    EXPECT_NEAR(p[0] / (4 * kPi), 1.0, 1e-12) << w << "x" << h;
  }
}

// ---- Resampling: integration over texel solid angles ----

TEST(EnvmapResample, ConstantMapStaysConstant) {
  struct Case {
    EnvmapLayout layout;
    int w, h, n;
    double rot;
  };
  for (const Case& c :
       {Case{EnvmapLayout::kLatLong, 1024, 512, 32, 0.0},
        Case{EnvmapLayout::kLatLong, 1024, 512, 32, 0.9},
        Case{EnvmapLayout::kLatLong, 16, 8, 64, 0.0},  // source coarser than L
        Case{EnvmapLayout::kCube, 64, 384, 32, 0.0}, Case{EnvmapLayout::kCube, 64, 384, 16, 2.1},
        Case{EnvmapLayout::kCube, 3, 18, 8, 0.3}}) {
    const CubemapRgb cube = ResampleToCubemap(Constant(c.layout, c.w, c.h, 2.5f), c.n, c.rot);
    ASSERT_EQ(cube.TexelCount(), static_cast<std::size_t>(6 * c.n * c.n));
    for (int ch = 0; ch < 3; ++ch) {
      const double expect = 2.5 * (1.0 + 0.5 * ch);
      for (std::size_t t = 0; t < cube.TexelCount(); ++t) {
        ASSERT_NEAR(cube.Channel(ch)[t] / expect, 1.0, 1e-6)
            << "texel " << t << " n=" << c.n << " source " << c.w << "x" << c.h;
      }
    }
  }
}

TEST(EnvmapResample, RejectsNonFiniteInput) {
  EnvironmentImage img = Constant(EnvmapLayout::kLatLong, 16, 8, 1);
  img.b[img.Index(3, 2)] = std::numeric_limits<float>::infinity();
  try {
    ResampleToCubemap(img, 4);
    FAIL();
  } catch (const NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("x=3, y=2, channel 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ResampleToCubemap(Constant(EnvmapLayout::kLatLong, 16, 8, 1), 4, std::nan("")),
               std::invalid_argument);
  EXPECT_THROW(ResampleToCubemap(Constant(EnvmapLayout::kLatLong, 16, 8, 1), 3),
               std::invalid_argument);
}

// A one-pixel sun keeps its power Σ L_j Ω_j (exact texel solid angles) within 0.5%, wherever it
// is: at the equator, near the poles, on cube face edges and near a cube corner.
TEST(EnvmapResample, OnePixelSunKeepsItsPower) {
  const int w = 1024, h = 512;
  // Pixel positions of directions on face edges / corners.
  double ex, ey, cx, cy;
  LatLongPixelPosition(w, h, Vec3{1, 0, 1}, ex, ey);  // +X/+Z edge at the equator
  LatLongPixelPosition(w, h, Vec3{1, 1, 1}, cx, cy);  // cube corner
  double tx, ty;
  LatLongPixelPosition(w, h, Vec3{0.3, 1, 1}, tx, ty);  // +Y/+Z edge
  const std::vector<std::pair<int, int>> suns = {
      {100, 255},
      {700, 256},
      {300, 1},  // next to the north pole cap
      {static_cast<int>(ex), static_cast<int>(ey)},
      {static_cast<int>(cx), static_cast<int>(cy)},
      {512, 509},  // near the south pole
      {static_cast<int>(tx), static_cast<int>(ty)},
      {static_cast<int>(std::lround(ex)), static_cast<int>(std::lround(ey))},
      {800, 2},
      {5, 510},
      {0, 200},  // on the seam (a half cell)
      {1023, 300},
      {static_cast<int>(tx) + 1, static_cast<int>(ty) + 1}};
  double worst = 0;
  for (const auto& [n, rot, count] :
       {std::tuple{32, 0.0, suns.size()}, std::tuple{64, 1.1, std::size_t{4}}}) {
    for (std::size_t k = 0; k < count; ++k) {
      // suns[2..5] are the hard ones: pole cap neighbour, face edge, cube corner, south pole.
      const auto [x, y] = suns[(k + 2) % suns.size()];
      EnvironmentImage img = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
      for (int c = 0; c < 3; ++c) img.Channel(c)[img.Index(x, y)] = 30000.0f;
      const double source = 30000.0 * PixelSolidAngle(img, x, y);
      const double out = CubemapPower(ResampleToCubemap(img, n, rot))[1];
      const double rel = std::abs(out / source - 1);
      worst = std::max(worst, rel);
      EXPECT_LT(rel, 0.005) << "sun at pixel (" << x << ", " << y << "), n=" << n << ", rotation "
                            << rot;
    }
  }
  std::printf("one-pixel sun: worst relative power error %.2e\n", worst);
}

// The solid angle credited to every texel matches its exact solid angle: this bounds the power
// error of a small sun ANYWHERE in the texel, for lat-long and cube sources, rotated or not.
TEST(EnvmapResample, CreditedSolidAngleMatchesExactTexelSolidAngle) {
  struct Case {
    EnvmapLayout layout;
    int w, h, n;
    double rot;
  };
  for (const Case& c :
       {Case{EnvmapLayout::kLatLong, 1024, 512, 32, 0.0},
        Case{EnvmapLayout::kLatLong, 1024, 512, 32, 0.37},
        Case{EnvmapLayout::kLatLong, 1024, 512, 64, 0.0},
        Case{EnvmapLayout::kLatLong, 1024, 512, 8, 0.0},
        Case{EnvmapLayout::kLatLong, 256, 128, 32, 0.0},
        Case{EnvmapLayout::kLatLong, 64, 32, 16, 0.2}, Case{EnvmapLayout::kCube, 128, 768, 32, 0.0},
        Case{EnvmapLayout::kCube, 128, 768, 32, 0.6}}) {
    const CubemapLayout layout(c.n);
    const std::vector<double> w =
        ResampledTexelSolidAngles(EnvironmentImage::Zero(c.layout, c.w, c.h), c.n, c.rot);
    double worst = 0, sum = 0;
    for (std::size_t t = 0; t < w.size(); ++t) {
      worst = std::max(worst, std::abs(w[t] / layout.TexelSolidAngle(t) - 1));
      sum += w[t];
    }
    std::printf("%s %dx%d -> n=%d rot %.2f: worst |credited/exact - 1| = %.2e\n",
                c.layout == EnvmapLayout::kCube ? "cube" : "lat-long", c.w, c.h, c.n, c.rot, worst);
    EXPECT_NEAR(sum / (4 * kPi), 1.0, 1e-12);
    EXPECT_LT(worst, 0.005);
  }
}

// Cube sources: the sun pixel on a face edge and in a corner.
TEST(EnvmapResample, OnePixelSunKeepsItsPowerFromCube) {
  const int s = 128;
  double worst = 0;
  for (const auto& [x, y] : std::vector<std::pair<int, int>>{
           {0, 0}, {127, 5}, {64, 64}, {3, 200}, {127, 767}, {50, 700}, {77, 4 * s + 31}}) {
    for (double rot : {0.0, 0.6}) {
      EnvironmentImage img = EnvironmentImage::Zero(EnvmapLayout::kCube, s, 6 * s);
      for (int c = 0; c < 3; ++c) img.Channel(c)[img.Index(x, y)] = 1000.0f;
      const double source = 1000.0 * PixelSolidAngle(img, x, y);
      const double out = CubemapPower(ResampleToCubemap(img, 32, rot))[0];
      worst = std::max(worst, std::abs(out / source - 1));
      EXPECT_NEAR(out / source, 1.0, 0.005) << "(" << x << ", " << y << ") rot " << rot;
    }
  }
  std::printf("cube one-pixel sun: worst relative power error %.2e\n", worst);
}

// Texel index of the cubemap rotated by +90° about +Y that shows original texel `src`:
// rotating by R moves the content at R⁻¹d to d. Worked out by hand (docs/conventions.md):
// +X ← +Z (x = n−1−j, y = i), −X ← −Z (n−1−j, i), +Y ← +Y (n−1−j, i), −Y ← −Y (n−1−j, i),
// +Z ← −X (j, i), −Z ← +X (j, i), for rotated texel (face, x = i, y = j).
std::size_t Rotated90Source(const CubemapLayout& l, int face, int i, int j) {
  const int n = l.n();
  switch (face) {
    case 0:
      return l.Index(4, n - 1 - j, i);
    case 1:
      return l.Index(5, n - 1 - j, i);
    case 2:
      return l.Index(2, n - 1 - j, i);
    case 3:
      return l.Index(3, n - 1 - j, i);
    case 4:
      return l.Index(1, j, i);
    default:
      return l.Index(0, j, i);
  }
}

TEST(EnvmapResample, Rotation90IsAFacePermutation) {
  // Period w − 1 = 512 columns, so a quarter turn is exactly 128 columns.
  const int w = 513, h = 257, n = 16;
  SkySunParams sky;
  sky.sun_direction = {0.4, 0.3, -0.7};
  const EnvironmentImage a = SampleEnvironment(EnvmapLayout::kLatLong, w, h, [&](const Vec3& d) {
    std::array<float, 3> v = SkyRadiance(sky, d);
    v[0] *= static_cast<float>(1.0 + 0.3 * d.x);  // break the remaining symmetries
    v[2] *= static_cast<float>(1.0 + 0.2 * d.z * d.y);
    return v;
  });
  // Rotating by +90° about +Y: L'(x) = L(x + (w−1)/4), column w−1 repeating column 0.
  EnvironmentImage b = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const int src = (x + (w - 1) / 4) % (w - 1);
      for (int c = 0; c < 3; ++c) b.Channel(c)[b.Index(x, y)] = a.Channel(c)[a.Index(src, y)];
    }
  }
  const CubemapLayout layout(n);
  const CubemapRgb ca = ResampleToCubemap(a, n);
  const CubemapRgb cb = ResampleToCubemap(b, n);
  const CubemapRgb cr = ResampleToCubemap(a, n, kPi / 2);
  double worst_shift = 0, worst_api = 0;
  for (int face = 0; face < 6; ++face) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const std::size_t t = layout.Index(face, i, j);
        const std::size_t s = Rotated90Source(layout, face, i, j);
        // The hand-written table agrees with rotating the texel centre.
        ASSERT_EQ(layout.TexelOf(RotateAboutY(layout.TexelCenter(t), -kPi / 2)), s);
        for (int c = 0; c < 3; ++c) {
          const double ref = ca.Channel(c)[s];
          worst_shift = std::max(worst_shift, std::abs(cb.Channel(c)[t] / ref - 1));
          worst_api = std::max(worst_api, std::abs(cr.Channel(c)[t] / ref - 1));
        }
      }
    }
  }
  std::printf("90-degree rotation: column shift %.2e, rotation argument %.2e (max rel)\n",
              worst_shift, worst_api);
  EXPECT_LT(worst_shift, 1e-4);
  EXPECT_LT(worst_api, 1e-4);
}

// The same procedural sky stored as a lat-long EXR and as a cube EXR gives the same lighting.
TEST(EnvmapResample, CubeAndLatLongExrAgree) {
  SkySunParams sky;
  sky.sun_direction = {0.5, 0.35, 0.6};
  sky.sun_angular_radius = 0.05;
  const fs::path dir = TempDir();
  WriteEnvironmentExr(MakeSkyWithSun(EnvmapLayout::kLatLong, 1024, 512, sky),
                      (dir / "sky_ll.exr").string());
  WriteEnvironmentExr(MakeSkyWithSun(EnvmapLayout::kCube, 256, 1536, sky),
                      (dir / "sky_cube.exr").string());
  EnvironmentLoadInfo info_ll, info_cube;
  const EnvironmentImage ll = ReadEnvironment((dir / "sky_ll.exr").string(), &info_ll);
  const EnvironmentImage cube = ReadEnvironment((dir / "sky_cube.exr").string(), &info_cube);
  EXPECT_EQ(ll.layout, EnvmapLayout::kLatLong);
  EXPECT_EQ(cube.layout, EnvmapLayout::kCube);
  EXPECT_TRUE(info_ll.layout_from_attribute);
  EXPECT_TRUE(info_cube.layout_from_attribute);
  // Sun power: the disc's closed-form power 2π(1 − cos r)·L_sun.
  const double disc = 2 * kPi * (1 - std::cos(sky.sun_angular_radius));
  for (double rot : {0.0, 0.8}) {
    const int n = 32;
    const CubemapRgb a = ResampleToCubemap(ll, n, rot);
    const CubemapRgb b = ResampleToCubemap(cube, n, rot);
    const CubemapLayout layout(n);
    const Vec3 sun = RotateAboutY(Normalize(sky.sun_direction), rot);
    double worst_sky = 0;
    for (std::size_t t = 0; t < layout.texel_count(); ++t) {
      if (Dot(layout.TexelCenter(t), sun) > std::cos(sky.sun_angular_radius + 0.1)) continue;
      for (int c = 0; c < 3; ++c) {
        worst_sky = std::max(worst_sky, std::abs(double{b.Channel(c)[t]} / a.Channel(c)[t] - 1));
      }
    }
    const std::array<double, 3> pa = CubemapPower(a), pb = CubemapPower(b);
    const std::array<double, 3> sa = EnvironmentPower(ll), sb = EnvironmentPower(cube);
    std::printf(
        "rot %.1f: sky texels max rel diff %.2e; power ll %.5f cube %.5f (sources %.5f "
        "%.5f); sun disc alone %.5f\n",
        rot, worst_sky, pa[0], pb[0], sa[0], sb[0], disc * sky.sun_radiance[0]);
    EXPECT_LT(worst_sky, 5e-3);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(pa[c] / pb[c], 1.0, 0.005);
      EXPECT_NEAR(pa[c] / sa[c], 1.0, 1e-4);
      EXPECT_NEAR(pb[c] / sb[c], 1.0, 1e-4);
    }
  }
  fs::remove_all(dir);
}

// ---- Readers: layout, NaN/Inf, negatives, corrupt files ----

TEST(EnvmapRead, LayoutInferredFromAspectWithoutAttribute) {
  const fs::path dir = TempDir();
  WriteExrNoAttribute(Constant(EnvmapLayout::kLatLong, 32, 16, 1), (dir / "ll.exr").string());
  WriteExrNoAttribute(Constant(EnvmapLayout::kCube, 8, 48, 1), (dir / "cube.exr").string());
  WriteExrNoAttribute(Constant(EnvmapLayout::kLatLong, 30, 20, 1), (dir / "odd.exr").string());
  EnvironmentLoadInfo info;
  info.layout_from_attribute = true;
  EXPECT_EQ(ReadEnvironment((dir / "ll.exr").string(), &info).layout, EnvmapLayout::kLatLong);
  EXPECT_FALSE(info.layout_from_attribute);
  EXPECT_EQ(ReadEnvironment((dir / "cube.exr").string(), &info).layout, EnvmapLayout::kCube);
  try {
    ReadEnvironment((dir / "odd.exr").string());
    FAIL() << "a 3:2 image without envmap attribute must be rejected";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("odd.exr"), std::string::npos) << e.what();
  }
  // With the attribute, a cube of the wrong shape is rejected too.
  WriteEnvironmentExr(Constant(EnvmapLayout::kCube, 8, 40, 1), (dir / "badcube.exr").string());
  EXPECT_THROW(ReadEnvironment((dir / "badcube.exr").string()), InputError);
  fs::remove_all(dir);
}

TEST(EnvmapRead, NanAndInfRejectedWithThePixelNamed) {
  const fs::path dir = TempDir();
  EnvironmentImage img = Constant(EnvmapLayout::kLatLong, 32, 16, 1);
  img.g[img.Index(5, 3)] = std::numeric_limits<float>::quiet_NaN();
  const std::string path = (dir / "nan.exr").string();
  WriteEnvironmentExr(img, path);
  try {
    ReadEnvironment(path);
    FAIL() << "NaN must be rejected";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find("NaN at pixel (x=5, y=3, channel G)"), std::string::npos) << msg;
  }
  img.g[img.Index(5, 3)] = 1;
  img.b[img.Index(31, 15)] = std::numeric_limits<float>::infinity();
  WriteEnvironmentExr(img, path);
  try {
    ReadEnvironment(path);
    FAIL() << "Inf must be rejected";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("Inf at pixel (x=31, y=15, channel B)"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

TEST(EnvmapRead, NegativesClampedAndCounted) {
  const fs::path dir = TempDir();
  EnvironmentImage img = Constant(EnvmapLayout::kLatLong, 32, 16, 1);
  img.r[img.Index(1, 1)] = -0.004f;
  img.g[img.Index(2, 9)] = -0.001f;
  img.b[img.Index(30, 15)] = -0.002f;
  const std::string path = (dir / "neg.exr").string();
  WriteEnvironmentExr(img, path);
  EnvironmentLoadInfo info;
  const EnvironmentImage back = ReadEnvironment(path, &info);
  EXPECT_EQ(info.negatives_clamped, 3u);
  EXPECT_NEAR(info.most_negative, -0.004, 1e-7);
  EXPECT_EQ(back.r[img.Index(1, 1)], 0.0f);
  EXPECT_EQ(back.g[img.Index(2, 9)], 0.0f);
  EXPECT_EQ(back.b[img.Index(30, 15)], 0.0f);
  EXPECT_EQ(back.r[img.Index(2, 9)], 1.0f);
  fs::remove_all(dir);
}

TEST(EnvmapRead, TruncatedAndCorruptFilesNameTheFile) {
  const fs::path dir = TempDir();
  SkySunParams sky;
  const std::string good = (dir / "good.exr").string();
  WriteEnvironmentExr(MakeSkyWithSun(EnvmapLayout::kLatLong, 128, 64, sky), good);
  const std::uintmax_t size = fs::file_size(good);
  for (std::uintmax_t keep : {size / 2, size - 10, std::uintmax_t{20}}) {
    const std::string cut = (dir / ("cut" + std::to_string(keep) + ".exr")).string();
    fs::copy_file(good, cut);
    fs::resize_file(cut, keep);
    try {
      ReadEnvironment(cut);
      FAIL() << "truncated file accepted: " << keep << " of " << size << " bytes";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(cut), std::string::npos) << e.what();
    }
  }
  const std::string junk = (dir / "junk.exr").string();
  std::ofstream(junk) << "not an image at all";
  EXPECT_THROW(ReadEnvironment(junk), InputError);
  EXPECT_THROW(ReadEnvironment((dir / "missing.exr").string()), InputError);
  fs::remove_all(dir);
}

// ---- Radiance .hdr ----

TEST(EnvmapHdr, RoundTripsRleAndFlat) {
  const fs::path dir = TempDir();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> mag(-12.f, 14.f);
  EnvironmentImage img = EnvironmentImage::Zero(EnvmapLayout::kLatLong, 64, 32);
  for (std::size_t i = 0; i < img.PixelCount(); ++i) {
    for (int c = 0; c < 3; ++c) img.Channel(c)[i] = std::exp2(mag(rng));
  }
  for (std::size_t i = 0; i < 64; ++i) img.r[i] = img.g[i] = img.b[i] = 0.0f;    // a run of zeros
  for (std::size_t i = 64; i < 128; ++i) img.r[i] = img.g[i] = img.b[i] = 3.0f;  // a long run
  for (bool rle : {true, false}) {
    const std::string path = (dir / (rle ? "rle.hdr" : "flat.hdr")).string();
    WriteRadianceHdr(img, path, rle);
    EnvironmentLoadInfo info;
    const EnvironmentImage back = ReadEnvironment(path, &info);
    ASSERT_EQ(back.width, 64);
    ASSERT_EQ(back.height, 32);
    EXPECT_EQ(back.layout, EnvmapLayout::kLatLong);
    EXPECT_FALSE(info.layout_from_attribute);
    for (std::size_t i = 0; i < img.PixelCount(); ++i) {
      const float m = std::max({img.r[i], img.g[i], img.b[i]});
      for (int c = 0; c < 3; ++c) {
        ASSERT_NEAR(back.Channel(c)[i], img.Channel(c)[i], m / 256.0f) << i << " rle " << rle;
      }
    }
  }
  EXPECT_LT(fs::file_size(dir / "rle.hdr"), fs::file_size(dir / "flat.hdr"));
  fs::remove_all(dir);
}

TEST(EnvmapHdr, OldStyleRepeatRunsAreRead) {
  const fs::path dir = TempDir();
  const std::string path = (dir / "old.hdr").string();
  std::string data = "#?RGBE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n";
  const unsigned char px[] = {128, 64, 32, 129,  // (c + 0.5)·2^(129−136)
                              1,   1,  1,  3,    // repeat ×3: rest of row 0
                              0,   0,  0,  0,   10, 20, 30, 130, 1, 1, 1, 2};
  data.append(reinterpret_cast<const char*>(px), sizeof(px));
  std::ofstream(path, std::ios::binary) << data;
  const EnvironmentImage img = ReadEnvironment(path);
  EXPECT_NEAR(img.r[3], (128 + 0.5) / 128.0, 1e-6);
  EXPECT_NEAR(img.b[2], (32 + 0.5) / 128.0, 1e-6);
  EXPECT_EQ(img.r[4], 0.0f);
  EXPECT_NEAR(img.g[7], (20 + 0.5) / 64.0, 1e-6);
  fs::remove_all(dir);
}

TEST(EnvmapHdr, CorruptFilesThrowNamingTheFile) {
  const fs::path dir = TempDir();
  EnvironmentImage img = Constant(EnvmapLayout::kLatLong, 32, 16, 1.5f);
  const std::string good = (dir / "good.hdr").string();
  WriteRadianceHdr(img, good, true);
  std::ifstream in(good, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto expect_rejected = [&](const std::string& name, const std::string& content) {
    const std::string path = (dir / name).string();
    std::ofstream(path, std::ios::binary) << content;
    try {
      ReadEnvironment(path);
      FAIL() << name << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  };
  expect_rejected("truncated.hdr", bytes.substr(0, bytes.size() - 7));
  expect_rejected("noheader.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n");
  expect_rejected("xyze.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 16 +X 32\n");
  expect_rejected("huge.hdr", "#?RADIANCE\n\n-Y 2000000000 +X 4000000000\n");
  expect_rejected("transposed.hdr", "#?RADIANCE\n\n+X 32 -Y 16\n");
  std::string bad_run = "#?RADIANCE\n\n-Y 16 +X 32\n";
  bad_run += std::string("\x02\x02\x00\x20", 4) + std::string("\xff\x01", 2);  // run of 127 > 32
  expect_rejected("badrun.hdr", bad_run);
  std::string bad_width = "#?RADIANCE\n\n-Y 16 +X 32\n" + std::string("\x02\x02\x00\x21", 4);
  expect_rejected("badwidth.hdr", bad_width);
  fs::remove_all(dir);
}

// The reader is safe on untrusted input: random byte corruptions and truncations of a valid
// file either read (finite, non-negative pixels) or throw InputError; never crash or hang.
TEST(EnvmapHdr, RandomCorruptionsReadOrThrowInputError) {
  const fs::path dir = TempDir();
  SkySunParams sky;
  const std::string good = (dir / "good.hdr").string();
  WriteRadianceHdr(MakeSkyWithSun(EnvmapLayout::kLatLong, 64, 32, sky), good, true);
  std::ifstream in(good, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::mt19937 rng(11);
  int read = 0, rejected = 0;
  const std::string path = (dir / "mutant.hdr").string();
  for (int trial = 0; trial < 300; ++trial) {
    std::string m = bytes;
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits; ++e) {
      m[rng() % m.size()] = static_cast<char>(rng() & 255);
    }
    if (trial % 3 == 0) m.resize(rng() % m.size());
    std::ofstream(path, std::ios::binary | std::ios::trunc) << m;
    try {
      const EnvironmentImage img = ReadEnvironment(path);
      for (int c = 0; c < 3; ++c) {
        for (float v : img.Channel(c)) ASSERT_TRUE(std::isfinite(v) && v >= 0);
      }
      ++read;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      ++rejected;
    }
  }
  EXPECT_GT(rejected, 0);
  std::printf("corrupted .hdr: %d read, %d rejected\n", read, rejected);
  fs::remove_all(dir);
}

// ---- Real data ----

TEST(EnvmapReal, SunriseLoadsAndKeepsItsPower) {
  const std::string path = std::string(PRT_DATA_DIR) + "/envmaps/sunrise.exr";
  if (!fs::exists(path)) GTEST_SKIP() << path << " absent (run scripts/install-deps.sh)";
  EnvironmentLoadInfo info;
  const EnvironmentImage env = ReadEnvironment(path, &info);
  EXPECT_EQ(env.layout, EnvmapLayout::kLatLong);
  EXPECT_EQ(env.width, 1024);
  EXPECT_EQ(env.height, 512);
  for (int c = 0; c < 3; ++c) {
    for (float v : env.Channel(c)) ASSERT_TRUE(std::isfinite(v) && v >= 0);
  }
  // Direct lat-long sum Σ L·cos(lat)·Δθ·Δφ (trapezoid rule on OpenEXR's pixel grid: pixel
  // centres at both ends of each range carry half weight).
  const double dth = kPi / (env.height - 1), dph = 2 * kPi / (env.width - 1);
  std::array<double, 3> direct{0, 0, 0};
  for (int y = 0; y < env.height; ++y) {
    const double lat = kPi * (0.5 - static_cast<double>(y) / (env.height - 1));
    const double wy = (y == 0 || y == env.height - 1) ? 0.5 : 1.0;
    for (int x = 0; x < env.width; ++x) {
      const double wx = (x == 0 || x == env.width - 1) ? 0.5 : 1.0;
      for (int c = 0; c < 3; ++c) {
        direct[c] += env.Channel(c)[env.Index(x, y)] * std::cos(lat) * dth * dph * wx * wy;
      }
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  const CubemapRgb cube = ResampleToCubemap(env, 32);
  const auto t1 = std::chrono::steady_clock::now();
  const std::array<double, 3> p = CubemapPower(cube);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(p[c] / direct[c], 1.0, 0.005) << "channel " << c;
  // A rotated environment keeps its power too.
  const std::array<double, 3> pr = CubemapPower(ResampleToCubemap(env, 32, 1.3));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(pr[c] / direct[c], 1.0, 0.005) << "channel " << c;
  std::printf(
      "sunrise: %zu negatives clamped (min %.4g); power R %.4f vs direct %.4f; "
      "resample 1024x512 -> n=32 in %.1f ms\n",
      info.negatives_clamped, info.most_negative, p[0], direct[0],
      std::chrono::duration<double, std::milli>(t1 - t0).count());
}

TEST(EnvmapReal, GraceHdrLoads) {
  const std::string path = std::string(PRT_SHARED_DATA_DIR) + "/envmaps/debevec_grace_256.hdr";
  if (!fs::exists(path)) GTEST_SKIP() << path << " absent";
  const EnvironmentImage env = ReadEnvironment(path);
  EXPECT_EQ(env.layout, EnvmapLayout::kLatLong);
  EXPECT_EQ(env.width, 256);
  EXPECT_EQ(env.height, 128);
  float mx = 0;
  for (float v : env.r) mx = std::max(mx, v);
  EXPECT_GT(mx, 1000.0f);  // the cathedral lamps (README: max 3,504)
  EXPECT_LT(mx, 4000.0f);
  const std::array<double, 3> src = EnvironmentPower(env);
  const std::array<double, 3> out = CubemapPower(ResampleToCubemap(env, 32));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(out[c] / src[c], 1.0, 0.005);
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// A map with structure in longitude and latitude, and with `sun` a small sun (3×3 pixels).
EnvironmentImage StructuredMap(int w, int h, bool sun) {
  EnvironmentImage img = EnvironmentImage::Zero(EnvmapLayout::kLatLong, w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double phi = 2 * std::numbers::pi * x / (w - 1), th = std::numbers::pi * y / (h - 1);
      const double v = 1.0 + 0.6 * std::sin(phi) * std::sin(th) + 0.3 * std::cos(3 * phi);
      for (int c = 0; c < 3; ++c)
        img.Channel(c)[img.Index(x, y)] = static_cast<float>(v * (1 + 0.2 * c));
    }
  if (sun)
    for (int y = h / 3; y < h / 3 + 3; ++y)
      for (int x = w / 5; x < w / 5 + 3; ++x)
        for (int c = 0; c < 3; ++c) img.Channel(c)[img.Index(x, y)] = 400.0f;
  return img;
}

double RelRms(const CubemapRgb& got, const CubemapRgb& want) {
  double num = 0, den = 0;
  for (int c = 0; c < 3; ++c)
    for (std::size_t t = 0; t < want.TexelCount(); ++t) {
      const double d = got.Channel(c)[t] - want.Channel(c)[t];
      num += d * d;
      den += static_cast<double>(want.Channel(c)[t]) * want.Channel(c)[t];
    }
  return std::sqrt(num / den);
}

// The periodic grid's resampling (the preview of interactive rotation) against the exact
// ResampleToCubemap of the full map: a constant map stays constant at any angle; a smooth map is
// within 0.3 % per texel (RMS) at whole-cell and fractional angles of both signs, where the
// rotation's sense being wrong would cost over 10 %; a small sun keeps its power at every angle
// (its split between texels is the grid's: a sun smaller than a cell is smeared over cells, so
// near a texel edge a texel may differ by a share of it, which the relit radiance averages).
TEST(EnvmapResample, PeriodicGridRotationsAgreeWithTheExactResampling) {
  const int n = 8;
  {
    const EnvironmentImage c = Constant(EnvmapLayout::kLatLong, 96, 48, 2.0f);
    const PeriodicLatLongResampler r(c, n, 16 * n);
    for (double a : {0.0, 0.37, -2.9}) {
      const CubemapRgb cube = r.Resample(a);
      for (int ch = 0; ch < 3; ++ch)
        for (float v : cube.Channel(ch)) ASSERT_NEAR(v, 2.0 * (1 + 0.5 * ch), 1e-5);
    }
    EXPECT_GT(r.weight_count(), 16u * n * 8u * n);
  }
  const double cell = 2 * std::numbers::pi / (16 * n);
  const std::vector<double> angles = {0.0, 5 * cell, -17 * cell, 0.3, -1.1, 2.5 * cell, 7 * cell};
  const EnvironmentImage smooth = StructuredMap(512, 256, false);
  const PeriodicLatLongResampler r(smooth, n, 16 * n);
  for (double a : angles) {
    const CubemapRgb exact = ResampleToCubemap(smooth, n, a);
    const double err = RelRms(r.Resample(a), exact);
    EXPECT_LT(err, 0.003) << a;
    if (a != 0.0) {
      EXPECT_GT(RelRms(r.Resample(-a), exact), 0.1) << a;
    }
    std::printf("rotation %+.3f: periodic grid vs exact %.3f %% RMS\n", a, 100 * err);
  }
  const EnvironmentImage sunny = StructuredMap(512, 256, true);
  const PeriodicLatLongResampler s(sunny, n, 16 * n);
  const double power = CubemapPower(ResampleToCubemap(sunny, n))[1];
  for (double a : angles) EXPECT_NEAR(CubemapPower(s.Resample(a))[1] / power, 1.0, 0.005) << a;
  EXPECT_THROW(PeriodicLatLongResampler(smooth, n, 7), std::invalid_argument);
  EXPECT_THROW(r.Resample(std::nan("")), std::invalid_argument);
}

}  // namespace
}  // namespace prt
