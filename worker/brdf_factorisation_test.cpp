// worker/brdf_factorisation.h against closed forms: a Lambert material is rank 1 and exact, the
// GGX factorisation converges with m, and Σ g_i f_i integrates to the lobe's directional albedo.
#include "worker/brdf_factorisation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace prt {
namespace {

Material Ggx(double r, double kd, double ks) {
  Material m;
  m.model = BrdfModel::kGgx;
  m.roughness = r;
  m.diffuse = {float(kd), float(kd), float(kd)};
  m.specular = {float(ks), float(ks), float(ks)};
  return m;
}

FactorisationOptions Small(int terms) {
  FactorisationOptions o;
  o.terms = terms;
  o.view_n = 16;
  o.svd_light_n = 32;
  o.light_n = 64;
  o.check_views = 64;
  o.check_lights = 512;
  return o;
}

TEST(BrdfFactorisation, LambertIsRankOneAndExact) {
  Material m;
  m.diffuse = {1, 1, 1};
  const BrdfFactors f = FactorBrdf(m, Small(2));
  EXPECT_LT(f.relative_error, 1e-2);  // bilinear interpolation of cos θ only
  const std::vector<double> t = TruncationErrors(m, Small(2), 3);
  EXPECT_LT(t[0], 1e-6);
  // g_0·f_0 = cos θ/π anywhere; the second term is (numerically) zero.
  const Vec3 view = Normalize(Vec3{0.3, 0.1, 0.8}), light = Normalize(Vec3{-0.4, 0.2, 0.7});
  EXPECT_NEAR(f.G(0, view) * f.F(0, light), light.z / std::numbers::pi, 2e-3);
  EXPECT_NEAR(f.G(1, view) * f.F(1, light), 0.0, 1e-6);
}

TEST(BrdfFactorisation, GgxConvergesWithTheNumberOfTerms) {
  const Material m = Ggx(0.5, 0.3, 0.7);
  const std::vector<double> t = TruncationErrors(m, Small(1), 8);
  ASSERT_EQ(t.size(), 8u);
  for (int i = 1; i < 8; ++i) EXPECT_LT(t[i], t[i - 1]);
  // A lobe that moves with the view is not low rank in a fixed frame (docs/glossy-transport.md
  // measures it): r = 0.5 keeps about 2/3 of its error at m = 4, r = 0.8 about 1/8.
  EXPECT_LT(t[3], t[0] * 0.9);
  EXPECT_LT(TruncationErrors(Ggx(0.8, 0.3, 0.7), Small(1), 4)[3], 0.15);
  // A wider lobe factors better at every m.
  const std::vector<double> wide = TruncationErrors(Ggx(0.8, 0.3, 0.7), Small(1), 4);
  const std::vector<double> sharp = TruncationErrors(Ggx(0.35, 0.3, 0.7), Small(1), 4);
  EXPECT_LT(wide[3], t[3]);
  EXPECT_GT(sharp[3], t[3]);
  // The looked-up error at m = 4 is near the truncation error (interpolation adds little).
  const BrdfFactors f = FactorBrdf(m, Small(4));
  EXPECT_LT(f.relative_error, t[3] * 1.5 + 0.02);
  EXPECT_GT(f.relative_error, t[3] * 0.5);
}

// ∫ Σ_i g_i(ω_o) f_i(ω) dω = k_d + k_s·E(ω_o), E the lobe's directional albedo, within the
// factorisation's error: the terms carry the energy of the BRDF.
TEST(BrdfFactorisation, TheTermsCarryTheDirectionalAlbedo) {
  const Material m = Ggx(0.8, 0.3, 0.7);
  const BrdfFactors f = FactorBrdf(m, Small(4));
  const int n = 128;
  for (const Vec3 view : {Vec3{0, 0, 1}, Normalize(Vec3{0.6, 0.2, 0.5})}) {
    const ShadingFrame frame = MakeShadingFrame({0, 0, 1}, view);
    double approx = 0, exact = 0;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Vec3 w = HemisphereFromSquare((x + 0.5) / n, (y + 0.5) / n);
        double s = 0;
        for (int i = 0; i < 4; ++i) s += f.G(i, view) * f.F(i, w);
        approx += s;
        exact += m.diffuse[0] * w.z / std::numbers::pi + m.specular[0] * SpecularLobe(m, frame, w);
      }
    const double cell = 2 * std::numbers::pi / (n * n);
    approx *= cell;
    exact *= cell;
    EXPECT_LE(exact, 1.0 + 1e-3);
    EXPECT_NEAR(approx, exact, 0.03 * exact) << view.x;
  }
}

TEST(BrdfFactorisation, RefusesBadOptions) {
  FactorisationOptions o = Small(0);
  EXPECT_THROW(FactorBrdf(Ggx(0.5, 0.5, 0.5), o), std::invalid_argument);
  o = Small(4);
  o.view_n = 1;
  EXPECT_THROW(FactorBrdf(Ggx(0.5, 0.5, 0.5), o), std::invalid_argument);
}

}  // namespace
}  // namespace prt
