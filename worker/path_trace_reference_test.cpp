#include "worker/path_trace_reference.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/errors.h"
#include "vocabulary/mesh.h"

namespace prt {
namespace {

constexpr double kPi = std::numbers::pi;

// A scene ready to trace: geometry, Embree scene, surfaces and the vertex samples (the scene and
// surfaces refer to the geometry, so it stays where it is).
class Built {
 public:
  explicit Built(SceneGeometry g)
      : geometry(std::move(g)),
        scene(geometry),
        surfaces(geometry),
        samples(SpatialSamplesOf(geometry)) {}
  const SceneGeometry geometry;
  const EmbreeScene scene;
  const SceneSurfaces surfaces;
  const std::vector<SpatialSample> samples;
};

SceneMesh MakeMesh(const std::string& name, std::vector<Vec3> positions,
                   std::vector<std::array<uint32_t, 3>> triangles, Vec3 normal, Rgb albedo) {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name;
  m.mesh.normals.assign(positions.size(), normal);
  m.mesh.positions = std::move(positions);
  m.mesh.triangles = std::move(triangles);
  m.albedo = albedo;
  return m;
}

// A 2000×2000 square on y = 0 (two triangles), normals and winding up; `flipped` turns both
// down (FlipWinding), so its front faces the void below.
SceneMesh Ground(Rgb albedo, bool flipped = false) {
  const double h = 1000;
  SceneMesh m = MakeMesh("ground", {{-h, 0, -h}, {-h, 0, h}, {h, 0, h}, {h, 0, -h}},
                         {{{0, 1, 2}}, {{0, 2, 3}}}, {0, 1, 0}, albedo);
  m.is_ground = true;
  if (flipped) FlipWinding(m.mesh);
  return m;
}

// A tiny square patch (half-side 0.005) centred at c with unit normal `normal`, as a fan of four
// triangles around its centre vertex (local index 0), wound to face `normal`.
SceneMesh Patch(const std::string& name, Vec3 c, Vec3 normal, Rgb albedo = {0.5f, 0.5f, 0.5f}) {
  Vec3 t, b;
  OrthonormalFrame(normal, t, b);
  const double s = 0.005;
  std::vector<Vec3> p = {c, c + (t + b) * s, c + (b - t) * s, c - (t + b) * s, c + (t - b) * s};
  std::vector<std::array<uint32_t, 3>> tris;
  for (uint32_t i = 1; i <= 4; ++i) {
    std::array<uint32_t, 3> tri = {0, i, i % 4 + 1};
    if (Dot(Cross(p[tri[1]] - p[0], p[tri[2]] - p[0]), normal) < 0) std::swap(tri[1], tri[2]);
    tris.push_back(tri);
  }
  return MakeMesh(name, std::move(p), std::move(tris), normal, albedo);
}

// Sample indices in PatchScene: the vertical patch's centre, the downward patch's centre.
constexpr uint64_t kVertical = 0;
constexpr uint64_t kDown = 5;

// A vertical patch (normal +X) at height 1 and a downward patch 5 units away, above the ground.
SceneGeometry PatchScene(Rgb ground_albedo, bool flipped_ground = false) {
  SceneGeometry g;
  g.meshes = {Patch("vertical", {0, 1, 0}, {1, 0, 0}), Patch("down", {5, 1, 0}, {0, -1, 0}),
              Ground(ground_albedo, flipped_ground)};
  return g;
}

// The inside of a unit sphere with a cap opening at the top: the opening's rim is the ring of
// polar angle θ_c (cos θ_c = cos_cap), `rings` rings of `segments` vertices from the rim down to
// the pole at −Y (the last vertex, index rings·segments). Normals point to the centre, and so
// does every triangle's winding. From any point inside a sphere, each part of it has the form
// factor of its area over 4πR²: the opening's (cap) fraction f = (1 − cos θ_c)/2 of the uniform
// sky enters at every point, and each bounce sees a fraction 1 − f of wall, so under a uniform
// sky Tᵏ = f·(ρ(1 − f))ᵏ at every point (up to the polygonal approximation).
SceneMesh OpenSphere(double cos_cap, int rings, int segments, Rgb albedo) {
  const double theta_c = std::acos(cos_cap);
  std::vector<Vec3> p;
  for (int i = 0; i < rings; ++i) {
    const double theta = theta_c + (kPi - theta_c) * i / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2 * kPi * s / segments;
      p.push_back(
          {std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi)});
    }
  }
  p.push_back({0, -1, 0});
  const auto at = [segments](int i, int s) {
    return static_cast<uint32_t>(i * segments + (s % segments));
  };
  std::vector<std::array<uint32_t, 3>> tris;
  const uint32_t pole = static_cast<uint32_t>(p.size() - 1);
  for (int i = 0; i < rings; ++i) {
    for (int s = 0; s < segments; ++s) {
      if (i + 1 < rings) {
        tris.push_back({at(i, s), at(i + 1, s), at(i + 1, s + 1)});
        tris.push_back({at(i, s), at(i + 1, s + 1), at(i, s + 1)});
      } else {
        tris.push_back({at(i, s), pole, at(i, s + 1)});
      }
    }
  }
  for (auto& t : tris) {  // wind towards the centre
    const Vec3 c = (p[t[0]] + p[t[1]] + p[t[2]]) / 3;
    if (Dot(Cross(p[t[1]] - p[t[0]], p[t[2]] - p[t[0]]), c) > 0) std::swap(t[1], t[2]);
  }
  SceneMesh m = MakeMesh("open sphere", p, std::move(tris), {}, albedo);
  for (std::size_t i = 0; i < p.size(); ++i) m.mesh.normals[i] = -p[i];
  return m;
}

