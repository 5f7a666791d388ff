#include "runtime/brdf.h"

#include <gtest/gtest.h>

#include <algorithm>
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

// GGX (Walter et al. 2007; docs/conventions.md "The GGX material"): D integrates to 1 over
// projected microfacet area, ∫_H D(m)(n·m) dm = 2π ∫_0^{π/2} D(θ) cos θ sin θ dθ = 1, by the
// midpoint rule in u = cos²θ (D is smooth in u: α²/(π(u(α²−1)+1)²)), where the integral is
// π ∫_0^1 D(u) du.
TEST(Brdf, GgxDistributionIntegratesToOneOverProjectedArea) {
  for (double r : {0.1, 0.2, 0.35, 0.5, 0.8, 1.0}) {
    const double alpha = r * r;
    const int steps = 4000000;
    double acc = 0;
    for (int i = 0; i < steps; ++i) {
      const double u = (i + 0.5) / steps;
      acc += GgxDistribution(alpha, std::sqrt(u));
    }
    EXPECT_NEAR(std::numbers::pi * acc / steps, 1.0, 2e-6) << "roughness " << r;
  }
  EXPECT_EQ(GgxDistribution(0.25, 0.0), 0.0);
  EXPECT_EQ(GgxDistribution(0.25, -0.5), 0.0);
  // G1 is 1 at normal incidence and falls towards grazing.
  EXPECT_NEAR(GgxSmithG1(0.25, 1.0), 1.0, 1e-15);
  EXPECT_LT(GgxSmithG1(0.25, 0.1), GgxSmithG1(0.25, 0.5));
}

// ∫ f_s(ω, ω_o) cos θ dω over the hemisphere of ω, by quadrature in (cos θ, φ) with the lobe's
// peak resolved: a 1000 × 1000 midpoint grid in (u = 1 − cos θ mapped by u = t², φ).
double GgxDirectionalAlbedo(const Material& m, const ShadingFrame& f) {
  const int nt = 1000, np = 1000;
  double acc = 0;
  for (int i = 0; i < nt; ++i) {
    const double t = (i + 0.5) / nt;
    const double cos_t = 1.0 - t * t;  // dcos = 2t dt
    const double sin_t = std::sqrt(std::max(0.0, 1.0 - cos_t * cos_t));
    for (int k = 0; k < np; ++k) {
      const double phi = 2 * std::numbers::pi * (k + 0.5) / np;
      const Vec3 w = f.normal * cos_t + f.tangent * (sin_t * std::cos(phi)) +
                     f.bitangent * (sin_t * std::sin(phi));
      acc += SpecularLobe(m, f, w) * 2 * t;
    }
  }
  return acc * (1.0 / nt) * (2 * std::numbers::pi / np);
}

TEST(Brdf, GgxIsEnergyBoundedAndReciprocal) {
  Material m;
  m.model = BrdfModel::kGgx;
  m.specular = {1, 1, 1};
  const Vec3 nrm = Normalize(Vec3{0.1, 1, -0.2});
  Vec3 t, b;
  OrthonormalBasis(nrm, t, b);
  for (double r : {0.2, 0.35, 0.5, 0.8, 1.0}) {
    m.roughness = r;
    for (double elevation : {1.0, 0.7, 0.3, 0.1}) {
      const Vec3 view = nrm * elevation + t * std::sqrt(1 - elevation * elevation);
      const double e = GgxDirectionalAlbedo(m, MakeShadingFrame(nrm, view));
      // White furnace: no Fresnel, no multiple scattering, so ≤ 1; and a smooth lobe near
      // normal incidence keeps most of it (Smith's single-scattering loss).
      EXPECT_LE(e, 1.0 + 1e-3) << "roughness " << r << " elevation " << elevation;
      EXPECT_GT(e, 0.2) << "roughness " << r << " elevation " << elevation;
      // Closed form: at α = 1, D = 1/π and G1(μ) = 2μ/(1 + μ), so at normal incidence
      // E = ∫ G1(μ)/(4π) dω = ∫_0^1 μ/(1 + μ) dμ = 1 − ln 2.
      if (r == 1.0 && elevation == 1.0) {
        EXPECT_NEAR(e, 1.0 - std::log(2.0), 1e-4);
      }
    }
  }
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  for (double r : {0.2, 0.5, 1.0}) {
    m.roughness = r;
    for (int i = 0; i < 200; ++i) {
      const Vec3 a = Normalize(Vec3{g(rng), std::abs(g(rng)) + 0.05, g(rng)});
      const Vec3 c = Normalize(Vec3{g(rng), std::abs(g(rng)) + 0.05, g(rng)});
      const Vec3 up{0, 1, 0};
      const double fac = SpecularLobe(m, MakeShadingFrame(up, c), a) / Dot(up, a);
      const double fca = SpecularLobe(m, MakeShadingFrame(up, a), c) / Dot(up, c);
      EXPECT_NEAR(fac, fca, 1e-9 * std::max(1.0, fac)) << r;
    }
  }
  // Below either horizon: nothing.
  const ShadingFrame f = MakeShadingFrame({0, 1, 0}, Normalize(Vec3{0, 1, 1}));
  EXPECT_EQ(SpecularLobe(m, f, Normalize(Vec3{0, -1, 1})), 0.0);
  EXPECT_EQ(SpecularLobe(m, MakeShadingFrame({0, 1, 0}, {0, -1, 1}), Vec3{0, 1, 0}), 0.0);
}

