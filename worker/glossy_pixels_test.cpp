// Glossy pixels' rows (worker/glossy_pixels.h, docs/image-relighting.md "Glossy pixels") against
// evaluations that share nothing with the sampler: an analytic occluder instead of Embree and
// fine per-texel quadrature instead of the stratified rays.
#include "worker/glossy_pixels.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "formats/image_file.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

constexpr double kPi = std::numbers::pi;

SceneMesh Quad(const std::string& name, double half, double y, Vec3 normal, Vec3 centre = {}) {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name;
  m.mesh.positions = {{centre.x - half, y, centre.z - half},
                      {centre.x + half, y, centre.z - half},
                      {centre.x + half, y, centre.z + half},
                      {centre.x - half, y, centre.z + half}};
  m.mesh.normals.assign(4, normal);
  m.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

Material Ggx(double roughness, double kd, double ks) {
  Material m;
  m.model = BrdfModel::kGgx;
  m.roughness = roughness;
  m.diffuse = {float(kd), float(kd), float(kd)};
  m.specular = {float(ks), float(ks), float(ks)};
  return m;
}

// ∫ over texel j of V·(k_d/π + k_s f_s)·cos dω by a q×q midpoint grid in the face coordinates,
// each cell weighted by its exact solid angle; V from the analytic square occluder
// |x|, |z| ≤ half at height h (none when half = 0).
double ReferenceTexel(const CubemapLayout& layout, std::size_t j, const Vec3& p,
                      const Material& m, const ShadingFrame& f, double half, double h, int q) {
  const TexelCoord c = layout.Coord(j);
  const double size = 2.0 / layout.n();
  const double u0 = -1 + size * c.x, v0 = -1 + size * c.y, d = size / q;
  double acc = 0;
  for (int a = 0; a < q; ++a) {
    for (int b = 0; b < q; ++b) {
      const double u = u0 + (a + 0.5) * d, v = v0 + (b + 0.5) * d;
      const Vec3 w = Normalize(CubemapLayout::FacePoint(c.face, u, v));
      const double cosine = Dot(f.normal, w);
      if (cosine <= 0) continue;
      if (half > 0 && w.y > 0) {
        const double t = (h - p.y) / w.y;
        const Vec3 hit = p + w * t;
        if (std::abs(hit.x) <= half && std::abs(hit.z) <= half) continue;
      }
      const double omega = FaceRectSolidAngle(u0 + a * d, u0 + (a + 1) * d, v0 + b * d,
                                              v0 + (b + 1) * d);
      acc += omega * (m.diffuse[0] * cosine / kPi + m.specular[0] * SpecularLobe(m, f, w));
    }
  }
  return acc;
}

// A point on a ground plane under a square occluder, seen from an eye above and to the side:
// the glossy row against the reference texel by texel (L1 over the row), and ComputeTexels and
// the unoccluded estimate against ComputeRow.
TEST(GlossyPixels, RowIsTheBrdfWeightedVisibilityIntegral) {
  const double half = 0.3, h = 0.5;
  SceneGeometry g;
  g.meshes = {Quad("roof", half, h, {0, -1, 0}), Quad("ground", 3.0, 0.0, {0, 1, 0})};
  const EmbreeScene scene(g);
  const Vec3 p{0.15, 0.0, 0.1};
  const Vec3 eye{0.0, 1.2, 2.0};
  for (double r : {0.35, 0.5, 0.8}) {
    TransportSamplerOptions o;
    o.rays_per_texel = 64;
    o.seed = 3;
    const GlossySampling gs{{Ggx(r, 0.4, 0.6)}, eye};
    const TransportSampler sampler(scene, 16, o, gs);
    SpatialSample s;
    s.position = p;
    s.normal = s.geometric_normal = {0, 1, 0};
    s.glossy_material = 0;
    std::vector<float> row(sampler.layout().texel_count());
    sampler.ComputeRow(s, 5, row.data());
    const ShadingFrame f = MakeShadingFrame({0, 1, 0}, eye - p);
    double diff = 0, norm = 0, sum = 0, ref_sum = 0;
    for (std::size_t j = 0; j < row.size(); ++j) {
      const double ref = ReferenceTexel(sampler.layout(), j, p, gs.materials[0], f, half,
                                        h, 24);
      diff += std::abs(row[j] - ref);
      norm += std::abs(ref);
      sum += row[j];
      ref_sum += ref;
    }
    // 64 jittered rays per texel against a 24×24 grid: the texels cut by the occluder's edges
    // and the lobe's peak carry the Monte-Carlo error (measured 0.4–1.1 %).
    EXPECT_LT(diff / norm, 0.02) << "roughness " << r;
    EXPECT_NEAR(sum / ref_sum, 1.0, 0.005) << "roughness " << r;
    // ComputeTexels: the same bits; the unoccluded estimate bounds the row.
    std::vector<uint32_t> all(row.size());
    for (std::size_t j = 0; j < all.size(); ++j) all[j] = static_cast<uint32_t>(j);
    std::vector<float> values(all.size()), unocc(all.size());
    sampler.ComputeTexels(s, 5, all, values.data(), unocc.data());
    for (std::size_t j = 0; j < all.size(); ++j) {
      ASSERT_EQ(values[j], row[j]) << j;
      ASSERT_LE(row[j], unocc[j]) << j;
    }
    // The diffuse sample at the same point keeps its old row (k_d = 1, no lobe).
    SpatialSample d = s;
    d.glossy_material = kDiffuseSample;
    std::vector<float> diffuse(row.size());
    sampler.ComputeRow(d, 5, diffuse.data());
    TransportSamplerOptions plain;
    plain.rays_per_texel = 64;
    plain.seed = 3;
    const TransportSampler plain_sampler(scene, 16, plain, {});
    std::vector<float> old(row.size());
    plain_sampler.ComputeRow(d, 5, old.data());
    EXPECT_EQ(diffuse, old);
  }
}

// ∫_H f_s(ω, ω_o) cos θ dω by a 1000 × 1000 grid in (t, φ), cos θ = 1 − t² (runtime/brdf_test's
// quadrature, independent of the cubemap).
double DirectionalAlbedo(const Material& m, const ShadingFrame& f) {
  const int nt = 1000, np = 1000;
  double acc = 0;
  for (int i = 0; i < nt; ++i) {
    const double t = (i + 0.5) / nt;
    const double cos_t = 1.0 - t * t, sin_t = std::sqrt(std::max(0.0, 1.0 - cos_t * cos_t));
    for (int k = 0; k < np; ++k) {
      const double phi = 2 * kPi * (k + 0.5) / np;
      const Vec3 w = f.normal * cos_t + f.tangent * (sin_t * std::cos(phi)) +
                     f.bitangent * (sin_t * std::sin(phi));
      acc += SpecularLobe(m, f, w) * 2 * t;
    }
  }
  return acc * (1.0 / nt) * (2 * kPi / np);
}

// An unoccluded GGX pixel under a constant environment of radiance 1 relights to
// w ⊙ Σ_j T_j = albedo + specular · E(ω_o), E the lobe's directional albedo.
TEST(GlossyPixels, UnoccludedPixelUnderAConstantSkyIsAlbedoPlusTheLobesDirectionalAlbedo) {
  const EmbreeScene none{SceneGeometry{}};
  const Vec3 p{0, 0, 0}, nrm = Normalize(Vec3{0.2, 1, 0.1});
  for (double r : {0.35, 0.5, 0.8}) {
    for (const Vec3& eye : {Vec3{0, 3, 0.5}, Vec3{2, 0.8, 1}}) {
      // albedo 0.3, specular 0.6 (grey): w = 0.9, k_d = 1/3, k_s = 2/3.
      GlossyMaterialSettings gs;
      gs.brdf = "ggx";
      gs.roughness = r;
      gs.specular = {0.6f, 0.6f, 0.6f};
      SceneDescription scene;
      scene.samples = SpatialSamples::kCameraPixels;
      MeshInstance mi;
      mi.name = "m";
      mi.glossy = gs;
      scene.meshes = {mi};
      SceneGeometry geometry;
      geometry.meshes = {Quad("m", 1, 0, {0, 1, 0})};
      geometry.meshes[0].albedo = {0.3f, 0.3f, 0.3f};
      const GlossyPixels glossy = ResolveGlossyPixels(scene, geometry);
      ASSERT_TRUE(glossy.any());
      TransportSamplerOptions o;
      o.rays_per_texel = 16;
      const TransportSampler sampler(none, 32, o, {glossy.materials, eye});
      SpatialSample s;
      s.position = p;
      s.normal = s.geometric_normal = nrm;
      s.glossy_material = 0;
      std::vector<float> row(sampler.layout().texel_count());
      sampler.ComputeRow(s, 9, row.data());
      double sum = 0;
      for (float x : row) sum += x;
      const Material lobe = Ggx(r, 0, 1);
      const double e = DirectionalAlbedo(lobe, MakeShadingFrame(nrm, eye - p));
      const double expected = 0.3 + 0.6 * e;
      EXPECT_NEAR(glossy.weight[0][0] * sum, expected, 0.003 * expected)
          << "roughness " << r << " E " << e;
    }
  }
}

// Materials: proportional colours split into (k_d, k_s, w); others are refused naming the key.
TEST(GlossyPixels, ColoursSplitIntoOneRowOrAreRefused) {
  SceneDescription scene;
  scene.file = "s.toml";
  scene.samples = SpatialSamples::kCameraPixels;
  MeshInstance mi;
  mi.name = "bunny";
  mi.line = 7;
  mi.glossy.brdf = "phong";
  mi.glossy.exponent = 50;
  mi.glossy.specular = {0.4f, 0.2f, 0.1f};
  scene.meshes = {mi};
  SceneGeometry geometry;
  geometry.meshes = {Quad("bunny", 1, 0, {0, 1, 0}), Quad("ground", 2, 0, {0, 1, 0})};
  geometry.meshes[0].albedo = {0.4f, 0.2f, 0.1f};
  geometry.meshes[1].albedo = {0.5f, 0.5f, 0.5f};
  geometry.meshes[1].is_ground = true;
  const GlossyPixels g = ResolveGlossyPixels(scene, geometry);
  EXPECT_EQ(g.glossy, (std::vector<uint8_t>{1, 0}));
  EXPECT_NEAR(g.materials[0].diffuse[1], 0.5, 1e-6);
  EXPECT_NEAR(g.materials[0].specular[2], 0.5, 1e-6);
  EXPECT_NEAR(g.weight[0][0], 0.8, 1e-6);
  EXPECT_EQ(g.weight[1], geometry.meshes[1].albedo);
  const GlossyPixels back = ParseGlossyPixels(SerializeGlossyPixels(g));
  EXPECT_EQ(back.glossy, g.glossy);
  EXPECT_EQ(back.weight, g.weight);
  EXPECT_EQ(back.materials[0].model, BrdfModel::kPhong);
  // Pixels: only those of the glossy mesh are marked.
  std::vector<SpatialSample> samples(3);
  MarkGlossyPixels(g, std::vector<uint32_t>{0, 1, kImageBackground}, samples);
  EXPECT_EQ(samples[0].glossy_material, 0u);
  EXPECT_EQ(samples[1].glossy_material, kDiffuseSample);
  EXPECT_EQ(samples[2].glossy_material, kDiffuseSample);
  // A white lobe on a coloured albedo: refused, naming the file, the mesh and the keys.
  scene.meshes[0].glossy.specular = {0.4f, 0.4f, 0.4f};
  try {
    ResolveGlossyPixels(scene, geometry);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("s.toml"), std::string::npos) << what;
    EXPECT_NE(what.find("'bunny'"), std::string::npos) << what;
    EXPECT_NE(what.find("`specular` proportional to `albedo`"), std::string::npos) << what;
    EXPECT_NE(what.find("brdf = \"lambert\""), std::string::npos) << what;
  }
  // A vertex scene has no glossy pixels.
  scene.samples = SpatialSamples::kVertices;
  EXPECT_FALSE(ResolveGlossyPixels(scene, geometry).any());
}

}  // namespace
}  // namespace prt