// Form factor from the sphere's pole (normal +Y) to the polygonal opening (the rim ring), by the
// contour integral F = (1/2π) Σ_i γ_i · n·(v_i × v_{i+1})/|v_i × v_{i+1}|, γ_i the angle between
// the rim vertices v_i, v_{i+1} seen from the pole.
double PoleToOpeningFormFactor(double cos_cap, int segments) {
  const double theta_c = std::acos(cos_cap);
  double f = 0;
  for (int s = 0; s < segments; ++s) {
    auto rim = [&](int k) {
      const double phi = 2 * kPi * k / segments;
      return Vec3{std::sin(theta_c) * std::cos(phi), cos_cap + 1,
                  std::sin(theta_c) * std::sin(phi)};
    };
    const Vec3 a = rim(s), b = rim(s + 1);
    const Vec3 c = Cross(a, b);
    const double gamma = std::acos(std::clamp(Dot(a, b) / (Length(a) * Length(b)), -1.0, 1.0));
    f += gamma * std::abs(c.y) / Length(c);
  }
  return f / (2 * kPi);
}

CubemapRgb Uniform(int n, Rgb radiance = {1, 1, 1}) {
  CubemapRgb l;
  l.n = n;
  const std::size_t t = static_cast<std::size_t>(6) * n * n;
  l.r.assign(t, radiance[0]);
  l.g.assign(t, radiance[1]);
  l.b.assign(t, radiance[2]);
  return l;
}

// One vertex's row, its per-bounce rows and its relit estimates under a uniform sky of 1.
struct Result {
  std::vector<float> row;
  std::vector<float> bounces;
  std::array<RelitEstimate, 3> relit;
  PathTraceStats stats;
  // Σ_j of bounce k's row, channel c.
  double BounceSum(int k, int c, int channels, std::size_t texels) const {
    const float* b = bounces.data() + (static_cast<std::size_t>(k) * channels + c) * texels;
    return std::accumulate(b, b + texels, 0.0);
  }
};

