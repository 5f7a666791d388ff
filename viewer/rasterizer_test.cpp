// Rasteriser: exact coverage of a known triangle (top-left rule on a shared edge), z-test,
// perspective-correct interpolation of a linear function (also across near-plane clipping),
// background from a cubemap.
#include "viewer/rasterizer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "viewer/environment_background.h"
#include "viewer/rasterizer_reference.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/envmap.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

// Eye at the origin looking down −Z with a 90° vertical fov on an 8×8 image: the world point
// (X, Y, −1) lands at pixel coordinates ((X + 1)·4, (1 − Y)·4).
Camera EightByEight() {
  Camera c;
  c.eye = {0, 0, 0};
  c.target = {0, 0, -1};
  c.up = {0, 1, 0};
  c.fov_deg = 90.0;
  c.width = 8;
  c.height = 8;
  return c;
}

Vec3 AtPixel(double px, double py, double depth) {
  return {(px / 4.0 - 1.0) * depth, (1.0 - py / 4.0) * depth, -depth};
}

TEST(RasterizerTest, TriangleCoversExactlyTheKnownPixels) {
  const Camera cam = EightByEight();
  // Screen triangle (0,0)-(8.5,0)-(0,8.5): pixel centre (x + ½, y + ½) is inside exactly when
  // x + y + 1 < 8.5, i.e. x + y ≤ 7.
  const std::vector<Vec3> p = {AtPixel(0, 0, 1), AtPixel(8.5, 0, 1), AtPixel(0, 8.5, 1)};
  const std::vector<std::array<uint32_t, 3>> one = {{0, 1, 2}};
  const std::vector<float> rgb(9, 1.0f);
  const RasterImage a = RasterizeTriangles(cam, p, one, rgb);
  for (int y = 0; y < 8; ++y) {
    for (int x = 0; x < 8; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * 8 + x;
      EXPECT_EQ(a.triangle[i], x + y <= 7 ? 0 : -1) << x << "," << y;
      EXPECT_EQ(a.rgb[3 * i], x + y <= 7 ? 1.0f : 0.0f);
      if (x + y <= 7) {
        EXPECT_NEAR(a.depth[i], 1.0f, 1e-6);
      }
    }
  }
}

TEST(RasterizerTest, SharedEdgeThroughPixelCentresIsDrawnOnce) {
  const Camera cam = EightByEight();
  // Two triangles (0,0)-(8,0)-(0,8) and (8,0)-(8,8)-(0,8) tile the image; their shared diagonal
  // passes through the centres of the pixels with x + y = 7. Every pixel belongs to exactly one
  // of them (edge functions are evaluated in a canonical order, ties go by the top-left rule).
  const std::vector<Vec3> p = {AtPixel(0, 0, 1), AtPixel(8, 0, 1), AtPixel(0, 8, 1),
                               AtPixel(8, 8, 1)};
  const std::vector<float> rgb(12, 1.0f);
  for (const auto& tris : {std::vector<std::array<uint32_t, 3>>{{0, 1, 2}, {1, 3, 2}},
                           std::vector<std::array<uint32_t, 3>>{{0, 2, 1}, {1, 2, 3}}}) {
    const RasterImage first = RasterizeTriangles(cam, p, std::span(tris.data(), 1), rgb);
    const RasterImage second = RasterizeTriangles(cam, p, std::span(tris.data() + 1, 1), rgb);
    for (int y = 0; y < 8; ++y) {
      for (int x = 0; x < 8; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * 8 + x;
        const int covered = (first.triangle[i] >= 0) + (second.triangle[i] >= 0);
        EXPECT_EQ(covered, 1) << x << "," << y;
        if (x + y <= 6) {
          EXPECT_GE(first.triangle[i], 0);
        }
        if (x + y >= 8) {
          EXPECT_GE(second.triangle[i], 0);
        }
      }
    }
  }
}

