// worker/brdf_factorisation.h against closed forms: a Lambert material is rank 1 and exact, the
// GGX factorisation converges with m, and Σ g_i f_i integrates to the lobe's directional albedo.
#include "worker/brdf_factorisation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "vocabulary/cubemap.h"
#include "worker/embree_scene.h"

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

namespace prt {
namespace {

SceneMesh Quad(const std::string& name, double half, double y, Vec3 normal) {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name;
  m.mesh.positions = {{-half, y, -half}, {half, y, -half}, {half, y, half}, {-half, y, half}};
  m.mesh.normals.assign(4, normal);
  m.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

// Eq. 3 end to end on one point under a square occluder: the m term rows the sampler bakes
// (T_i = V·f_i), relit and combined with g_i for a view, against the exact glossy row for that
// view (the image runs' row, V·ρ̃(ω, ω_o) with the same rays), under a smooth sky with a sun.
// The difference is the factorisation's alone, and shrinks as m grows.
TEST(BrdfFactorisation, TermRowsRelitForAViewMatchTheExactRow) {
  SceneGeometry g;
  g.meshes = {Quad("roof", 0.3, 0.5, {0, -1, 0}), Quad("ground", 3.0, 0.0, {0, 1, 0})};
  const EmbreeScene scene(g);
  const Vec3 p{0.15, 0.0, 0.1};
  const Material m = Ggx(0.8, 0.4, 0.6);
  TransportSamplerOptions o;
  o.rays_per_texel = 16;
  o.seed = 3;
  const int n = 16;
  const CubemapLayout layout(n);
  std::vector<double> light(layout.texel_count());
  const Vec3 sun = Normalize(Vec3{0.6, 0.7, -0.4});
  for (std::size_t j = 0; j < light.size(); ++j) {
    const Vec3 d = layout.TexelCenter(j);
    light[j] = 0.4 + 0.6 * std::max(0.0, d.y) + 30 * std::exp(30 * (Dot(d, sun) - 1));
  }
  SpatialSample s;
  s.position = p;
  s.normal = s.geometric_normal = {0, 1, 0};
  std::vector<float> row(layout.texel_count());
  auto relit = [&](const TransportSampler& sampler, const SpatialSample& x) {
    sampler.ComputeRow(x, 7, row.data());
    double b = 0;
    for (std::size_t j = 0; j < row.size(); ++j) b += row[j] * light[j];
    return b;
  };
  double previous = 1e9;
  for (int terms : {1, 4, 8}) {
    FactorisationOptions fo = Small(terms);
    fo.view_n = 24;
    fo.svd_light_n = 48;
    fo.light_n = 96;
    auto table = std::make_shared<GlossyFactorTable>();
    table->terms = terms;
    table->mesh_factor = {GlossyFactorTable::kDiffuseMesh, 0};
    table->mesh_weight = {Rgb{1, 1, 1}, Rgb{1, 1, 1}};
    table->factors.push_back(FactorBrdf(m, fo));
    const TransportSampler factored(scene, n, o, GlossySampling{{}, {}, table});
    std::vector<double> term_b(terms);
    for (int t = 0; t < terms; ++t) {
      SpatialSample x = s;
      x.glossy_material = 0;
      x.term = static_cast<uint8_t>(t);
      term_b[t] = relit(factored, x);
    }
    double worst = 0;
    for (const Vec3 eye : {Vec3{0.0, 1.2, 2.0}, Vec3{1.5, 0.6, -0.5}, Vec3{-0.3, 2.0, 0.2}}) {
      const TransportSampler exact(scene, n, o, GlossySampling{{m}, eye});
      SpatialSample x = s;
      x.glossy_material = 0;
      const double b_exact = relit(exact, x);
      float gv[16];
      table->factors[0].GAll(MakeFactorFrame(s.normal).ToLocal(eye - p), gv);
      double b = 0;
      for (int t = 0; t < terms; ++t) b += gv[t] * term_b[t];
      worst = std::max(worst, std::abs(b - b_exact) / b_exact);
    }
    EXPECT_LT(worst, previous + 1e-3) << terms;
    previous = worst;
    if (terms == 8) {
      EXPECT_LT(worst, 0.03);
    }
  }
}

}  // namespace
}  // namespace prt