Result Compute(const PathTraceReference& ref, const Built& b, uint64_t index, int channels = 3) {
  const std::size_t m = ref.layout().texel_count();
  Result r;
  r.row.assign(channels * m, -1.0f);
  r.bounces.assign((ref.options().bounces + 1) * channels * m, -1.0f);
  const CubemapRgb sky = Uniform(ref.layout().n());
  PathTraceExtras extras;
  extras.bounce_rows = r.bounces.data();
  extras.lights = std::span<const CubemapRgb>(&sky, 1);
  extras.relit = r.relit.data();
  r.stats = ref.ComputeRow(b.samples.at(index), index, channels, r.row.data(), extras);
  return r;
}

double Sum(const float* v, std::size_t count) {
  return std::accumulate(v, v + count, 0.0);
}

// Test 1 of the issue. Ground albedo ρ_g = 0.5 under a uniform sky of radiance 1: the ground's
// irradiance is 1 (its direct row sums to 1), so it sends ρ_g up. A vertical patch sees sky in
// its upper quarter-sphere (0.5 direct) and ground in the lower (0.5·ρ_g after one bounce); a
// patch facing down sees only ground (0 direct, ρ_g). The ground is finite (±1000 at height 1):
// a band of 10⁻³ rad below the horizon is sky, worth ≲ 6·10⁻⁴ of the vertical patch's direct
// light; the direct rows' jitter bias at n = 8 is ~10⁻³ (docs/transport-sampling.md): both are
// in the absolute allowance.
TEST(PathTraceReference, PatchAboveGroundGetsHalfPlusHalfTheGroundAlbedo) {
  const double rho = 0.5;
  const Built b(PatchScene({0.5f, 0.5f, 0.5f}));
  PathTraceOptions o;
  o.bounces = 1;
  o.paths = 256;
  o.rays_per_texel = 4;
  o.seed = 7;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  const std::size_t m = ref.layout().texel_count();
  EXPECT_EQ(ref.paths_u() * ref.paths_v(), 256);

  const Result v = Compute(ref, b, kVertical);
  const Result d = Compute(ref, b, kDown);
  std::printf("vertical: direct %.5f ± %.5f, indirect %.5f ± %.5f (expected 0.5, %.3f)\n",
              v.relit[0].direct, v.relit[0].direct_standard_error, v.relit[0].indirect,
              v.relit[0].indirect_standard_error, 0.5 * rho);
  std::printf("down: direct %.6f, indirect %.5f ± %.5f (expected 0, %.3f)\n", d.relit[0].direct,
              d.relit[0].indirect, d.relit[0].indirect_standard_error, rho);
  for (int c = 0; c < 3; ++c) {
    const RelitEstimate& ve = v.relit[c];
    EXPECT_NEAR(ve.direct, 0.5, 4 * ve.direct_standard_error + 2e-3);
    EXPECT_NEAR(ve.indirect, 0.5 * rho, 4 * ve.indirect_standard_error + 2e-3);
    EXPECT_NEAR(ve.total(), 0.5 + 0.5 * rho, 4 * ve.standard_error() + 3e-3);
    EXPECT_GT(ve.indirect_standard_error, 0.0);
    EXPECT_LT(ve.standard_error(), 0.01);  // a useful test: the noise is small
    const RelitEstimate& de = d.relit[c];
    EXPECT_LT(de.direct, 1e-5);
    EXPECT_NEAR(de.indirect, rho, 4 * de.indirect_standard_error + 2e-3);
    EXPECT_LT(de.standard_error(), 0.01);
    // The row is the estimate: Σ_j T_c[j] equals the relit total (float rounding apart), and the
    // bounce rows are its terms.
    EXPECT_NEAR(Sum(v.row.data() + c * m, m), ve.total(), 1e-5);
    EXPECT_NEAR(Sum(d.row.data() + c * m, m), de.total(), 1e-5);
    EXPECT_NEAR(v.BounceSum(0, c, 3, m), ve.direct, 1e-6);
    EXPECT_NEAR(v.BounceSum(1, c, 3, m), ve.indirect, 1e-5);
  }
  // Counters: one segment per path (K = 1); from the vertical patch about half hit the ground.
  EXPECT_EQ(v.stats.intersect_rays, 256u);
  EXPECT_EQ(v.stats.path_vertices + v.stats.escaped + v.stats.back_faces, 256u);
  EXPECT_NEAR(static_cast<double>(v.stats.path_vertices), 128, 8);
  EXPECT_EQ(d.stats.path_vertices, 256u);
  EXPECT_GT(d.stats.shadow_rays, 256u * 100u);  // a direct row (~192 rays at n = 8) per hit
  EXPECT_EQ(v.stats.rays_traced(), v.stats.intersect_rays + v.stats.shadow_rays);
}

