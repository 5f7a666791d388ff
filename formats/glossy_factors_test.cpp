// formats/glossy_factors.h: the equal-area map (inverse, area), the frame, bilinear lookups and
// run/glossy.prtf on hostile bytes.
#include "formats/glossy_factors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <numbers>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {
namespace {

TEST(GlossyFactors, SquareAndHemisphereAreInverse) {
  for (int y = 0; y < 37; ++y)
    for (int x = 0; x < 37; ++x) {
      const double u = (x + 0.3) / 37, v = (y + 0.6) / 37;
      const Vec3 d = HemisphereFromSquare(u, v);
      EXPECT_NEAR(Length(d), 1.0, 1e-12);
      EXPECT_GE(d.z, 0.0);
      double u2, v2;
      SquareFromHemisphere(d, u2, v2);
      EXPECT_NEAR(u2, u, 1e-9) << x << " " << y;
      EXPECT_NEAR(v2, v, 1e-9) << x << " " << y;
    }
}

// Equal area: the solid angle of a cell (by its four corners' spherical quadrilateral, split
// into fine sub-cells) is 2π/n² for every cell.
TEST(GlossyFactors, EveryCellHasTheSameSolidAngle) {
  const int n = 8, sub = 24;
  for (int cy = 0; cy < n; ++cy)
    for (int cx = 0; cx < n; ++cx) {
      double area = 0;
      for (int j = 0; j < sub; ++j)
        for (int i = 0; i < sub; ++i) {
          const double h = 1.0 / (n * sub);
          const double u = cx * 1.0 / n + i * h, v = cy * 1.0 / n + j * h;
          const Vec3 a = HemisphereFromSquare(u, v), b = HemisphereFromSquare(u + h, v);
          const Vec3 c = HemisphereFromSquare(u + h, v + h), d = HemisphereFromSquare(u, v + h);
          area += 0.5 * (Length(Cross(b - a, c - a)) + Length(Cross(c - a, d - a)));
        }
      EXPECT_NEAR(area, 2 * std::numbers::pi / (n * n), 2e-3 * 2 * std::numbers::pi / (n * n))
          << cx << " " << cy;
    }
}

TEST(GlossyFactors, TheFrameIsOrthonormalAndContinuous) {
  for (const Vec3 n : {Vec3{0, 1, 0}, Vec3{0, 0, 1}, Vec3{0, 0, -1}, Vec3{0.3, -0.2, 1e-9},
                       Vec3{0.3, -0.2, -1e-9}, Vec3{1, std::sqrt(2.0), std::sqrt(3.0)}}) {
    const FactorFrame f = MakeFactorFrame(n);
    EXPECT_NEAR(Length(f.tangent), 1, 1e-12);
    EXPECT_NEAR(Dot(f.tangent, f.normal), 0, 1e-12);
    EXPECT_NEAR(Dot(f.bitangent, f.normal), 0, 1e-12);
    EXPECT_NEAR(Length(Cross(f.tangent, f.bitangent) - f.normal), 0, 1e-12);
  }
  // Across z = 0, where OrthonormalBasis flips, this frame does not move.
  const FactorFrame a = MakeFactorFrame({0.3, -0.2, 1e-9}), b = MakeFactorFrame({0.3, -0.2, -1e-9});
  EXPECT_NEAR(Length(a.tangent - b.tangent), 0, 1e-8);
}

BrdfFactors Linear(int n) {
  // g_0 = u + 2v on the view grid, f_0 = 3u − v on the light grid (exact under bilinear).
  BrdfFactors f;
  f.terms = 1;
  f.view_n = f.light_n = n;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const double u = (x + 0.5) / n, v = (y + 0.5) / n;
      f.g.push_back(static_cast<float>(u + 2 * v));
      f.f.push_back(static_cast<float>(3 * u - v));
    }
  return f;
}

TEST(GlossyFactors, LookupsInterpolateLinearFunctionsExactly) {
  const BrdfFactors f = Linear(16);
  for (double u : {0.1, 0.37, 0.5, 0.81})
    for (double v : {0.12, 0.44, 0.9}) {
      const Vec3 d = HemisphereFromSquare(u, v);
      EXPECT_NEAR(f.G(0, d), u + 2 * v, 1e-5);
      EXPECT_NEAR(f.F(0, d), 3 * u - v, 1e-5);
      EXPECT_NEAR(f.G(0, d * 3.0), u + 2 * v, 1e-5);  // any length
    }
  EXPECT_EQ(f.F(0, {0, 0.2, -0.5}), 0.0);  // below the horizon
}

GlossyFactorTable Table() {
  GlossyFactorTable t;
  t.terms = 1;
  t.mesh_factor = {0, GlossyFactorTable::kDiffuseMesh};
  t.mesh_weight = {Rgb{0.9f, 0.8f, 0.7f}, Rgb{0.5f, 0.5f, 0.5f}};
  t.factors.push_back(Linear(4));
  t.factors[0].relative_error = 0.125;
  t.factors[0].description = "ggx r=0.5";
  return t;
}

TEST(GlossyFactors, RoundTripWithAndWithoutF) {
  const GlossyFactorTable t = Table();
  const GlossyFactorTable a = ParseGlossyFactors(SerializeGlossyFactors(t, true), "a");
  EXPECT_EQ(a.terms, 1);
  EXPECT_EQ(a.mesh_factor, t.mesh_factor);
  EXPECT_EQ(a.factors[0].g, t.factors[0].g);
  EXPECT_EQ(a.factors[0].f, t.factors[0].f);
  EXPECT_EQ(a.factors[0].description, "ggx r=0.5");
  EXPECT_EQ(a.factors[0].relative_error, 0.125);
  EXPECT_EQ(a.mesh_weight[0][1], 0.8f);
  const GlossyFactorTable b = ParseGlossyFactors(SerializeGlossyFactors(t, false), "b");
  EXPECT_TRUE(b.factors[0].f.empty());
  EXPECT_EQ(b.factors[0].g, t.factors[0].g);
}

std::string Resealed(std::string b) {
  const uint64_t sum = Checksum64(b.data(), b.size() - 8);
  std::memcpy(b.data() + b.size() - 8, &sum, 8);
  return b;
}

TEST(GlossyFactors, HostileBytesAreInputErrorsNamingTheFile) {
  const std::string good = SerializeGlossyFactors(Table(), true);
  auto refuses = [](const std::string& bytes, const char* what) {
    try {
      ParseGlossyFactors(bytes, "x.prtf");
      ADD_FAILURE() << "accepted: " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("x.prtf"), std::string::npos) << e.what();
    }
  };
  refuses("", "empty");
  refuses(good.substr(0, 20), "cut");
  std::string b = good;
  b[30] ^= 1;
  refuses(b, "checksum");
  for (std::size_t at = 8; at + 8 < good.size(); ++at) {  // every byte, resealed
    std::string c = good;
    c[at] = static_cast<char>(c[at] ^ 0xA5);
    try {
      ParseGlossyFactors(Resealed(c), "x.prtf");
    } catch (const InputError&) {
    }
  }
  std::string terms = good;
  const uint32_t big = 99;
  std::memcpy(terms.data() + 8, &big, 4);
  refuses(Resealed(terms), "terms");
  std::string nan = good;
  const float q = std::nanf("");
  std::memcpy(nan.data() + nan.size() - 8 - 4, &q, 4);
  refuses(Resealed(nan), "nan");
  refuses(Resealed(good.substr(0, good.size() - 12) + good.substr(good.size() - 8)), "short");
}

}  // namespace
}  // namespace prt
