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

TEST(Cubemap, RejectsBadResolution) {
  EXPECT_THROW(CubemapLayout(0), std::invalid_argument);
  EXPECT_THROW(CubemapLayout(48), std::invalid_argument);
  EXPECT_THROW(CubemapLayout(512), std::invalid_argument);
}

INSTANTIATE_TEST_SUITE_P(Sizes, CubemapSizes, ::testing::Values(8, 16, 32, 64, 128, 256));

}  // namespace
}  // namespace prt