// Back faces absorb: with the ground turned over (its front faces down), it still hides the
// lower half from the vertical patch, but what reaches its back brings nothing: exactly 0.5 of
// direct light and no indirect light, for every path.
TEST(PathTraceReference, BackFacesOccludeButDoNotReflect) {
  const Built b(PatchScene({0.5f, 0.5f, 0.5f}, /*flipped_ground=*/true));
  PathTraceOptions o;
  o.bounces = 2;
  o.paths = 64;
  o.seed = 7;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  const Result v = Compute(ref, b, kVertical);
  const Result d = Compute(ref, b, kDown);
  std::printf("flipped ground: vertical direct %.5f indirect %.5f, down %.6f %.5f\n",
              v.relit[0].direct, v.relit[0].indirect, d.relit[0].direct, d.relit[0].indirect);
  EXPECT_NEAR(v.relit[0].direct, 0.5, 2e-3);
  EXPECT_EQ(v.relit[0].indirect, 0.0);
  EXPECT_EQ(d.relit[0].indirect, 0.0);
  EXPECT_EQ(v.stats.path_vertices, 0u);
  EXPECT_NEAR(static_cast<double>(v.stats.back_faces), 32, 6);
  EXPECT_EQ(v.stats.back_faces + v.stats.escaped, 64u);
  EXPECT_EQ(d.stats.back_faces, 64u);
  const std::size_t m = ref.layout().texel_count();
  for (int c = 0; c < 3; ++c) {
    for (std::size_t j = 0; j < m; ++j) {
      ASSERT_EQ(v.row[c * m + j], v.bounces[j]);  // T = T⁰
    }
  }
}

// K = 0 is the direct row: TransportSampler::ComputeRow with the same rays per texel and seed,
// bit for bit, in every channel and in the bounce output; the counters are its rays.
TEST(PathTraceReference, ZeroBouncesIsTheDirectRowBitForBit) {
  const Built b(PatchScene({0.8f, 0.1f, 0.1f}));
  PathTraceOptions o;
  o.bounces = 0;
  o.paths = 16;
  o.rays_per_texel = 4;
  o.seed = 31;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  const TransportSampler direct(b.scene, 8, {4, 31});
  const std::size_t m = ref.layout().texel_count();
  for (uint64_t i : {kVertical, kDown, uint64_t{3}, uint64_t{11}}) {
    std::vector<float> t0(m);
    const SampleStats st = direct.ComputeRow(b.samples[i], i, t0.data());
    const Result r = Compute(ref, b, i);
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(0, std::memcmp(r.row.data() + c * m, t0.data(), m * sizeof(float))) << i;
      EXPECT_EQ(0, std::memcmp(r.bounces.data() + c * m, t0.data(), m * sizeof(float))) << i;
      EXPECT_EQ(r.relit[c].indirect, 0.0);
    }
    EXPECT_EQ(r.stats.shadow_rays, st.rays_traced);
    EXPECT_EQ(r.stats.intersect_rays, 0u);
  }
  // With bounces, T⁰ is still that row (bounce 0), whatever the path options.
  o.bounces = 2;
  o.path_rays_per_texel = 2;
  const PathTraceReference with_paths(b.scene, b.surfaces, 8, o);
  std::vector<float> t0(m);
  direct.ComputeRow(b.samples[kVertical], kVertical, t0.data());
  const Result r = Compute(with_paths, b, kVertical);
  EXPECT_EQ(0, std::memcmp(r.bounces.data() + 2 * m, t0.data(), m * sizeof(float)));
}

