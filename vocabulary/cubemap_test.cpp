#include "vocabulary/cubemap.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace prt {
namespace {

class CubemapSizes : public ::testing::TestWithParam<int> {};

// The texel solid angles tile the sphere: they sum to 4π (closed form, double precision).
TEST_P(CubemapSizes, SolidAnglesSumToFourPi) {
  CubemapLayout c(GetParam());
  double sum = 0;
  for (std::size_t i = 0; i < c.texel_count(); ++i) sum += c.TexelSolidAngle(i);
  EXPECT_NEAR(sum / (4 * std::numbers::pi), 1.0, 1e-9);
}

// Every texel's centre direction maps back to the same texel.
TEST_P(CubemapSizes, TexelCenterRoundTrips) {
  CubemapLayout c(GetParam());
  for (std::size_t i = 0; i < c.texel_count(); ++i) {
    const Vec3 d = c.TexelCenter(i);
    EXPECT_NEAR(Length(d), 1.0, 1e-12);
    ASSERT_EQ(c.TexelOf(d), i);
  }
}

// Cosine-weighted hemisphere integral ∫ max(0, n·ω) dω = π, summed from texel centres with
// exact solid angles converges to π; at n = 256 the midpoint rule is within 1e-3.
TEST(Cubemap, CosineLobeIntegratesToPi) {
  CubemapLayout c(256);
  const Vec3 n = Normalize(Vec3{0.3, 0.8, -0.2});
  double sum = 0;
  for (std::size_t i = 0; i < c.texel_count(); ++i)
    sum += std::max(0.0, Dot(n, c.TexelCenter(i))) * c.TexelSolidAngle(i);
  EXPECT_NEAR(sum / std::numbers::pi, 1.0, 1e-3);
}

// Face order and axes follow ImfEnvmap.h: face k's centre is ±X, ±Y, ±Z in that order.
TEST(Cubemap, FaceOrderMatchesOpenExr) {
  const Vec3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (int f = 0; f < 6; ++f) {
    const Vec3 d = CubemapLayout::FaceDirection(f, 0, 0);
    EXPECT_NEAR(Dot(d, axes[f]), 1.0, 1e-15) << f;
  }
  // Imf::CubeMap::direction for +X maps face position x to dir.y and y to dir.z.
  const Vec3 d = CubemapLayout::FacePoint(0, 0.5, -0.25);
  EXPECT_EQ(d, (Vec3{1, 0.5, -0.25}));
}

// The horizon test is exact: a texel is above the horizon iff some point of it is.
TEST(Cubemap, HorizonTestAgreesWithDenseSampling) {
  CubemapLayout c(8);
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 n = Normalize(Vec3{g(rng), g(rng), g(rng)});
    for (std::size_t i = 0; i < c.texel_count(); ++i) {
      bool any = false;
      for (int a = 0; a <= 16 && !any; ++a)
        for (int b = 0; b <= 16 && !any; ++b) any = Dot(c.TexelDirection(i, a / 16.0, b / 16.0), n) > 1e-12;
      EXPECT_EQ(any, c.TexelAboveHorizon(i, n)) << i;
    }
  }
}

// The mask agrees with the per-texel test; "fully above" means all of the texel is above.
TEST(Cubemap, AboveHorizonMaskMatchesPerTexelTest) {
  CubemapLayout c(16);
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  std::vector<uint8_t> mask(c.texel_count()), full(c.texel_count());
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 n = Normalize(Vec3{g(rng), g(rng), g(rng)});
    std::size_t count = c.AboveHorizonMask(n, mask.data(), full.data());
    std::size_t expect = 0;
    for (std::size_t i = 0; i < c.texel_count(); ++i) {
      ASSERT_EQ(mask[i] != 0, c.TexelAboveHorizon(i, n)) << i;
      expect += mask[i];
      if (full[i]) {
        for (int a = 0; a <= 4; ++a)
          for (int b = 0; b <= 4; ++b) ASSERT_GT(Dot(c.TexelDirection(i, a / 4.0, b / 4.0), n), 0);
      }
    }
    EXPECT_EQ(count, expect);
  }
}

// Arvo's vector irradiance: |Φ_j| ≤ Ω_j, n·Φ_j equals a dense quadrature of the cosine over a
// fully visible texel, and Σ_j Φ_j = 0 over the whole sphere.
TEST(Cubemap, VectorIrradianceIntegratesTheCosine) {
  CubemapLayout c(8);
  const auto& phi = c.TexelVectorIrradiance();
  Vec3 total;
  for (std::size_t i = 0; i < c.texel_count(); ++i) {
    total += phi[i];
    EXPECT_LE(Length(phi[i]), c.TexelSolidAngle(i) * (1 + 1e-12));
  }
  EXPECT_LT(Length(total), 1e-12);
  const Vec3 n = Normalize(Vec3{0.2, 1.0, 0.1});
  std::vector<uint8_t> mask(c.texel_count()), full(c.texel_count());
  c.AboveHorizonMask(n, mask.data(), full.data());
  const int q = 64;
  const double h = 2.0 / c.n();
  for (std::size_t i = 0; i < c.texel_count(); i += 5) {
    if (!full[i]) continue;
    const TexelCoord tc = c.Coord(i);
    double sum = 0;
    for (int a = 0; a < q; ++a)
      for (int b = 0; b < q; ++b) {
        const double u0 = -1 + h * (tc.x + a / double(q)), v0 = -1 + h * (tc.y + b / double(q));
        const double om = FaceRectSolidAngle(u0, u0 + h / q, v0, v0 + h / q);
        sum += om * Dot(n, CubemapLayout::FaceDirection(tc.face, u0 + 0.5 * h / q, v0 + 0.5 * h / q));
      }
    EXPECT_NEAR(Dot(n, phi[i]) / sum, 1.0, 1e-4) << i;
  }
}

TEST(Cubemap, RejectsBadResolution) {
  EXPECT_THROW(CubemapLayout(0), std::invalid_argument);
  EXPECT_THROW(CubemapLayout(48), std::invalid_argument);
  EXPECT_THROW(CubemapLayout(512), std::invalid_argument);
}

INSTANTIATE_TEST_SUITE_P(Sizes, CubemapSizes, ::testing::Values(8, 16, 32, 64, 128, 256));

}  // namespace
}  // namespace prt