// The scene's keys make the same material (roughness carried, α = r² inside the lobe).
// LobeReflectance's quadrature against an independent estimate: the GGX lobe importance-sampled
// through its half vector (h with density D(h)·(n·h), Walter et al. 2007 Eq. 35), for which
// f_s·cos θ / p(ω) = G1(ω)·G1(ω_o)·(h·ω_o) / ((n·ω_o)·(n·h)); ω_o cosine-distributed. Rougher
// lobes lose more to masking (the reflectance falls with r) and none exceeds 1.
TEST(Brdf, LobeReflectanceAgreesWithImportanceSampling) {
  EXPECT_EQ(LobeReflectance(Material{}), 0.0);
  double previous = 1.0;
  for (double r : {0.2, 0.35, 0.5, 0.8}) {
    Material m;
    m.model = BrdfModel::kGgx;
    m.roughness = r;
    const double alpha = r * r;
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    double sum = 0;
    constexpr int kSamples = 400000;
    for (int i = 0; i < kSamples; ++i) {
      const double ro = std::sqrt(u(rng)), po = 2 * std::numbers::pi * u(rng);
      const Vec3 wo{ro * std::cos(po), ro * std::sin(po), std::sqrt(1 - ro * ro)};
      const double u1 = u(rng), ph = 2 * std::numbers::pi * u(rng);
      const double ch = 1 / std::sqrt(1 + alpha * alpha * u1 / (1 - u1));
      const double sh = std::sqrt(std::max(0.0, 1 - ch * ch));
      const Vec3 h{sh * std::cos(ph), sh * std::sin(ph), ch};
      const double ho = Dot(h, wo);
      if (ho <= 0) continue;
      const Vec3 wi = h * (2 * ho) - wo;
      if (wi.z <= 0) continue;
      sum += GgxSmithG1(alpha, wi.z) * GgxSmithG1(alpha, wo.z) * ho / (wo.z * ch);
    }
    const double want = sum / kSamples, got = LobeReflectance(m);
    EXPECT_NEAR(got, want, 0.01) << "r = " << r;
    EXPECT_LE(got, 1.0) << "r = " << r;
    EXPECT_LT(got, previous) << "r = " << r;
    previous = got;
  }
}

TEST(Brdf, GgxMaterialOfSettings) {
  GlossyMaterialSettings g;
  g.brdf = "ggx";
  g.specular = {0.5f, 0.5f, 0.5f};
  g.roughness = 0.35;
  const Material m = MaterialOfSettings(g, {0.25f, 0.25f, 0.25f});
  EXPECT_EQ(m.model, BrdfModel::kGgx);
  EXPECT_EQ(m.roughness, 0.35);
  EXPECT_TRUE(HasSpecular(m));
  // Mirror configuration at normal incidence: f_s·cos = D(1)·1·1/4 = 1/(4πα²).
  const ShadingFrame f = MakeShadingFrame({0, 1, 0}, {0, 1, 0});
  const double alpha = 0.35 * 0.35;
  EXPECT_NEAR(SpecularLobe(m, f, {0, 1, 0}), 1.0 / (4 * std::numbers::pi * alpha * alpha), 1e-9);
  g.brdf = "ward";
  EXPECT_THROW(MaterialOfSettings(g, {0.5f, 0.5f, 0.5f}), std::invalid_argument);
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