// Energy: inside an open sphere (concave), bounce k + 1 carries at most ρ_c times bounce k, per
// channel: there it is ρ_c·(1 − f) times, f the opening's fraction, at every point. Coloured
// albedo, so that each channel has its own ratio (ρ_max = 0.9). Tolerances: 4 standard errors of
// the two bounces (their own estimates) and 2% for the polygonal sphere and the direct rows'
// jitter bias.
TEST(PathTraceReference, EachBounceCarriesAtMostTheAlbedoTimesThePrevious) {
  const double cos_cap = 0.5;  // f = 0.25
  const int rings = 16, segments = 48;
  const Rgb rho = {0.9f, 0.6f, 0.3f};
  SceneGeometry g;
  g.meshes = {OpenSphere(cos_cap, rings, segments, rho)};
  const Built b(std::move(g));
  PathTraceOptions o;
  o.bounces = 3;
  o.paths = 1024;
  o.rays_per_texel = 16;
  o.seed = 3;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  const std::size_t m = ref.layout().texel_count();
  const double f = PoleToOpeningFormFactor(cos_cap, segments);
  const uint64_t pole = rings * segments, side = (rings / 2) * segments + 5;
  for (uint64_t i : {pole, side}) {
    const Result r = Compute(ref, b, i);
    for (int c = 0; c < 3; ++c) {
      const RelitEstimate& e = r.relit[c];
      std::printf(
          "sphere vertex %llu channel %d: E_k = %.5f %.5f %.5f %.5f "
          "(± %.5f %.5f %.5f %.5f), E_k+1/E_k = %.4f %.4f %.4f; ρ(1−f) = %.4f, f = %.4f\n",
          static_cast<unsigned long long>(i), c, e.bounce[0], e.bounce[1], e.bounce[2], e.bounce[3],
          e.bounce_standard_error[0], e.bounce_standard_error[1], e.bounce_standard_error[2],
          e.bounce_standard_error[3], e.bounce[1] / e.bounce[0], e.bounce[2] / e.bounce[1],
          e.bounce[3] / e.bounce[2], rho[c] * (1 - f), f);
      EXPECT_NEAR(e.bounce[0], f, 4 * e.bounce_standard_error[0] + 0.02 * f);
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(r.BounceSum(k + 1, c, 3, m), e.bounce[k + 1], 1e-5);
        const double noise =
            std::hypot(e.bounce_standard_error[k + 1], rho[c] * e.bounce_standard_error[k]);
        EXPECT_LE(e.bounce[k + 1], rho[c] * e.bounce[k] + 4 * noise) << k;
        EXPECT_NEAR(e.bounce[k + 1], rho[c] * (1 - f) * e.bounce[k],
                    4 * noise + 0.02 * e.bounce[k + 1])
            << k;
      }
    }
  }
}