TEST(RasterizerTest, NearerTriangleWinsWhateverTheOrder) {
  const Camera cam = EightByEight();
  // A far full-screen quad (depth 3, colour 1) and a near triangle (depth 2, colour 2) covering
  // the top-left half; then the same in the other drawing order.
  std::vector<Vec3> p = {AtPixel(-1, -1, 3), AtPixel(9, -1, 3), AtPixel(-1, 9, 3), AtPixel(9, 9, 3),
                         AtPixel(0, 0, 2),   AtPixel(8, 0, 2),  AtPixel(0, 8, 2)};
  std::vector<float> rgb(21, 1.0f);
  for (int k = 12; k < 21; ++k) rgb[k] = 2.0f;
  for (bool near_first : {false, true}) {
    std::vector<std::array<uint32_t, 3>> tris = {{0, 1, 2}, {1, 3, 2}, {4, 5, 6}};
    if (near_first) std::rotate(tris.begin(), tris.begin() + 2, tris.end());
    const RasterImage img = RasterizeTriangles(cam, p, tris, rgb);
    for (int y = 0; y < 8; ++y) {
      for (int x = 0; x < 8; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * 8 + x;
        const bool near = x + y <= 6;
        EXPECT_EQ(img.rgb[3 * i + 1], near ? 2.0f : 1.0f) << x << "," << y;
        EXPECT_NEAR(img.depth[i], near ? 2.0f : 3.0f, 1e-5);
      }
    }
  }
}

// A linear function of world position f(P) = a·P + b given at the vertices must come out, at
// every pixel centre, as f at the point where that pixel's ray meets the triangle: perspective-
// correct interpolation is exact for functions linear on the triangle. One triangle is tilted
// in depth; the other reaches behind the camera and is clipped by the near plane.
TEST(RasterizerTest, InterpolatesLinearFunctionsExactlyAtPixelCentres) {
  Camera cam;
  cam.eye = {0.3, 1.2, 2.5};
  cam.target = {0, 0, 0};
  cam.up = {0, 1, 0};
  cam.fov_deg = 50;
  cam.width = 64;
  cam.height = 48;
  const CameraProjection proj(cam);
  const std::vector<Vec3> p = {{-1.0, -0.2, -1.5},
                               {1.2, 0.1, 0.4},
                               {-0.3, 0.9, 0.8},
                               // ground-like triangle running from far away to behind the eye
                               {-3.0, -0.5, -6.0},
                               {3.0, -0.5, -6.0},
                               {0.3, -0.5, 6.0}};
  const auto f = [](const Vec3& q, int c) {
    return 0.5 + (c + 1) * 0.3 * q.x - 0.2 * q.y + (c == 2 ? 0.7 : -0.1) * q.z;
  };
  std::vector<float> rgb;
  for (const Vec3& q : p) {
    for (int c = 0; c < 3; ++c) rgb.push_back(static_cast<float>(f(q, c)));
  }
  const std::vector<std::array<uint32_t, 3>> tris = {{0, 1, 2}, {3, 4, 5}};
  const RasterImage img = RasterizeTriangles(cam, p, tris, rgb);
  int checked[2] = {0, 0};
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * cam.width + x;
      const int t = img.triangle[i];
      if (t < 0) continue;
      const Vec3& a = p[tris[t][0]];
      const Vec3 nrm = Cross(p[tris[t][1]] - a, p[tris[t][2]] - a);
      const Vec3 d = proj.PixelDirection(x + 0.5, y + 0.5);
      const double s = Dot(a - cam.eye, nrm) / Dot(d, nrm);
      const Vec3 hit = cam.eye + d * s;
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(img.rgb[3 * i + c], f(hit, c), 2e-5 * (1 + std::abs(f(hit, c))))
            << "pixel " << x << "," << y << " triangle " << t;
      }
      EXPECT_NEAR(img.depth[i], Dot(hit - cam.eye, proj.forward()), 1e-5 * s);
      ++checked[t];
    }
  }
  EXPECT_GT(checked[0], 100);
  EXPECT_GT(checked[1], 100);
}

