#include "runtime/brdf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "vocabulary/cubemap.h"

namespace prt {
namespace {

// ∫ f dω over the sphere by the exact texel solid angles of a 128² cubemap (texel centres).
template <typename F>
double SphereIntegral(const CubemapLayout& layout, F&& f) {
  double acc = 0;
  for (std::size_t j = 0; j < layout.texel_count(); ++j)
    acc += f(layout.TexelCenter(j)) * layout.TexelSolidAngle(j);
  return acc;
}

TEST(Brdf, LambertIntegratesToAlbedo) {
  const CubemapLayout layout(128);
  Material m;
  m.diffuse = {0.7f, 0.5f, 0.25f};
  for (const Vec3& nrm : {Vec3{0, 1, 0}, Normalize(Vec3{1, 2, -3})}) {
    const ShadingFrame f = MakeShadingFrame(nrm, {0.3, 1, 0.2});
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(
          SphereIntegral(layout, [&](const Vec3& w) { return CosineWeightedBrdf(m, f, w, c); }),
          m.diffuse[c], 2e-3 * m.diffuse[c]);
  }
}

TEST(Brdf, PhongLobeIsEnergyBounded) {
  const CubemapLayout layout(128);
  Material m;
  m.model = BrdfModel::kPhong;
  m.specular = {1, 1, 1};
  const Vec3 nrm = Normalize(Vec3{0.2, 1, 0.1});
  for (double s : {1.0, 10.0, 100.0, 200.0}) {
    m.exponent = s;
    // Normal incidence: (s+2)/(2π) ∫ cos^s α cos θ dω = 1 exactly.
    const ShadingFrame f0 = MakeShadingFrame(nrm, nrm);
    EXPECT_NEAR(SphereIntegral(layout, [&](const Vec3& w) { return SpecularLobe(m, f0, w); }), 1.0,
                s > 150 ? 0.03 : 0.01)
        << s;
    for (double elevation : {0.9, 0.5, 0.1}) {
      Vec3 t, b;
      OrthonormalBasis(nrm, t, b);
      const Vec3 view = nrm * elevation + t * std::sqrt(1 - elevation * elevation);
      const ShadingFrame f = MakeShadingFrame(nrm, view);
      EXPECT_LE(SphereIntegral(layout, [&](const Vec3& w) { return SpecularLobe(m, f, w); }),
                1.0 + 0.02)
          << s << " " << elevation;
    }
  }
}

TEST(Brdf, AshikhminShirleyIsReciprocalAndBounded) {
  Material m;
  m.model = BrdfModel::kAshikhminShirley;
  m.specular = {1, 1, 1};
  m.exponent = 200;
  m.exponent_v = 20;
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  const Vec3 nrm{0, 1, 0};
  for (int i = 0; i < 200; ++i) {
    Vec3 a = Normalize(Vec3{g(rng), std::abs(g(rng)), g(rng)});
    Vec3 b = Normalize(Vec3{g(rng), std::abs(g(rng)), g(rng)});
    const double fab = SpecularLobe(m, MakeShadingFrame(nrm, b), a) / Dot(nrm, a);
    const double fba = SpecularLobe(m, MakeShadingFrame(nrm, a), b) / Dot(nrm, b);
    EXPECT_NEAR(fab, fba, 1e-9 * std::max(1.0, fab));
  }
  const CubemapLayout layout(128);
  const ShadingFrame f = MakeShadingFrame(nrm, Normalize(Vec3{0.3, 1, 0}));
  const double e = SphereIntegral(layout, [&](const Vec3& w) { return SpecularLobe(m, f, w); });
  EXPECT_GT(e, 0.5);
  EXPECT_LT(e, 1.1);
}

TEST(BlockDct, ConstantHasOnlyTheDcCoefficient) {
  float px[256], c16[16];
  for (float& p : px) p = 3.f;
  BlockDct::Forward16(px, c16);
  EXPECT_NEAR(c16[0], 48.f, 1e-4);  // 16·c for the orthonormal 16×16 DCT
  for (int i = 1; i < 16; ++i) EXPECT_NEAR(c16[i], 0.f, 1e-4);
  for (int l : {1, 2, 4}) {
    float samples[16], coeffs[16], back[256];
    for (float& s : samples) s = 3.f;
    BlockDct::Project(l, samples, coeffs);
    EXPECT_NEAR(coeffs[0], 48.f, 1e-4);
    for (int i = 1; i < l * l; ++i) EXPECT_NEAR(coeffs[i], 0.f, 1e-4);
    BlockDct::Reconstruct(l, coeffs, back);
    for (float v : back) EXPECT_NEAR(v, 3.f, 1e-5);
  }
}

TEST(BlockDct, SubsampledProjectionRecoversBandLimitedBlocks) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int l : {2, 4}) {
    float a[16], px[256], samples[16], got[16], c16[16];
    for (int i = 0; i < l * l; ++i) a[i] = u(rng);
    BlockDct::Reconstruct(l, a, px);
    // Eq. 4's samples of the band-limited block, at the continuous positions x_i.
    for (int j = 0; j < l; ++j)
      for (int i = 0; i < l; ++i) {
        double v = 0;
        const double x = BlockDct::SamplePosition(l, i), y = BlockDct::SamplePosition(l, j);
        for (int q = 0; q < l; ++q)
          for (int p = 0; p < l; ++p) {
            const double ax = p == 0 ? 0.25 : std::numbers::sqrt2 / 4,
                         ay = q == 0 ? 0.25 : std::numbers::sqrt2 / 4;
            v += a[q * l + p] * ax * std::cos(std::numbers::pi * (2 * x + 1) * p / 32) * ay *
                 std::cos(std::numbers::pi * (2 * y + 1) * q / 32);
          }
        samples[j * l + i] = static_cast<float>(v);
      }
    BlockDct::Project(l, samples, got);
    for (int i = 0; i < l * l; ++i) EXPECT_NEAR(got[i], a[i], 1e-4) << l << " " << i;
    BlockDct::Forward16(px, c16);  // orthonormality: the forward transform gives them back
    for (int v = 0; v < 4; ++v)
      for (int uu = 0; uu < 4; ++uu)
        EXPECT_NEAR(c16[v * 4 + uu], (uu < l && v < l) ? a[v * l + uu] : 0.f, 1e-4);
  }
}

TEST(Brdf, AppendixASamplingRates) {
  const Vec3 nrm{0, 1, 0};
  const ShadingFrame f = MakeShadingFrame(nrm, nrm);  // V = N: ∠(V, R) = ∠(N, centre)
  auto centre = [](double deg) {
    const double a = deg * std::numbers::pi / 180;
    return Vec3{std::sin(a), std::cos(a), 0};
  };
  Material m;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(0)), 1);  // Lambert
  m.model = BrdfModel::kPhong;
  m.specular = {0.5f, 0.5f, 0.5f};
  m.exponent = 10;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10)), 4);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(60)), 1);
  m.exponent = 100;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10)), 16);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(30)), 4);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(60)), 1);
  m.exponent = 300;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10)), 256);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(30)), 4);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(60)), 1);
  // The 256-sample threshold as a parameter (the paper's 250 by default).
  m.exponent = 200;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10)), 16);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10), 250.0), 16);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10), 100.0), 256);
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(30), 100.0), 4);
  m.exponent = 20;
  EXPECT_EQ(BrdfSamplingRate(m, f, centre(10), 10.0), 4);  // s < 30 never takes 16 or 256
}

}  // namespace
}  // namespace prt