// Furnace: albedo 1 inside the open sphere under a uniform sky of 1. T⁰ = f at every point and
// each bounce adds f(1 − f)ᵏ, so with K bounces Σ_j T[j] = 1 − (1 − f)^{K+1}: it grows with K,
// monotonically, towards 1 (B = 1 everywhere, the furnace). The same seed gives the same paths,
// K + 1 extending those of K, so the rows grow element by element (K = 0…8 at the pole). At
// three vertices with K = 8, the series' tail E_8·(1 − f)/f that K = 8 leaves out brings the
// total to 1.
TEST(PathTraceReference, FurnaceEnclosureTendsToOneMonotonicallyInTheBounces) {
  const double cos_cap = 0.5;
  const int rings = 16, segments = 48;
  SceneGeometry g;
  g.meshes = {OpenSphere(cos_cap, rings, segments, {1, 1, 1})};
  const Built b(std::move(g));
  const double f = PoleToOpeningFormFactor(cos_cap, segments);
  const uint64_t pole = rings * segments;
  const auto expected = [f](int k) { return 1 - std::pow(1 - f, k + 1); };
  std::vector<float> previous;
  for (int k = 0; k <= 8; ++k) {
    PathTraceOptions o;
    o.bounces = k;
    o.paths = 256;
    o.rays_per_texel = 16;
    o.seed = 5;
    const PathTraceReference ref(b.scene, b.surfaces, 8, o);
    const Result r = Compute(ref, b, pole, 1);
    const RelitEstimate& e = r.relit[0];
    std::printf("furnace K = %d, pole: %.5f ± %.5f, expected %.5f\n", k, e.total(),
                e.standard_error(), expected(k));
    EXPECT_NEAR(e.total(), expected(k), 4 * e.standard_error() + 0.01 * expected(k)) << k;
    if (k > 0) {
      for (std::size_t j = 0; j < r.row.size(); ++j) {
        ASSERT_GE(r.row[j], previous[j]) << "K = " << k << " texel " << j;
      }
      EXPECT_GT(Sum(r.row.data(), r.row.size()), Sum(previous.data(), r.row.size()));
    }
    previous = r.row;
  }
  PathTraceOptions o;
  o.bounces = 8;
  o.paths = 2048;
  o.rays_per_texel = 16;
  o.seed = 6;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  for (uint64_t v : {pole, uint64_t{(rings / 2) * segments + 7}, uint64_t{2 * segments + 20}}) {
    const RelitEstimate e = Compute(ref, b, v, 1).relit[0];
    const double tail = e.bounce[8] * (1 - f) / f;
    std::printf("furnace K = 8, vertex %llu: %.5f ± %.5f (expected %.5f), with the tail %.5f\n",
                static_cast<unsigned long long>(v), e.total(), e.standard_error(), expected(8),
                e.total() + tail);
    EXPECT_NEAR(e.total(), expected(8), 4 * e.standard_error() + 0.01);
    EXPECT_NEAR(e.total() + tail, 1.0,
                4 * (e.standard_error() + e.bounce_standard_error[8] * (1 - f) / f) + 0.01);
    for (int k = 1; k <= 8; ++k) EXPECT_LT(e.bounce[k], e.bounce[k - 1]) << k;
  }
}
// A red ground tints the patch: the indirect part of each channel is ρ_c times the same paths'
// grey sum, so the channels' ratios are the albedo's (to float rounding: with K = 1 every path
// contribution is ρ_c·T̂⁰[y]), and each is 0.5·ρ_c within the noise.
TEST(PathTraceReference, ColouredGroundTintsTheIndirectLightByItsAlbedo) {
  const Rgb red = {0.8f, 0.1f, 0.1f};
  const Built b(PatchScene(red));
  PathTraceOptions o;
  o.bounces = 1;
  o.paths = 64;
  o.seed = 11;
  const PathTraceReference ref(b.scene, b.surfaces, 8, o);
  const std::size_t m = ref.layout().texel_count();
  EXPECT_FALSE(ref.ChannelsAllowed(1));
  EXPECT_TRUE(ref.ChannelsAllowed(3));
  std::vector<float> row(m);
  EXPECT_THROW(ref.ComputeRow(b.samples[0], 0, 1, row.data()), std::invalid_argument);
  for (uint64_t i : {kVertical, kDown}) {
    const Result r = Compute(ref, b, i);
    std::printf("red ground, vertex %llu: indirect %.5f %.5f %.5f\n",
                static_cast<unsigned long long>(i), r.relit[0].indirect, r.relit[1].indirect,
                r.relit[2].indirect);
    const double weight = i == kVertical ? 0.5 : 1.0;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(r.relit[c].indirect / r.relit[0].indirect, red[c] / red[0], 1e-6);
      EXPECT_NEAR(r.BounceSum(1, c, 3, m) / r.BounceSum(1, 0, 3, m), red[c] / red[0], 1e-5);
      EXPECT_NEAR(r.relit[c].indirect, weight * red[c],
                  4 * r.relit[c].indirect_standard_error + 2e-3);
      for (std::size_t j = 0; j < m; ++j) {  // texel by texel too
        const double i0 = r.bounces[m * 3 + j];
        ASSERT_NEAR(r.bounces[m * 3 + c * m + j], i0 * red[c] / red[0], 1e-6 * i0 + 1e-12);
      }
    }
  }
}

