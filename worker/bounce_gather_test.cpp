#include "worker/bounce_gather.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <numeric>
#include <string>
#include <vector>

#include "runtime/brdf.h"
#include "vocabulary/scene.h"
#include "worker/camera_samples.h"
#include "worker/grid_scene_test_support.h"
#include "worker/path_trace_reference.h"

namespace prt {
namespace {

using grid_scenes::Grid;
using grid_scenes::Scene;

// The transport of a scene with K bounces gathered: direct rows at n, bounces at m.
struct Gathered {
  std::vector<SpatialSample> samples;
  std::vector<float> direct;                // V rows at n
  std::vector<std::vector<float>> bounces;  // K × (C·V rows at m)
  std::size_t cols_n = 0, cols_m = 0;
  std::vector<GatherStats> stats;
  // Σ_j of the row (the relit value under a uniform sky of radiance 1).
  double Direct(std::size_t v) const {
    return std::accumulate(direct.begin() + v * cols_n, direct.begin() + (v + 1) * cols_n, 0.0);
  }
  double Bounce(int k, std::size_t v, int c = 0) const {
    const std::size_t V = samples.size();
    const auto& b = bounces[k - 1];
    return std::accumulate(b.begin() + (c * V + v) * cols_m, b.begin() + (c * V + v + 1) * cols_m,
                           0.0);
  }
};

Gathered Gather(const SceneGeometry& g, int bounces, int paths, int channels, int n = 8, int m = 4,
                uint64_t seed = 1) {
  Gathered out;
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  out.samples = SpatialSamplesOf(g);
  TransportSamplerOptions to;
  to.rays_per_texel = 16;
  const TransportSampler sampler(scene, n, to);
  out.cols_n = sampler.layout().texel_count();
  out.direct.resize(out.samples.size() * out.cols_n);
  sampler.ComputeRows(out.samples, 0, out.direct.data());
  BounceGatherOptions go;
  go.paths = paths;
  go.seed = seed;
  const BounceGatherer gatherer(scene, surfaces, go);
  const CubemapLayout coarse(m);
  out.cols_m = coarse.texel_count();
  out.bounces = GatherBounces(gatherer, out.samples, sampler.layout(), coarse, out.direct, bounces,
                              channels, &out.stats);
  return out;
}

constexpr double kHalf = 1000;  // the ground's half width: a patch at height ~1 sees it all

SceneMesh Ground(Rgb albedo, Vec3 normal = {0, 1, 0}) {
  return Grid("ground", {-kHalf, 0, -kHalf}, {2 * kHalf, 0, 0}, {0, 0, 2 * kHalf}, normal, 2,
              albedo);
}

// Issue 22's closed forms: a small patch above a large ground of albedo ρ_g under a uniform sky
// of radiance 1. Vertical: 0.5 direct, 0.5 + 0.5·ρ_g with one bounce. Facing down: ρ_g, no
// direct.
TEST(BounceGather, PatchAboveGroundMatchesClosedForms) {
  const float rho = 0.6f;
  const SceneGeometry g = Scene(
      {Grid("vertical", {0, 0.99, -0.01}, {0, 0.02, 0}, {0, 0, 0.02}, {1, 0, 0}, 2,
            {0.5f, 0.5f, 0.5f}),
       Grid("down", {2, 1, -0.01}, {0.02, 0, 0}, {0, 0, 0.02}, {0, -1, 0}, 2, {0.5f, 0.5f, 0.5f}),
       Ground({rho, rho, rho})});
  const Gathered t = Gather(g, 1, 1024, 1);
  for (std::size_t v = 0; v < 4; ++v) {
    EXPECT_NEAR(t.Direct(v), 0.5, 0.005) << v;
    EXPECT_NEAR(t.Direct(v) + t.Bounce(1, v), 0.5 + 0.5 * rho, 0.005) << v;
  }
  for (std::size_t v = 4; v < 8; ++v) {
    EXPECT_NEAR(t.Direct(v), 0.0, 1e-3) << v;
    EXPECT_NEAR(t.Bounce(1, v), rho, 0.005) << v;
  }
  // Every ray of the facing-down patch hits the ground's front; half of the vertical's escape.
  EXPECT_EQ(t.stats[0].back_face_hits, 0u);
  // Half of the vertical patch's rays and all the ground's escape, none of the other patch's.
  EXPECT_NEAR(double(t.stats[0].rays_escaped) / double(t.stats[0].rays_traced), 0.5, 0.01);
}

// docs/interreflection.md "Back faces": a ground whose normals face down still occludes the
// lower half, but its back reflects nothing.
TEST(BounceGather, BackFacesOccludeAndAbsorb) {
  const SceneGeometry g = Scene({Grid("vertical", {0, 0.99, -0.01}, {0, 0.02, 0}, {0, 0, 0.02},
                                      {1, 0, 0}, 2, {0.5f, 0.5f, 0.5f}),
                                 Ground({0.6f, 0.6f, 0.6f}, {0, -1, 0})});
  const Gathered t = Gather(g, 1, 256, 1);
  for (std::size_t v = 0; v < 4; ++v) {
    EXPECT_NEAR(t.Direct(v), 0.5, 0.005);
    EXPECT_EQ(t.Bounce(1, v), 0.0);
  }
  // Half of the patch's rays (4 of the 8 vertices).
  EXPECT_NEAR(double(t.stats[0].back_face_hits) / double(t.stats[0].rays_traced), 0.25, 0.01);
}

// A red ground tints the patch: the indirect part's channels are in the albedo's ratios.
TEST(BounceGather, ColouredAlbedoTintsTheBounceLight) {
  const Rgb red{0.8f, 0.1f, 0.2f};
  const SceneGeometry g = Scene({Grid("vertical", {0, 0.99, -0.01}, {0, 0.02, 0}, {0, 0, 0.02},
                                      {1, 0, 0}, 2, {0.5f, 0.5f, 0.5f}),
                                 Ground(red)});
  const Gathered t = Gather(g, 2, 256, 3);
  for (std::size_t v = 0; v < 4; ++v)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(t.Bounce(1, v, c), 0.5 * red[c], 0.004) << c;
}

// An open box (five inward faces) of albedo ρ under a uniform sky. Per vertex, a bounce's
// uniform-sky value is at most ρ × the previous bounce's largest (the gather averages ρ·Tᵏ over
// the hemisphere); the area-weighted energy falls by ρ at least (reciprocity: the form factors
// from a surface to the rest sum to ≤ 1). With ρ = 1 (the furnace) B rises monotonically with
// K towards 1 and never passes it.
SceneGeometry OpenBox(Rgb albedo, int res = 7) {
  const double s = 1;
  return Scene({Grid("floor", {0, 0, 0}, {s, 0, 0}, {0, 0, s}, {0, 1, 0}, res, albedo),
                Grid("x0", {0, 0, 0}, {0, s, 0}, {0, 0, s}, {1, 0, 0}, res, albedo),
                Grid("x1", {s, 0, 0}, {0, s, 0}, {0, 0, s}, {-1, 0, 0}, res, albedo),
                Grid("z0", {0, 0, 0}, {s, 0, 0}, {0, s, 0}, {0, 0, 1}, res, albedo),
                Grid("z1", {0, 0, s}, {s, 0, 0}, {0, s, 0}, {0, 0, -1}, res, albedo)});
}

TEST(BounceGather, EachBounceHasAtMostAlbedoTimesThePreviousEnergy) {
  const float rho = 0.7f;
  const Gathered t = Gather(OpenBox({rho, rho, rho}), 4, 256, 1, 4, 2);
  const std::size_t V = t.samples.size();
  double prev_max = 0, prev_sum = 0;
  for (std::size_t v = 0; v < V; ++v) {
    prev_max = std::max(prev_max, t.Direct(v));
    prev_sum += t.Direct(v);
  }
  for (int k = 1; k <= 4; ++k) {
    double mx = 0, sum = 0;
    for (std::size_t v = 0; v < V; ++v) {
      mx = std::max(mx, t.Bounce(k, v));
      sum += t.Bounce(k, v);
    }
    EXPECT_LE(mx, rho * prev_max * 1.02) << "bounce " << k;
    EXPECT_LE(sum, rho * prev_sum * 1.02) << "bounce " << k;
    EXPECT_GT(sum, 0.05 * prev_sum) << "bounce " << k;
    prev_max = mx;
    prev_sum = sum;
  }
}

// A spherical cavity of radius 1 with its cap above polar angle α cut away, seen from inside:
// from any point of a sphere's inside, every surface element subtends the same form factor
// dA / (4πR²), so under a uniform sky of radiance 1 every point gets F = (1 − cos α)/2 direct
// and, with albedo ρ, bounce k adds F·(ρ(1 − F))^k. The furnace (ρ = 1): B(K) = 1 − (1 − F)^(K+1),
// rising monotonically to 1. (A box would do as well but for its creases: a vertex on a crease
// sees half of its hemisphere through the other face's back.)
SceneGeometry SphereCavity(double alpha, int rings, int segments, Rgb albedo) {
  SceneMesh m;
  m.name = "cavity";
  m.mesh.source = "cavity";
  m.albedo = albedo;
  for (int r = 0; r < rings; ++r) {
    const double theta = alpha + (std::numbers::pi - alpha) * r / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * std::numbers::pi * s / segments;
      const Vec3 p{std::sin(theta) * std::cos(phi), std::cos(theta),
                   std::sin(theta) * std::sin(phi)};
      m.mesh.positions.push_back(p);
      m.mesh.normals.push_back(-p);
    }
  }
  const uint32_t pole = static_cast<uint32_t>(m.mesh.positions.size());
  m.mesh.positions.push_back({0, -1, 0});
  m.mesh.normals.push_back({0, 1, 0});
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = r * segments + s, b = r * segments + (s + 1) % segments;
      if (r + 1 < rings) {
        const uint32_t c = a + segments, d = b + segments;
        m.mesh.triangles.push_back({a, b, d});
        m.mesh.triangles.push_back({a, d, c});
      } else {
        m.mesh.triangles.push_back({a, b, pole});
      }
    }
  return Scene({m});
}