TEST(RasterizerTest, BackgroundShowsTheEnvironmentThroughTheCamera) {
  // Each face of a 2×2 cubemap holds its face number: an uncovered pixel shows the face its
  // central ray points into.
  CubemapRgb cube;
  cube.n = 2;
  for (int c = 0; c < 3; ++c) {
    cube.Channel(c).resize(24);
    for (int j = 0; j < 24; ++j) cube.Channel(c)[j] = static_cast<float>(j / 4);
  }
  Camera cam = EightByEight();
  cam.fov_deg = 120;
  RasterOptions options;
  options.background = CubemapBackground(cube);
  const RasterImage img = RasterizeTriangles(cam, {}, {}, {}, options);
  const CameraProjection proj(cam);
  for (int y = 0; y < 8; ++y) {
    for (int x = 0; x < 8; ++x) {
      int face;
      double u, v;
      CubemapLayout::DirectionToFace(proj.PixelDirection(x + 0.5, y + 0.5), face, u, v);
      EXPECT_EQ(img.rgb[3 * (static_cast<std::size_t>(y) * 8 + x)], float(face));
      EXPECT_EQ(img.depth[static_cast<std::size_t>(y) * 8 + x], std::numeric_limits<float>::max());
    }
  }
  EXPECT_EQ(img.rgb[3 * (4 * 8 + 4)], 5.0f);  // straight ahead is −Z
}

// No pixel is blacked out silently (docs/viewer.md, "NaN and Inf"): a NaN/Inf vertex colour or
// background value is an error naming the vertex or pixel; vertex colours at the top of the float
// range interpolate to finite pixels (the interpolation is a convex combination).
TEST(RasterizerTest, NonFiniteColoursAreErrorsAndFloatMaxStaysFinite) {
  const Camera cam = EightByEight();
  const std::vector<Vec3> p = {AtPixel(0, 0, 1), AtPixel(8.5, 0, 1), AtPixel(0, 8.5, 4)};
  const std::vector<std::array<uint32_t, 3>> one = {{0, 1, 2}};
  const float big = std::numeric_limits<float>::max();
  const std::vector<float> top = {big, -big, big, big, big, -big, big, big, big};
  const RasterImage img = RasterizeTriangles(cam, p, one, top);
  int drawn = 0;
  for (std::size_t i = 0; i < img.triangle.size(); ++i) {
    if (img.triangle[i] < 0) continue;
    ++drawn;
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(img.rgb[3 * i + c])) << i;
    EXPECT_EQ(img.rgb[3 * i], big);
  }
  EXPECT_GT(drawn, 20);
  std::vector<float> bad(9, 1.0f);
  bad[4] = std::nanf("");
  try {
    RasterizeTriangles(cam, p, one, bad);
    FAIL() << "a NaN colour was drawn";
  } catch (const NumericalError& e) {
    EXPECT_EQ(std::string(e.what()), "RasterizeTriangles: vertex 1 colour (channel 1) is NaN");
  }
  RasterOptions options;
  options.background = [](const Vec3& d) {
    return Rgb{1.0f, d.x > 0.5 ? std::numeric_limits<float>::infinity() : 0.5f, 1.0f};
  };
  EXPECT_THROW(RasterizeTriangles(cam, {}, {}, {}, options), NumericalError);
  CubemapRgb cube;
  cube.n = 1;
  for (int c = 0; c < 3; ++c) cube.Channel(c).assign(6, 1.0f);
  cube.g[3] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(CubemapBackground(cube), NumericalError);
}

// The tiled rasteriser against the straightforward one it replaced (rasterizer_reference.h) on
// random scenes: the same visible triangle and bitwise the same depth and colour at every
// covered pixel; background pixels within 1e-6 relative (EnvironmentBackground's batch uses
// libmvec's atan2, within 4 ulp of std::atan2; the cubemap background is bitwise); one pixel at
// a time (RasterOptions::scalar) and on one or two threads alike.
struct RandomScene {
  Camera camera;
  std::vector<Vec3> positions;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<float> rgb;
};