// Determinism: the same seed gives the same bytes whether rows come one at a time or in
// batches starting anywhere, on 1 or 4 threads (rows, bounce rows, relit estimates, counters);
// with grey albedo one channel is channel 0 of three, bit for bit.
TEST(PathTraceReference, RowsAreBitIdenticalWhateverTheThreadsOrBatch) {
  SceneGeometry g = PatchScene({0.5f, 0.5f, 0.5f});
  g.meshes.insert(g.meshes.begin(), OpenSphere(0.5, 6, 12, {0.7f, 0.7f, 0.7f}));
  for (Vec3& p : g.meshes[0].mesh.positions) p = p + Vec3{-3, 1.5, 0};
  const Built b(std::move(g));
  PathTraceOptions o;
  o.bounces = 3;
  o.paths = 12;
  o.path_rays_per_texel = 2;
  o.seed = 99;
  const PathTraceReference ref(b.scene, b.surfaces, 4, o);
  const std::size_t count = 24;  // sphere and patches
  const std::span<const SpatialSample> samples(b.samples.data(), count);
  const std::size_t m = ref.layout().texel_count();
  const std::size_t row = 3 * m, bounce = 4 * row;
  const std::array<CubemapRgb, 2> lights = {Uniform(4), Uniform(4, {2, 0.5f, 0})};
  std::vector<float> rows(count * row), bounces(count * bounce);
  std::vector<RelitEstimate> relit(count * 6);
  PathTraceStats stats;
  for (std::size_t i = 0; i < count; ++i) {
    PathTraceExtras e;
    e.bounce_rows = bounces.data() + i * bounce;
    e.lights = lights;
    e.relit = relit.data() + i * 6;
    stats += ref.ComputeRow(samples[i], 1000 + i, 3, rows.data() + i * row, e);
  }
  EXPECT_GT(stats.path_vertices, 0u);
  const auto same = [](const auto& x, const auto& y) {
    return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0;
  };
  for (int threads : {1, 4}) {
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, threads);
    tbb::task_arena arena(threads);
    std::vector<float> rows2(rows.size(), -1.0f), bounces2(bounces.size(), -1.0f);
    std::vector<RelitEstimate> relit2(relit.size());
    PathTraceStats st;
    arena.execute([&] {
      // Two batches, the second starting in the middle.
      for (std::size_t first : {std::size_t{0}, std::size_t{7}}) {
        const std::size_t n = first == 0 ? 7 : count - 7;
        PathTraceExtras e;
        e.bounce_rows = bounces2.data() + first * bounce;
        e.lights = lights;
        e.relit = relit2.data() + first * 6;
        st += ref.ComputeRows(samples.subspan(first, n), 1000 + first, 3,
                              rows2.data() + first * row, e);
      }
    });
    EXPECT_TRUE(same(rows, rows2)) << threads;
    EXPECT_TRUE(same(bounces, bounces2)) << threads;
    EXPECT_EQ(0, std::memcmp(relit.data(), relit2.data(), relit.size() * sizeof(RelitEstimate)));
    EXPECT_EQ(st, stats);
  }
  // Asking for less changes nothing; one channel is channel 0.
  std::vector<float> alone(row), grey(m);
  ref.ComputeRow(samples[3], 1003, 3, alone.data());
  ref.ComputeRow(samples[3], 1003, 1, grey.data());
  EXPECT_EQ(0, std::memcmp(alone.data(), rows.data() + 3 * row, row * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(grey.data(), rows.data() + 3 * row, m * sizeof(float)));
  // Another seed or another global index gives other paths.
  ref.ComputeRow(samples[3], 1004, 3, alone.data());
  EXPECT_NE(0, std::memcmp(alone.data(), rows.data() + 3 * row, row * sizeof(float)));
}