TEST(BounceGather, FurnaceRisesMonotonicallyTowardsOne) {
  const double alpha = std::numbers::pi / 3, F = (1 - std::cos(alpha)) / 2;  // F = 1/4
  const Gathered t = Gather(SphereCavity(alpha, 24, 48, {1, 1, 1}), 12, 256, 1, 8, 4);
  const std::size_t V = t.samples.size();
  std::vector<double> total(V);
  double mean = 0;
  for (std::size_t v = 0; v < V; ++v) {
    total[v] = t.Direct(v);
    mean += total[v] / double(V);
  }
  EXPECT_NEAR(mean, F, 0.02);
  for (int k = 1; k <= 12; ++k) {
    const double before = mean;
    mean = 0;
    for (std::size_t v = 0; v < V; ++v) {
      total[v] += t.Bounce(k, v);
      mean += total[v] / double(V);
      EXPECT_LE(total[v], 1.03) << "vertex " << v << " after " << k << " bounces";
    }
    EXPECT_GT(mean, before) << k;
    EXPECT_NEAR(mean, 1 - std::pow(1 - F, k + 1), 0.03) << k;
  }
}

TEST(BounceGather, TermsAreAPureFunctionOfSeedVertexAndBounce) {
  const SceneGeometry g = OpenBox({0.5f, 0.5f, 0.5f}, 4);
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const auto samples = SpatialSamplesOf(g);
  const BounceGatherer gatherer(scene, surfaces, {64, 7});
  std::vector<GatherTerm> a, b, c;
  gatherer.Terms(samples[5], 5, 1, 1, a);
  gatherer.Terms(samples[5], 5, 1, 1, b);
  gatherer.Terms(samples[5], 5, 2, 1, c);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].vertex, b[i].vertex);
    EXPECT_EQ(a[i].weight[0], b[i].weight[0]);
  }
  bool differs = a.size() != c.size();
  for (std::size_t i = 0; !differs && i < a.size(); ++i)
    differs = a[i].vertex != c[i].vertex || a[i].weight[0] != c[i].weight[0];
  EXPECT_TRUE(differs) << "bounce 2 must draw fresh directions";
}

