// Rasteriser: exact coverage of a known triangle (top-left rule on a shared edge), z-test,
// perspective-correct interpolation of a linear function (also across near-plane clipping),
// background from a cubemap.
#include "viewer/rasterizer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

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