// The reported standard error of the indirect part is the spread of independent seeds: at a
// wall vertex of the open sphere (K = 2), over 60 seeds, with 2×2 blocks (16 paths, 4×4) and with
// pairs (12 paths, 4×3).
TEST(PathTraceReference, IndirectStandardErrorMatchesTheSpreadOfIndependentSeeds) {
  SceneGeometry g;
  g.meshes = {OpenSphere(0.5, 8, 24, {0.8f, 0.8f, 0.8f})};
  const Built b(std::move(g));
  const uint64_t vertex = 4 * 24 + 3;
  for (int paths : {16, 12}) {
    double sum = 0, sum2 = 0, reported2 = 0;
    const int seeds = 60;
    for (int s = 0; s < seeds; ++s) {
      PathTraceOptions o;
      o.bounces = 2;
      o.paths = paths;
      o.seed = 1000 + static_cast<uint64_t>(s);
      const PathTraceReference ref(b.scene, b.surfaces, 4, o);
      const Result r = Compute(ref, b, vertex, 1);
      sum += r.relit[0].indirect;
      sum2 += r.relit[0].indirect * r.relit[0].indirect;
      reported2 += r.relit[0].indirect_standard_error * r.relit[0].indirect_standard_error;
    }
    const double mean = sum / seeds;
    const double measured = std::sqrt((sum2 - seeds * mean * mean) / (seeds - 1));
    const double reported = std::sqrt(reported2 / seeds);
    std::printf(
        "%d paths: indirect %.5f, spread of seeds %.5f, reported standard error %.5f "
        "(ratio %.3f)\n",
        paths, mean, measured, reported, reported / measured);
    EXPECT_GT(reported / measured, 0.7);
    EXPECT_LT(reported / measured, 1.8);  // conservative with pairs (see RelitEstimate)
  }
}

TEST(PathTraceReference, RejectsBadOptions) {
  const Built b(PatchScene({0.5f, 0.5f, 0.5f}));
  const auto make = [&](int bounces, int paths, int k, int n) {
    PathTraceOptions o;
    o.bounces = bounces;
    o.paths = paths;
    o.path_rays_per_texel = k;
    return PathTraceReference(b.scene, b.surfaces, n, o);
  };
  EXPECT_THROW(make(9, 4, 1, 8), std::invalid_argument);
  EXPECT_THROW(make(-1, 4, 1, 8), std::invalid_argument);
  EXPECT_THROW(make(1, 0, 1, 8), std::invalid_argument);
  EXPECT_THROW(make(1, 65537, 1, 8), std::invalid_argument);
  EXPECT_THROW(make(1, 4, 0, 8), std::invalid_argument);
  EXPECT_THROW(make(1, 4, 1, 6), std::invalid_argument);
  const PathTraceReference ref = make(1, 4, 1, 8);
  EXPECT_TRUE(ref.ChannelsAllowed(1));
  EXPECT_FALSE(ref.ChannelsAllowed(2));
  std::vector<float> row(3 * ref.layout().texel_count());
  EXPECT_THROW(ref.ComputeRow(b.samples[0], 0, 2, row.data()), std::invalid_argument);
  const CubemapRgb wrong = Uniform(4);
  std::vector<RelitEstimate> relit(3);
  PathTraceExtras e;
  e.lights = std::span<const CubemapRgb>(&wrong, 1);
  e.relit = relit.data();
  EXPECT_THROW(ref.ComputeRow(b.samples[0], 0, 3, row.data(), e), std::invalid_argument);
  SpatialSample bad = b.samples[0];
  bad.position.x = std::nan("");
  EXPECT_THROW(ref.ComputeRow(bad, 0, 3, row.data()), NumericalError);
}

}  // namespace
}  // namespace prt