// Refining a coarse row keeps its relit value under any light that is constant over the coarse
// texels, and coarsening a refined row gives the coarse row back.
TEST(BounceGather, CoarsenAndRefineAreExactOnTheCoarseGrid) {
  const CubemapLayout fine(8), coarse(2);
  std::vector<float> c(coarse.texel_count()), f(fine.texel_count(), 0.0f),
      back(coarse.texel_count());
  for (std::size_t J = 0; J < c.size(); ++J) c[J] = float(1 + (J * 7) % 5);
  AddRefinedRow(coarse, fine, c.data(), f.data());
  CoarsenRow(fine, coarse, f.data(), back.data());
  for (std::size_t J = 0; J < c.size(); ++J) EXPECT_NEAR(back[J], c[J], 1e-5 * c[J]);
  // Fine texels of one coarse texel share its value per solid angle.
  const std::size_t j0 = fine.Index(2, 0, 0), j1 = fine.Index(2, 3, 3);
  EXPECT_NEAR(f[j0] / fine.TexelSolidAngle(j0), f[j1] / fine.TexelSolidAngle(j1), 1e-6);
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// The CGAL dragon (10k vertices, ../shared/data's chinese_dragon_10kv through the build's data
// folder) on the default scene's ground, n = 8.
SceneDescription DragonOnTheDefaultGround() {
  SceneDescription scene = LoadDefaultScene(PRT_DATA_DIR);
  scene.meshes.at(0).path = std::string(PRT_DATA_DIR) + "/meshes/ChineseDragon-10kv.off";
  scene.meshes.at(0).resolved_path = scene.meshes.at(0).path;
  scene.cubemap_n = 8;
  return scene;
}

// A uniform sky of radiance 1 as a lighting cubemap of n texels per face edge.
CubemapRgb UniformSky(int n) {
  CubemapRgb sky;
  sky.n = n;
  for (int c = 0; c < 3; ++c) sky.Channel(c).assign(CubemapLayout(n).texel_count(), 1.0f);
  return sky;
}

// The gather against the per-element path-traced reference on a real mesh at low n: the CGAL
// dragon (10k vertices, ../shared/data's chinese_dragon_10kv through the build's data folder)
// on the default scene's ground, n = 8, one bounce, a uniform sky. The same seed makes the two
// direct terms equal bit for bit, so the difference is the indirect estimators'; over 24
// vertices of the model and 24 of the ground its RMS must lie within the reference's own noise
// (2× its RMS standard error, the gather's noise being smaller) and under 2% of B.
TEST(BounceGather, AgreesWithThePathTracedReferenceOnARealMeshWithinItsNoise) {
  SceneDescription scene = DragonOnTheDefaultGround();
  const SceneGeometry g = BuildSceneGeometry(scene);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  TransportSamplerOptions to;
  to.rays_per_texel = 4;
  const TransportSampler sampler(embree, 8, to);
  std::vector<float> direct(samples.size() * sampler.layout().texel_count());
  sampler.ComputeRows(samples, 0, direct.data());
  const BounceGatherer gatherer(embree, surfaces, {1024, 1});
  const CubemapLayout coarse(2);
  const auto bounces = GatherBounces(gatherer, samples, sampler.layout(), coarse, direct, 1, 1);

  PathTraceOptions po;
  po.bounces = 1;
  po.paths = 256;
  po.rays_per_texel = 4;
  const PathTraceReference reference(embree, surfaces, 8, po);
  const std::vector<CubemapRgb> lights{UniformSky(8)};
  const std::size_t model = g.meshes[0].mesh.positions.size();
  for (const auto& [first, last] :
       {std::pair{std::size_t{0}, model}, std::pair{model, samples.size()}}) {
    double diff2 = 0, noise2 = 0, ref2 = 0;
    for (int i = 0; i < 24; ++i) {
      const std::size_t v = first + (last - first) * (2 * i + 1) / 48;
      std::vector<float> row(sampler.layout().texel_count());
      RelitEstimate relit[3];
      PathTraceExtras ex;
      ex.lights = lights;
      ex.relit = relit;
      reference.ComputeRow(samples[v], v, 1, row.data(), ex);
      const auto& b = bounces[0];
      const double gathered =
          std::accumulate(direct.begin() + v * 384, direct.begin() + (v + 1) * 384, 0.0) +
          std::accumulate(b.begin() + v * 24, b.begin() + (v + 1) * 24, 0.0);
      diff2 += (gathered - relit[0].total()) * (gathered - relit[0].total());
      noise2 += relit[0].indirect_standard_error * relit[0].indirect_standard_error;
      ref2 += relit[0].total() * relit[0].total();
    }
    EXPECT_LE(std::sqrt(diff2), 2 * std::sqrt(noise2) + 1e-3 * std::sqrt(ref2))
        << (first == 0 ? "model" : "ground");
    EXPECT_LE(std::sqrt(diff2 / ref2), 0.02) << (first == 0 ? "model" : "ground");
  }
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// The near field: a patch facing down 1 cm above a ground of two huge triangles. The ground
// under it is shadowed by the patch itself, which no ground vertex (all in open sky, ±1000 away)
// knows: interpolation gives ρ_g·1, the truth (the reference, T⁰ traced at every hit) is much
// less. The near field traces T⁰ at those hits and agrees with the reference.
TEST(BounceGather, NearFieldTracesWhatTheVerticesCannotResolve) {
  const float rho = 0.5f;
  const SceneGeometry g = Scene({Grid("down", {-0.05, 0.01, -0.05}, {0.1, 0, 0}, {0, 0, 0.1},
                                      {0, -1, 0}, 2, {0.5f, 0.5f, 0.5f}),
                                 Ground({rho, rho, rho})});
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const auto samples = SpatialSamplesOf(g);
  TransportSamplerOptions to;
  to.rays_per_texel = 4;
  const TransportSampler sampler(embree, 8, to);
  std::vector<float> direct(samples.size() * 384);
  sampler.ComputeRows(samples, 0, direct.data());
  BounceGatherOptions interpolate{1024, 1}, near{1024, 1};
  // On the direct grid itself (n = 8): the sampler's one jittered ray per texel is exact in
  // expectation only for texels small enough that the solid angle is even across them
  // (docs/transport-sampling.md), as the reference's rays at its path vertices are.
  near.indirect_n = 8;
  near.near_rows = 1024;
  const CubemapLayout coarse(8);
  auto uniform = [&](const BounceGatherOptions& o) {
    const BounceGatherer gatherer(embree, surfaces, o);
    const auto b = GatherBounces(gatherer, samples, sampler.layout(), coarse, direct, 1, 1);
    return std::accumulate(b[0].begin(), b[0].begin() + 384, 0.0);  // vertex 0's row
  };
  PathTraceOptions po;
  po.bounces = 1;
  po.paths = 256;
  const PathTraceReference reference(embree, surfaces, 8, po);
  CubemapRgb sky;
  sky.n = 8;
  for (int c = 0; c < 3; ++c) sky.Channel(c).assign(384, 1.0f);
  const std::vector<CubemapRgb> lights{sky};
  RelitEstimate relit[3];
  PathTraceExtras ex;
  ex.lights = lights;
  ex.relit = relit;
  std::vector<float> row(384);
  reference.ComputeRow(samples[0], 0, 1, row.data(), ex);
  const double truth = relit[0].indirect;
  EXPECT_LT(truth, 0.8 * rho);  // the patch's own shadow on the ground
  EXPECT_NEAR(uniform(interpolate), rho, 0.01);
  EXPECT_NEAR(uniform(near), truth, 4 * relit[0].indirect_standard_error + 0.02 * truth);
}

// An image run's gather (docs/image-relighting.md, "Interreflection"): at camera pixels, which
// are not vertices, Σ_k Tᵏ in one gather from the vertices' support rows (T⁰ traced on the
// indirect grid, bounce 1 gathered at the vertices with its near field) against the per-element
// path-traced reference at the same points, two bounces: the CGAL dragon on the default scene's
// ground from the default camera at 40×30, n = 8, a uniform sky. The direct terms are the same
// bits (the same seed and index); over 24 model pixels and 24 ground pixels the RMS difference of
// B must lie within the reference's noise (2× its RMS standard error) plus 1% of B and under 2%
// of B. It fails when the pixels' gather drops T⁰ or the higher bounces at near hits, or reads
// the support rows of the wrong bounce.
// The dragon on the default ground from the default camera at 40×30, with the vertices' support
// rows of a two-bounce pixel gather on the n = 2 indirect grid: T⁰ (16 rays per coarse texel),
// then bounce 1 gathered at every vertex.
struct PixelGatherScene {
  PixelGatherScene()
      : scene(Scene()),
        g(BuildSceneGeometry(scene)),
        embree(g),
        surfaces(g),
        vertices(SpatialSamplesOf(g)),
        pixels(ComputeCameraSamples(embree, surfaces, scene.camera)),
        V(vertices.size()),
        direct(V * cols),
        higher(V * cols) {
    TransportSamplerOptions so;
    so.rays_per_texel = 16;
    so.seed = 11;
    const TransportSampler coarse_sampler(embree, kM, so);
    coarse_sampler.ComputeRows(vertices, 0, direct.data());
    const BounceGatherer gatherer(embree, surfaces, Options(1024));
    std::vector<GatherTerm> terms;
    std::vector<float> near;
    for (uint64_t v = 0; v < V; ++v)
      gatherer.GatherRow(vertices[v], v, 1, 1, direct.data(), V, 1, cols, higher.data() + v * cols,
                         terms, near);
  }
  static SceneDescription Scene() {
    SceneDescription s = DragonOnTheDefaultGround();
    s.camera.width = 40;
    s.camera.height = 30;
    return s;
  }
  static BounceGatherOptions Options(int paths) {
    BounceGatherOptions go;
    go.paths = paths;
    go.indirect_n = kM;
    return go;
  }
  // 24 pixels of mesh m, spread over them (none when it has fewer than 48).
  std::vector<uint64_t> Pixels(uint32_t m) const {
    std::vector<uint64_t> all, out;
    for (uint64_t p = 0; p < pixels.samples.size(); ++p)
      if (pixels.pixel_mesh[p] == m) all.push_back(p);
    for (std::size_t i = 0; i < 24 && all.size() >= 48; ++i)
      out.push_back(all[all.size() * (2 * i + 1) / 48]);
    return out;
  }
  static constexpr int kM = 2;  // the indirect grid
  const std::size_t cols = CubemapLayout(kM).texel_count();
  SceneDescription scene;
  SceneGeometry g;
  EmbreeScene embree;
  SceneSurfaces surfaces;
  std::vector<SpatialSample> vertices;
  CameraSamples pixels;
  uint64_t V;
  std::vector<float> direct, higher;
};

TEST(BounceGather, PixelSumOfBouncesAgreesWithThePathTracedReference) {
  const PixelGatherScene ps;
  const CameraSamples& pixels = ps.pixels;
  const std::size_t cols = ps.cols;
  const BounceGatherer gatherer(ps.embree, ps.surfaces, PixelGatherScene::Options(1024));
  ASSERT_TRUE(gatherer.HasNearField(1, cols));
  const EmbreeScene& embree = ps.embree;
  const SceneSurfaces& surfaces = ps.surfaces;
  TransportSamplerOptions to;
  to.rays_per_texel = 4;
  const TransportSampler sampler(embree, 8, to);
  PathTraceOptions po;
  po.bounces = 2;
  po.paths = 256;
  po.rays_per_texel = 4;
  const PathTraceReference reference(embree, surfaces, 8, po);
  const std::vector<CubemapRgb> lights{UniformSky(8)};
  const std::vector<uint64_t> model = ps.Pixels(0), ground = ps.Pixels(1);
  ASSERT_EQ(model.size(), 24u);
  ASSERT_EQ(ground.size(), 24u);
  BounceGatherer::SumScratch scratch;
  for (const std::vector<uint64_t>* group : {&model, &ground}) {
    double diff2 = 0, noise2 = 0, ref2 = 0, indirect = 0;
    for (const uint64_t p : *group) {
      const SpatialSample& x = pixels.samples[p];
      std::vector<float> row(sampler.layout().texel_count()), sum(cols);
      sampler.ComputeRow(x, p, row.data());
      const GatherStats st =
          gatherer.GatherSumRow(x, p, pixels.pixel_edge[p], 1, ps.direct.data(), ps.higher.data(),
                                ps.V, cols, sum.data(), scratch);
      EXPECT_GT(st.rays_traced, 0u);
      const double gathered = std::accumulate(row.begin(), row.end(), 0.0) +
                              std::accumulate(sum.begin(), sum.end(), 0.0);
      indirect += std::accumulate(sum.begin(), sum.end(), 0.0);
      std::vector<float> ref_row(sampler.layout().texel_count());
      RelitEstimate relit[3];
      PathTraceExtras ex;
      ex.lights = lights;
      ex.relit = relit;
      reference.ComputeRow(x, p, 1, ref_row.data(), ex);
      diff2 += (gathered - relit[0].total()) * (gathered - relit[0].total());
      noise2 += relit[0].indirect_standard_error * relit[0].indirect_standard_error;
      ref2 += relit[0].total() * relit[0].total();
    }
    const char* what = group == &model ? "model" : "ground";
    std::printf("%s: RMS difference %.4f of B, reference noise %.4f, mean indirect %.4f\n", what,
                std::sqrt(diff2 / ref2), std::sqrt(noise2 / ref2), indirect / 24);
    EXPECT_GT(indirect / 24, 0.02) << what;  // the bounces matter here
    EXPECT_LE(std::sqrt(diff2), 2 * std::sqrt(noise2) + 1e-2 * std::sqrt(ref2)) << what;
    EXPECT_LE(std::sqrt(diff2 / ref2), 0.02) << what;
  }
}

// A glossy pixel's gather (GatherLobe): its cosine-distributed directions weighed by
// k_d + π·k_s·f_s estimate ∫ [k_d/π + k_s·f_s(ω, ω_o)]·cos·L_in(ω) dω. Checked against the same
// integral estimated another way: 65,536 stratified uniform directions over the hemisphere, each
// weighed by the BRDF times cosine over the uniform pdf, L_in the same interpolation of the same
// support rows (no near field on either side), over 24 GGX (r = 0.5) model pixels and 24 ground
// pixels under a uniform sky of 1. And with k_s = 0 the lobe gather is the diffuse gather, bit
// for bit. It fails when the lobe's weight is left out (the diffuse gather differs from the
// reference by more than the tolerance, checked) or applied with the cosine twice.
TEST(BounceGather, GlossyPixelGatherIsTheLobeWeightedIntegral) {
  const PixelGatherScene ps;
  BounceGatherOptions go = PixelGatherScene::Options(4096);
  go.near_field = 0;
  const BounceGatherer gatherer(ps.embree, ps.surfaces, go);
  ASSERT_FALSE(gatherer.HasNearField(1, ps.cols));
  GlossyMaterialSettings ggx;
  ggx.brdf = "ggx";
  ggx.roughness = 0.5;
  ggx.specular = {0.6f, 0.6f, 0.6f};
  Material m = MaterialOfSettings(ggx, {0.3f, 0.3f, 0.3f});
  m.diffuse = {1.f / 3, 1.f / 3, 1.f / 3};  // k_d = albedo / (albedo + specular), as glossy pixels
  m.specular = {2.f / 3, 2.f / 3, 2.f / 3};
  Material lambert = m;
  lambert.diffuse = {1.f, 1.f, 1.f};
  lambert.specular = {0.f, 0.f, 0.f};
  const auto row_sum = [&](const std::vector<float>& rows, uint64_t v) {
    const auto first = rows.begin() + static_cast<std::ptrdiff_t>(v * ps.cols);
    return std::accumulate(first, first + static_cast<std::ptrdiff_t>(ps.cols), 0.0);
  };
  BounceGatherer::SumScratch scratch;
  for (uint32_t mesh : {0u, 1u}) {
    double diff2 = 0, diffuse2 = 0, ref2 = 0;
    for (const uint64_t p : ps.Pixels(mesh)) {
      SpatialSample x = ps.pixels.samples[p];
      x.glossy_material = 0;  // materials[0] of the lobe tables below
      const ShadingFrame frame = MakeShadingFrame(x.normal, ps.scene.camera.eye - x.position);
      const std::vector<Material> glossy{m}, diffuse_table{lambert};
      const GatherLobe lobe{glossy, ps.scene.camera.eye}, diffuse_lobe{diffuse_table, lobe.eye};
      GatherSite with_lobe, with_diffuse_lobe;
      with_lobe.lobe = &lobe;
      with_diffuse_lobe.lobe = &diffuse_lobe;
      std::vector<float> sum(ps.cols), plain(ps.cols), kd1(ps.cols);
      gatherer.GatherSumRow(x, p, -1, 1, ps.direct.data(), ps.higher.data(), ps.V, ps.cols,
                            sum.data(), scratch, with_lobe);
      gatherer.GatherSumRow(x, p, -1, 1, ps.direct.data(), ps.higher.data(), ps.V, ps.cols,
                            plain.data(), scratch);
      gatherer.GatherSumRow(x, p, -1, 1, ps.direct.data(), ps.higher.data(), ps.V, ps.cols,
                            kd1.data(), scratch, with_diffuse_lobe);
      EXPECT_EQ(kd1, plain) << p;  // k_d = 1, k_s = 0: the diffuse gather's bits
      // The reference: uniform directions, the weight BRDF·cos over the pdf 1/2π.
      const Vec3 n = x.normal / Length(x.normal);
      Vec3 t, b;
      OrthonormalFrame(n, t, b);
      float above[3], below[3];
      ps.embree.RobustOrigin(x.position, x.geometric_normal, above);
      ps.embree.RobustOrigin(x.position, -x.geometric_normal, below);
      constexpr int kSide = 256;
      double ref = 0;
      for (int i = 0; i < kSide * kSide; ++i) {
        const double z = (i % kSide + 0.5) / kSide, r = std::sqrt(std::max(0.0, 1 - z * z));
        const double phi = 2 * std::numbers::pi * (i / kSide + 0.5) / kSide;
        const Vec3 d = t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * z;
        OcclusionRay ray{};
        std::copy_n(Dot(d, x.geometric_normal) >= 0 ? above : below, 3, ray.origin);
        ray.direction[0] = static_cast<float>(d.x);
        ray.direction[1] = static_cast<float>(d.y);
        ray.direction[2] = static_cast<float>(d.z);
        ray.tfar = std::numeric_limits<float>::infinity();
        RayHit hit;
        SurfaceHit h;
        if (ps.surfaces.Trace(ps.embree, ray, hit, h) != SceneSurfaces::Outcome::kFront) continue;
        double radiance = 0;
        for (int k = 0; k < 3; ++k)
          radiance += h.weights[k] *
                      (row_sum(ps.direct, h.vertices[k]) + row_sum(ps.higher, h.vertices[k]));
        radiance *= ps.surfaces.albedo(h.mesh)[0];
        const double brdf_cos =
            m.diffuse[0] * z / std::numbers::pi + m.specular[0] * SpecularLobe(m, frame, d);
        ref += brdf_cos * radiance * 2 * std::numbers::pi / (kSide * kSide);
      }
      const double got = std::accumulate(sum.begin(), sum.end(), 0.0);
      const double diffuse = std::accumulate(plain.begin(), plain.end(), 0.0);
      diff2 += (got - ref) * (got - ref);
      diffuse2 += (diffuse - ref) * (diffuse - ref);
      ref2 += ref * ref;
    }
    ASSERT_GT(ref2, 0.0);
    std::printf("mesh %u: glossy gather %.4f from the reference, the diffuse gather %.4f\n", mesh,
                std::sqrt(diff2 / ref2), std::sqrt(diffuse2 / ref2));
    EXPECT_LE(std::sqrt(diff2 / ref2), 0.03) << mesh;
    EXPECT_GE(std::sqrt(diffuse2 / ref2), 0.06) << mesh;  // the lobe matters here
  }
}

// A supersampled pixel's gather (docs/image-relighting.md, "Supersampling"): a footprint of one
// sub-sample, the pixel's own point, gives the unsupersampled bytes; a footprint of a model and a
// ground point with λ = (¼, ¾) gathers ¼ and ¾ of their own gathers, within the noise.
TEST(BounceGather, AFootprintGathersTheLambdaMixOfItsSubSamples) {
  SceneDescription scene = DragonOnTheDefaultGround();
  scene.camera.width = 40;
  scene.camera.height = 30;
  const SceneGeometry g = BuildSceneGeometry(scene);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> vertices = SpatialSamplesOf(g);
  const CameraSamples pixels = ComputeCameraSamples(embree, surfaces, scene.camera);
  const uint64_t V = vertices.size();
  constexpr int kM = 2;
  const std::size_t cols = CubemapLayout(kM).texel_count();
  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  const TransportSampler coarse_sampler(embree, kM, so);
  std::vector<float> direct(V * cols);
  coarse_sampler.ComputeRows(vertices, 0, direct.data());
  BounceGatherOptions go;
  go.paths = 4096;
  go.indirect_n = kM;
  go.near_field = 0;  // the near field's thinned rows are far noisier than the mix tested here
  const BounceGatherer gatherer(embree, surfaces, go);
  uint64_t model = 0, ground = 0;
  for (uint64_t p = 0; p < pixels.samples.size(); ++p) {
    if (pixels.pixel_mesh[p] == 0) model = p;  // the last: the model's foot, lit by the ground
    if (pixels.pixel_mesh[p] == 1 && pixels.samples[p].position.y < 0.01 &&
        std::abs(pixels.samples[p].position.x) < 0.3)
      ground = p;
  }
  ASSERT_GT(model, 0u);
  ASSERT_GT(ground, 0u);
  BounceGatherer::SumScratch scratch;
  auto gather = [&](uint64_t p, const GatherSite& site) {
    std::vector<float> sum(cols);
    gatherer.GatherSumRow(pixels.samples[p], p, pixels.pixel_edge[p], 1, direct.data(), nullptr, V,
                          cols, sum.data(), scratch, site);
    return sum;
  };
  SampleFootprints fp;
  fp.subs = {pixels.samples[model], pixels.samples[model], pixels.samples[ground]};
  fp.edge = {pixels.pixel_edge[model], pixels.pixel_edge[model], pixels.pixel_edge[ground]};
  fp.cdf = {1.0, 0.25, 1.0};
  GatherSite one;
  one.footprint = &fp;
  one.first = 0;
  one.count = 1;
  EXPECT_TRUE(gather(model, one) == gather(model, {}));
  GatherSite two;
  two.footprint = &fp;
  two.first = 1;
  two.count = 2;
  const std::vector<float> mixed = gather(model, two);
  const std::vector<float> a = gather(model, {}), b = gather(ground, {});
  const double m = std::accumulate(mixed.begin(), mixed.end(), 0.0);
  const double want = 0.25 * std::accumulate(a.begin(), a.end(), 0.0) +
                      0.75 * std::accumulate(b.begin(), b.end(), 0.0);
  EXPECT_GT(want, 0.0);
  EXPECT_NEAR(m, want, 0.05 * want) << std::accumulate(a.begin(), a.end(), 0.0) << " "
                                    << std::accumulate(b.begin(), b.end(), 0.0);
}
}  // namespace
}  // namespace prt