RandomScene MakeRandomScene(unsigned seed, int width, int height) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<float> colour(0.0f, 4.0f);
  RandomScene s;
  s.camera.eye = {0.2, 0.3, 3.0};
  s.camera.target = {0, 0, 0};
  s.camera.up = {0, 1, 0};
  s.camera.fov_deg = 55;
  s.camera.width = width;
  s.camera.height = height;
  // A mesh-like grid of small triangles sharing edges (many pixel centres on shared edges:
  // vertices on a lattice of the pixel size seen from the camera), big triangles, slivers, and
  // triangles that reach behind the eye (near clipping).
  const int g = 24;
  for (int j = 0; j <= g; ++j)
    for (int i = 0; i <= g; ++i)
      s.positions.push_back({-1.5 + 3.0 * i / g, -1.2 + 2.4 * j / g, -0.3 * std::sin(i + j)});
  for (int j = 0; j < g; ++j)
    for (int i = 0; i < g; ++i) {
      const auto v = static_cast<uint32_t>(j * (g + 1) + i);
      s.triangles.push_back({v, v + 1, v + g + 1});
      s.triangles.push_back({v + 1, v + g + 2, v + g + 1});
    }
  for (int k = 0; k < 300; ++k) {
    const auto base = static_cast<uint32_t>(s.positions.size());
    const Vec3 c{1.5 * u(rng), 1.5 * u(rng), 1.5 * u(rng)};
    const double r = k % 10 == 0 ? 2.5 : 0.05 + 0.3 * std::abs(u(rng));
    for (int m = 0; m < 3; ++m) s.positions.push_back(c + Vec3{r * u(rng), r * u(rng), r * u(rng)});
    if (k % 25 == 0) s.positions.back().z = 4.0 + 3.0 * std::abs(u(rng));  // behind the eye
    if (k % 37 == 0) s.positions.back() = s.positions[base];               // degenerate
    s.triangles.push_back({base, base + 1, base + 2});
  }
  for (std::size_t i = 0; i < 3 * s.positions.size(); ++i) s.rgb.push_back(colour(rng));
  return s;
}

void ExpectSamePicture(const RasterImage& want, const RasterImage& got, double background_tol,
                       const std::string& what) {
  ASSERT_EQ(want.width, got.width);
  ASSERT_EQ(want.height, got.height);
  int covered = 0;
  for (std::size_t p = 0; p < want.triangle.size(); ++p) {
    ASSERT_EQ(want.triangle[p], got.triangle[p]) << what << ": pixel " << p;
    ASSERT_EQ(want.depth[p], got.depth[p]) << what << ": pixel " << p;
    covered += want.triangle[p] >= 0;
    for (int c = 0; c < 3; ++c) {
      const float a = want.rgb[3 * p + c], b = got.rgb[3 * p + c];
      if (want.triangle[p] >= 0 || background_tol == 0) {
        ASSERT_EQ(a, b) << what << ": pixel " << p << " channel " << c;
      } else {
        ASSERT_NEAR(a, b, background_tol * std::abs(a)) << what << ": pixel " << p;
      }
    }
  }
  EXPECT_GT(covered, 0) << what;
}

TEST(RasterizerTest, MatchesTheStraightforwardRasteriserPixelForPixel) {
  EnvironmentImage env = EnvironmentImage::Zero(EnvmapLayout::kLatLong, 64, 32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 64; ++x) {
      const std::size_t i = env.Index(x, y);
      env.r[i] = 1.0f + static_cast<float>((x * 7 + y * 3) % 11);
      env.g[i] = 0.5f + 0.25f * static_cast<float>(y);
      env.b[i] = x == 40 && y == 10 ? 1000.0f : 0.1f;  // a sun: large contrast between pixels
    }
  const auto lookup = std::make_shared<const EnvironmentLookup>(env);
  CubemapRgb cube;
  cube.n = 2;
  for (int c = 0; c < 3; ++c) {
    cube.Channel(c).resize(24);
    for (int j = 0; j < 24; ++j) cube.Channel(c)[j] = static_cast<float>(j + c);
  }
  const std::pair<int, int> sizes[] = {{160, 120}, {203, 77}, {64, 32}, {7, 5}};
  unsigned seed = 1;
  for (const auto& [w, h] : sizes) {
    for (int bg = 0; bg < 3; ++bg) {
      const RandomScene s = MakeRandomScene(seed++, w, h);
      RasterOptions options;
      if (bg == 1) options.background = CubemapBackground(cube);
      if (bg == 2) options.background = EnvironmentBackground(lookup, 0.7);
      const double tol = bg == 2 ? 1e-6 : 0.0;
      const std::string what =
          std::to_string(w) + "x" + std::to_string(h) + " background " + std::to_string(bg);
      const RasterImage want =
          RasterizeTrianglesReference(s.camera, s.positions, s.triangles, s.rgb, options);
      ExpectSamePicture(
          want, RasterizeTriangles(s.camera, s.positions, s.triangles, s.rgb, options), tol, what);
      RasterOptions scalar = options;
      scalar.scalar = true;
      ExpectSamePicture(want, RasterizeTriangles(s.camera, s.positions, s.triangles, s.rgb, scalar),
                        tol, what + " scalar");
      for (int threads : {1, 2}) {
        tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
        ExpectSamePicture(want,
                          RasterizeTriangles(s.camera, s.positions, s.triangles, s.rgb, options),
                          tol, what + " threads " + std::to_string(threads));
      }
    }
  }
}

// A background that is not finite names the first such pixel in row-major order, whatever the
// tiling and the thread count.
TEST(RasterizerTest, NonFiniteBackgroundNamesTheFirstPixel) {
  Camera cam = EightByEight();
  cam.width = 150;
  cam.height = 90;
  const CameraProjection proj(cam);
  RasterOptions options;
  options.background = [](const Vec3& d) {
    return Rgb{1.0f, d.x > 0.3 && d.y < -0.2 ? std::nanf("") : 0.5f, 1.0f};
  };
  std::string expected;
  for (int y = 0; y < cam.height && expected.empty(); ++y)
    for (int x = 0; x < cam.width && expected.empty(); ++x) {
      const Vec3 d = proj.PixelDirection(x + 0.5, y + 0.5);
      if (d.x > 0.3 && d.y < -0.2)
        expected = "RasterizeTriangles: the background of pixel (x=" + std::to_string(x) +
                   ", y=" + std::to_string(y) + ") is not finite";
    }
  ASSERT_FALSE(expected.empty());
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    try {
      RasterizeTriangles(cam, {}, {}, {}, options);
      FAIL() << "a NaN background was drawn";
    } catch (const NumericalError& e) {
      EXPECT_EQ(std::string(e.what()), expected);
    }
  }
}

TEST(RasterizerTest, RejectsBadInput) {
  const Camera cam = EightByEight();
  const std::vector<Vec3> p = {{0, 0, -1}, {1, 0, -1}, {0, 1, -1}};
  const std::vector<std::array<uint32_t, 3>> bad = {{0, 1, 3}};
  EXPECT_THROW(RasterizeTriangles(cam, p, bad, std::vector<float>(9, 0.f)), std::invalid_argument);
  const std::vector<std::array<uint32_t, 3>> good = {{0, 1, 2}};
  EXPECT_THROW(RasterizeTriangles(cam, p, good, std::vector<float>(8, 0.f)), std::invalid_argument);
  Camera degenerate = cam;
  degenerate.target = degenerate.eye;
  EXPECT_THROW(CameraProjection{degenerate}, std::invalid_argument);
}

}  // namespace
}  // namespace prt
