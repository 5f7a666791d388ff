#include "worker/transport_sampler.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <numeric>
#include <string>
#include <vector>

#include "vocabulary/errors.h"

namespace prt {
namespace {

constexpr double kPi = std::numbers::pi;

// A rigid placement p ↦ R·(scale·p) + offset, R a rotation given by its columns.
struct Placement {
  double scale = 1.0;
  Vec3 offset{0, 0, 0};
  Vec3 c0{1, 0, 0}, c1{0, 1, 0}, c2{0, 0, 1};
  Vec3 Rotate(const Vec3& v) const { return c0 * v.x + c1 * v.y + c2 * v.z; }
  Vec3 Point(const Vec3& p) const { return Rotate(p * scale) + offset; }
};

// A generic rotation (axis (1, 2, 3), 0.7 rad) by Rodrigues' formula.
Placement Rotated(double scale, Vec3 offset) {
  const Vec3 k = Normalize(Vec3{1, 2, 3});
  const double a = 0.7, c = std::cos(a), s = std::sin(a);
  auto rot = [&](const Vec3& v) { return v * c + Cross(k, v) * s + k * (Dot(k, v) * (1 - c)); };
  Placement p;
  p.scale = scale;
  p.offset = offset;
  p.c0 = rot({1, 0, 0});
  p.c1 = rot({0, 1, 0});
  p.c2 = rot({0, 0, 1});
  return p;
}

SceneMesh MakeMesh(const std::string& name, std::vector<Vec3> positions,
                   std::vector<std::array<uint32_t, 3>> triangles, const Placement& place,
                   Vec3 normal = {0, 1, 0}) {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name;
  for (Vec3& p : positions) p = place.Point(p);
  m.mesh.normals.assign(positions.size(), Normalize(place.Rotate(normal)));
  m.mesh.positions = std::move(positions);
  m.mesh.triangles = std::move(triangles);
  return m;
}

// A res×res grid on y = 0 over [−half, half]², row-major with x fastest (scene.h's ground).
SceneMesh Grid(int res, double half, const Placement& place = {}) {
  std::vector<Vec3> p;
  std::vector<std::array<uint32_t, 3>> t;
  for (int j = 0; j < res; ++j) {
    for (int i = 0; i < res; ++i) {
      p.push_back({-half + 2 * half * i / (res - 1), 0, -half + 2 * half * j / (res - 1)});
    }
  }
  for (int j = 0; j + 1 < res; ++j) {
    for (int i = 0; i + 1 < res; ++i) {
      const auto a = static_cast<uint32_t>(j * res + i), b = a + 1;
      const auto c = static_cast<uint32_t>(a + res), d = c + 1;
      t.push_back({a, c, b});
      t.push_back({b, c, d});
    }
  }
  SceneMesh m = MakeMesh("ground", std::move(p), std::move(t), place);
  m.is_ground = true;
  m.grid_resolution = res;
  return m;
}

// A box [−half, half] × [0, height] × [−half, half] as one mesh with shared corners: the floor
// is a fan around its centre vertex (index 8, normal +Y); the top is left out when open.
SceneMesh Box(double half, double height, bool closed, const Placement& place = {}) {
  const double a = half, h = height;
  std::vector<Vec3> p = {{-a, 0, -a}, {a, 0, -a}, {a, 0, a},  {-a, 0, a}, {-a, h, -a},
                         {a, h, -a},  {a, h, a},  {-a, h, a}, {0, 0, 0}};
  std::vector<std::array<uint32_t, 3>> t = {{8, 1, 0}, {8, 2, 1}, {8, 3, 2}, {8, 0, 3}};
  for (uint32_t i = 0; i < 4; ++i) {  // walls
    const uint32_t j = (i + 1) % 4;
    t.push_back({i, j, j + 4});
    t.push_back({i, j + 4, i + 4});
  }
  if (closed) {
    t.push_back({4, 5, 6});
    t.push_back({4, 6, 7});
  }
  return MakeMesh(closed ? "closed box" : "open box", std::move(p), std::move(t), place);
}

double Sum(const std::vector<float>& row) {
  return std::accumulate(row.begin(), row.end(), 0.0);
}

std::vector<float> Row(const TransportSampler& sampler, const SpatialSample& s, uint64_t index,
                       SampleStats* stats = nullptr) {
  std::vector<float> row(sampler.layout().texel_count(), -1.0f);
  const SampleStats st = sampler.ComputeRow(s, index, row.data());
  if (stats != nullptr) *stats = st;
  return row;
}

// Form factor from a point to a parallel a×b rectangle at height c with one corner above the
// point (Howell's catalogue, configuration B-3; by contour integration of the rectangle).
double CornerRectangleFormFactor(double a, double b, double c) {
  const double A = a / c, B = b / c;
  const double sa = std::sqrt(1 + A * A), sb = std::sqrt(1 + B * B);
  return (A / sa * std::atan(B / sa) + B / sb * std::atan(A / sb)) / (2 * kPi);
}

TEST(TransportSampler, StrataSolidAnglesTileEachTexelAndTheSphere) {
  const SceneGeometry empty;
  const EmbreeScene scene(empty);
  for (int k : {1, 2, 3, 4, 6, 9, 16}) {
    const TransportSampler sampler(scene, 8, {k, 1});
    EXPECT_EQ(sampler.strata_u() * sampler.strata_v(), k);
    EXPECT_LE(sampler.strata_v(), sampler.strata_u());
    double total = 0;
    for (std::size_t j = 0; j < sampler.layout().texel_count(); ++j) {
      double texel = 0;
      for (int s = 0; s < k; ++s) texel += sampler.StratumSolidAngle(j, s);
      EXPECT_NEAR(texel, sampler.layout().TexelSolidAngle(j), 1e-15);
      total += texel;
    }
    EXPECT_NEAR(total, 4 * kPi, 1e-13) << "k = " << k;
  }
  EXPECT_EQ(TransportSampler(scene, 8, {4, 1}).strata_u(), 2);
  EXPECT_EQ(TransportSampler(scene, 8, {6, 1}).strata_v(), 2);
  EXPECT_THROW(TransportSampler(scene, 8, {0, 1}), std::invalid_argument);
  EXPECT_THROW(TransportSampler(scene, 12, {4, 1}), std::invalid_argument);
}

TEST(SpatialSamplesOf, GlobalOrderShadingAndGeometricNormals) {
  SceneGeometry g;
  // An inward-wound triangle whose file normals point +Z: the geometric normal is flipped to +Z.
  SceneMesh tri = MakeMesh("tri", {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}}, {{{0, 1, 2}}}, {}, {0, 0, 1});
  g.meshes = {tri, Grid(3, 1.0)};
  g.meshes[1].mesh.normals[4] = {0, 2, 0};  // not unit: normalised
  g.meshes[1].mesh.normals.pop_back();      // the last vertex lacks a normal: geometric
  const std::vector<SpatialSample> s = SpatialSamplesOf(g);
  ASSERT_EQ(s.size(), 12u);
  EXPECT_EQ(s[1].position, (Vec3{0, 1, 0}));
  EXPECT_EQ(s[0].normal, (Vec3{0, 0, 1}));
  EXPECT_EQ(s[0].geometric_normal, (Vec3{0, 0, 1}));
  EXPECT_EQ(s[3 + 4].position, (Vec3{0, 0, 0}));
  EXPECT_EQ(s[3 + 4].normal, (Vec3{0, 1, 0}));
  EXPECT_EQ(s[3 + 4].geometric_normal, (Vec3{0, 1, 0}));
  EXPECT_EQ(s[11].normal, (Vec3{0, 1, 0}));
}

// Counting: an upward normal at n = 8 skips exactly the texels whose four corners all have
// y ≤ 0 (the −Y face and the lower half of the four side faces: 64 + 4·32 = 192).
TEST(TransportSampler, SkipsAndCountsTexelsBelowTheHorizon) {
  const SceneGeometry empty;
  const EmbreeScene scene(empty);
  const TransportSampler sampler(scene, 8, {4, 3});
  const CubemapLayout& layout = sampler.layout();
  for (const Vec3& n : {Vec3{0, 1, 0}, Normalize(Vec3{0.3, 0.8, -0.5})}) {
    std::size_t below = 0;
    for (std::size_t j = 0; j < layout.texel_count(); ++j) {
      const TexelCoord c = layout.Coord(j);
      bool all = true;
      for (int k = 0; k < 4; ++k) {
        const Vec3 p = CubemapLayout::FacePoint(c.face, -1 + 0.25 * (c.x + (k & 1)),
                                                -1 + 0.25 * (c.y + (k >> 1)));
        all = all && Dot(p, n) <= 0;
      }
      below += all ? 1 : 0;
    }
    SampleStats st;
    const std::vector<float> row = Row(sampler, {{0, 0, 0}, n, n}, 5, &st);
    EXPECT_EQ(st.texels_below_horizon, below);
    EXPECT_EQ(st.texels_traced + st.texels_below_horizon, layout.texel_count());
    EXPECT_EQ(st.rays_traced + st.rays_below_horizon, 4 * st.texels_traced);
    for (std::size_t j = 0; j < layout.texel_count(); ++j) {
      if (!layout.TexelAboveHorizon(j, n)) {
        EXPECT_EQ(row[j], 0.0f);
      }
    }
    if (n.y == 1) {
      EXPECT_EQ(below, 192u);
      EXPECT_EQ(st.rays_traced, 4u * 192u);  // every jittered ray of a traced texel has y > 0
    } else {
      EXPECT_GT(st.rays_below_horizon, 0u);
    }
  }
}

// The row skips whole faces whose corners are all below the horizon; the counts must still be
// exactly those of TexelAboveHorizon, also for normals on face diagonals and axes.
TEST(TransportSampler, BelowHorizonCountMatchesTexelAboveHorizonForManyNormals) {
  const EmbreeScene none{SceneGeometry{}};
  const TransportSampler sampler(none, 8, {1, 3});
  const CubemapLayout& layout = sampler.layout();
  std::vector<Vec3> normals = {{1, 0, 0},  {0, -1, 0}, {0, 0, 1},   {1, 1, 0},
                               {0, 1, -1}, {1, 1, 1},  {-1, 1, -1}, {1, 1e-13, 0}};
  uint64_t h = 12345;
  auto next = [&h] {  // a small LCG: deterministic normals
    h = h * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(h >> 11) * 0x1p-53 * 2 - 1;
  };
  for (int i = 0; i < 200; ++i) normals.push_back({next(), next(), next()});
  std::vector<float> row(layout.texel_count());
  for (Vec3 n : normals) {
    n = Normalize(n);
    const SampleStats st = sampler.ComputeRow({{0, 0, 0}, n, n}, 1, row.data());
    std::size_t below = 0;
    for (std::size_t j = 0; j < layout.texel_count(); ++j) {
      const bool above = layout.TexelAboveHorizon(j, n);
      below += above ? 0 : 1;
      if (!above) {
        EXPECT_EQ(row[j], 0.0f);
      }
    }
    EXPECT_EQ(st.texels_below_horizon, below) << n.x << " " << n.y << " " << n.z;
    EXPECT_EQ(st.texels_traced, layout.texel_count() - below);
  }
}

// Unoccluded vertex under a uniform environment: Σ_j T[j] = (1/π)∫ max(0, n·ω) dω = 1, for the
// upward vertex at the centre of a ground grid and for tilted normals in an empty scene.
TEST(TransportSampler, UnoccludedRowSumsToOne) {
  SceneGeometry g;
  g.meshes = {Grid(9, 4.0)};
  const EmbreeScene scene(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const TransportSampler sampler(scene, 32, {});
  const SpatialSample& centre = samples[40];
  ASSERT_EQ(centre.position, (Vec3{0, 0, 0}));
  EXPECT_NEAR(Sum(Row(sampler, centre, 40)), 1.0, 1e-4);

  const EmbreeScene none{SceneGeometry{}};
  const TransportSampler free_sampler(none, 32, {});
  for (const Vec3& n : {Normalize(Vec3{0.3, 0.8, 0.52}), Normalize(Vec3{-1, -0.1, 0.01})}) {
    EXPECT_NEAR(Sum(Row(free_sampler, {{1, 2, 3}, n, n}, 7)), 1.0, 5e-4);
  }
}

// A vertex under a huge occluding quad (an "infinite" plane one unit above): only rays within
// ~1e−5 rad of the horizon could pass beside it, worth ≲ 1e−9 of the unoccluded value 1.
TEST(TransportSampler, VertexUnderAnOccludingPlaneSeesNothing) {
  SceneGeometry g;
  const double b = 1e5;
  g.meshes = {MakeMesh("roof", {{-b, 1, -b}, {b, 1, -b}, {b, 1, b}, {-b, 1, b}},
                       {{{0, 2, 1}}, {{0, 3, 2}}}, {}, {0, -1, 0}),
              Grid(3, 1.0)};
  const EmbreeScene scene(g);
  const TransportSampler sampler(scene, 32, {});
  const SpatialSample s = SpatialSamplesOf(g)[4 + 4];
  ASSERT_EQ(s.position, (Vec3{0, 0, 0}));
  SampleStats st;
  const double sum = Sum(Row(sampler, s, 8, &st));
  EXPECT_LT(sum, 1e-6);
  EXPECT_GE(sum, 0.0);
  EXPECT_GT(st.rays_traced, 0u);
}

// The centre of the floor of an open box sees the sky through the square opening only:
// Σ_j T[j] = form factor of the opening = 4·F_corner(a, a, h). With a/h = 1/2 the opening is
// exactly the texels |u|, |v| ≤ 1/2 of the +Y face (n = 32), so only the cosine is estimated;
// with a/h = 0.37 the opening's edges cut texels and n = 64, k = 64 keep the error < 1e−3.
TEST(TransportSampler, OpenBoxFloorCentreSeesTheFormFactorOfTheOpening) {
  struct Case {
    double half, height;
    int n, k;
    double tolerance;
  };
  for (const Case& c : {Case{1.0, 2.0, 32, 4, 1e-4}, Case{1.0, 2.7, 64, 64, 1e-3}}) {
    SceneGeometry g;
    g.meshes = {Box(c.half, c.height, false)};
    const EmbreeScene scene(g);
    const TransportSampler sampler(scene, c.n, {c.k, 11});
    const SpatialSample s = SpatialSamplesOf(g)[8];
    ASSERT_EQ(s.position, (Vec3{0, 0, 0}));
    ASSERT_EQ(s.geometric_normal, (Vec3{0, 1, 0}));
    const double expected = 4 * CornerRectangleFormFactor(c.half, c.half, c.height);
    const double got = Sum(Row(sampler, s, 8));
    EXPECT_NEAR(got / expected, 1.0, c.tolerance) << "h = " << c.height << " F = " << expected;
  }
}

// The per-texel variance from a row's own rays (collapsed strata) against the variance measured
// over many independent seeds: the floor centre of an open box whose opening's edges cut texels
// (a/h = 0.37, the test above), so partly visible texels carry real Monte-Carlo noise. Summed
// over the row, the estimate must be within 10 % of the measured variance for a 2×2 and a 4×4
// stratification (2×2 blocks: 0.998 and 1.012 measured), and conservative within 1.5× for the
// pairs of a 3×2 one (1.21 measured); the rows must be the same bytes with and without it.
TEST(TransportSampler, VarianceEstimateMatchesTheSpreadOfIndependentSeeds) {
  SceneGeometry g;
  g.meshes = {Box(1.0, 2.7, false)};
  const EmbreeScene scene(g);
  const SpatialSample s = SpatialSamplesOf(g)[8];
  for (int k : {4, 16, 6}) {
    constexpr int kSeeds = 300;
    const int n = 16;
    const std::size_t texels = 6u * n * n;
    std::vector<double> sum(texels, 0.0), sum2(texels, 0.0);
    double estimated = 0;
    for (int seed = 1; seed <= kSeeds; ++seed) {
      const TransportSampler sampler(scene, n, {k, static_cast<uint64_t>(seed)});
      std::vector<float> row(texels), var(texels, -1.0f), plain(texels);
      sampler.ComputeRow(s, 8, row.data(), var.data());
      sampler.ComputeRow(s, 8, plain.data());
      ASSERT_EQ(std::memcmp(row.data(), plain.data(), texels * sizeof(float)), 0);
      for (std::size_t j = 0; j < texels; ++j) {
        ASSERT_GE(var[j], 0.0f);
        sum[j] += row[j];
        sum2[j] += double(row[j]) * row[j];
        estimated += var[j];
      }
    }
    estimated /= kSeeds;
    double measured = 0;
    for (std::size_t j = 0; j < texels; ++j) {
      const double mean = sum[j] / kSeeds;
      measured += (sum2[j] - kSeeds * mean * mean) / (kSeeds - 1);
    }
    ASSERT_GT(measured, 0.0);
    std::printf("k = %d: estimated / measured variance %.3f\n", k, estimated / measured);
    // 2×2 blocks (k = 4, 16): unbiased for trends linear across a block; pairs (k = 6, a 3×2
    // grid): conservative.
    const bool blocks = k != 6;
    EXPECT_GE(estimated / measured, blocks ? 0.9 : 0.95) << "k = " << k;
    EXPECT_LE(estimated / measured, blocks ? 1.1 : 1.5) << "k = " << k;
  }
  // One ray per texel: nothing to compare a stratum with.
  const TransportSampler single(scene, 8, {1, 1});
  EXPECT_FALSE(single.VarianceEstimable());
  std::vector<float> row(6 * 64), var(6 * 64, -1.0f);
  single.ComputeRow(s, 8, row.data(), var.data());
  for (float v : var) EXPECT_EQ(v, 0.0f);
}

// Acne and leaks at every scale and far from the origin, axis-aligned and rotated: a vertex on
// a flat grid sees exactly (bit for bit) what it sees with no geometry at all, and the floor
// centre of a closed box sees exactly 0 (not one ray escapes).
TEST(TransportSampler, NoAcneNoLeaksAtAnyScaleOrOffset) {
  const EmbreeScene none{SceneGeometry{}};
  const TransportSampler free_sampler(none, 16, {});
  for (double scale : {1e-3, 1.0, 1e4}) {
    std::vector<Vec3> offsets = {{0, 0, 0}, Vec3{1, -2, 3} * (1e3 * scale)};
    if (scale >= 1) offsets.push_back({1e3, 1e3, -1e3});
    for (const Vec3& offset : offsets) {
      for (bool rotated : {false, true}) {
        const Placement place = rotated ? Rotated(scale, offset) : Placement{scale, offset};
        const std::string what = "scale " + std::to_string(scale) + " offset " +
                                 std::to_string(offset.x) + (rotated ? " rotated" : "");
        SceneGeometry plane;
        plane.meshes = {Grid(9, 1.0, place)};
        const EmbreeScene plane_scene(plane);
        const TransportSampler sampler(plane_scene, 16, {});
        const SpatialSample s = SpatialSamplesOf(plane)[40];
        const std::vector<float> seen = Row(sampler, s, 3);
        const std::vector<float> free_row = Row(free_sampler, s, 3);
        EXPECT_EQ(0, std::memcmp(seen.data(), free_row.data(), seen.size() * sizeof(float)))
            << what;
        EXPECT_NEAR(Sum(seen), 1.0, 2e-3) << what;

        SceneGeometry box;
        box.meshes = {Box(1.0, 1.0, true, place)};
        const EmbreeScene box_scene(box);
        const TransportSampler box_sampler(box_scene, 16, {});
        SampleStats st;
        const std::vector<float> inside = Row(box_sampler, SpatialSamplesOf(box)[8], 8, &st);
        EXPECT_EQ(*std::max_element(inside.begin(), inside.end()), 0.0f) << what;
        EXPECT_GT(st.rays_traced, 700u) << what;
      }
    }
  }
}

// A scene with partial occlusion everywhere: a floor inside an open box, sampled at all 9 box
// vertices and 25 grid vertices.
struct PartlyOccluded {
  SceneGeometry geometry;
  std::vector<SpatialSample> samples;
  PartlyOccluded() {
    geometry.meshes = {Box(1.0, 1.3, false, Placement{1.0, {0.2, 0, 0}}), Grid(5, 2.0)};
    samples = SpatialSamplesOf(geometry);
  }
};

TEST(TransportSampler, RowsAreBitIdenticalWhateverTheThreadsOrBatch) {
  const PartlyOccluded scene_data;
  const EmbreeScene scene(scene_data.geometry);
  const TransportSampler sampler(scene, 8, {4, 99});
  const std::span<const SpatialSample> samples(scene_data.samples);
  const std::size_t m = sampler.layout().texel_count();
  std::vector<float> reference(samples.size() * m);
  SampleStats ref_stats;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    ref_stats += sampler.ComputeRow(samples[i], 100 + i, reference.data() + i * m);
  }
  for (int threads : {1, 4}) {
    // Allow more threads than this machine's cores, so that 4 really run.
    const tbb::global_control allow(tbb::global_control::max_allowed_parallelism, threads);
    tbb::task_arena arena(threads);
    std::vector<float> batch(reference.size(), -1.0f);
    SampleStats st;
    arena.execute([&] { st = sampler.ComputeRows(samples, 100, batch.data()); });
    EXPECT_EQ(0, std::memcmp(batch.data(), reference.data(), batch.size() * sizeof(float)))
        << threads << " threads";
    EXPECT_EQ(st, ref_stats);
    // A batch starting in the middle reproduces the same rows.
    std::vector<float> tail((samples.size() - 7) * m);
    arena.execute([&] { sampler.ComputeRows(samples.subspan(7), 107, tail.data()); });
    EXPECT_EQ(0, std::memcmp(tail.data(), reference.data() + 7 * m, tail.size() * sizeof(float)));
  }
  // The jitter depends on the global index: the same sample under another index differs.
  std::vector<float> other(m);
  sampler.ComputeRow(samples[0], 12345, other.data());
  EXPECT_NE(0, std::memcmp(other.data(), reference.data(), m * sizeof(float)));
}

void ComputeTexelsMatchesComputeRow(const TransportSampler& sampler,
                                    const PartlyOccluded& scene_data) {
  const std::size_t m = sampler.layout().texel_count();
  for (std::size_t i : {0u, 8u, 20u}) {
    const SpatialSample& s = scene_data.samples[i];
    SampleStats row_stats;
    const std::vector<float> row = Row(sampler, s, i, &row_stats);
    std::vector<uint32_t> texels;
    for (uint32_t j = 0; j < m; j += 7) texels.push_back(static_cast<uint32_t>(m - 1 - j));
    std::vector<float> values(texels.size(), -1.0f);
    const SampleStats st = sampler.ComputeTexels(s, i, texels, values.data());
    std::size_t below = 0;
    for (std::size_t t = 0; t < texels.size(); ++t) {
      EXPECT_EQ(std::memcmp(&values[t], &row[texels[t]], sizeof(float)), 0) << texels[t];
      below += sampler.layout().TexelAboveHorizon(texels[t], s.normal) ? 0 : 1;
    }
    EXPECT_EQ(st.texels_below_horizon, below);
    EXPECT_EQ(st.texels_traced, texels.size() - below);
    // All texels at once: the same counters as the row.
    std::vector<uint32_t> all(m);
    std::iota(all.begin(), all.end(), 0u);
    std::vector<float> all_values(m);
    EXPECT_EQ(sampler.ComputeTexels(s, i, all, all_values.data()), row_stats);
    EXPECT_EQ(0, std::memcmp(all_values.data(), row.data(), m * sizeof(float)));
  }
  const uint32_t bad = static_cast<uint32_t>(m);
  float v;
  EXPECT_THROW(sampler.ComputeTexels(scene_data.samples[0], 0, {&bad, 1}, &v), std::out_of_range);
}

// Also for 1, 6 and 37 rays per texel: the rays are traced 16 at a time, so a texel's rays share
// packets with different neighbours in a row than in a list, and with 37 one texel spans three
// packets; its value must not depend on that.
TEST(TransportSampler, ComputeTexelsMatchesComputeRowBitForBit) {
  const PartlyOccluded scene_data;
  const EmbreeScene scene(scene_data.geometry);
  for (const int k : {6, 1, 37}) {
    SCOPED_TRACE(k);
    const TransportSampler sampler(scene, 16, {k, 5});
    ComputeTexelsMatchesComputeRow(sampler, scene_data);
  }
}

// U_j (visibility ≡ 1) equals T_j bit for bit where nothing is in the way, bounds T_j from
// above everywhere, and sums to 1 over the hemisphere.
TEST(TransportSampler, UnoccludedTexelsBoundTheRowAndMatchItWhenFree) {
  const PartlyOccluded scene_data;
  const EmbreeScene scene(scene_data.geometry);
  const EmbreeScene none{SceneGeometry{}};
  const TransportSampler sampler(scene, 16, {4, 5});
  const TransportSampler free_sampler(none, 16, {4, 5});
  const std::size_t m = sampler.layout().texel_count();
  std::vector<uint32_t> all(m);
  std::iota(all.begin(), all.end(), 0u);
  for (std::size_t i : {0u, 8u, 20u}) {
    const SpatialSample& s = scene_data.samples[i];
    const std::vector<float> row = Row(sampler, s, i);
    const std::vector<float> free_row = Row(free_sampler, s, i);
    std::vector<float> u(m);
    sampler.ComputeUnoccludedTexels(s, i, all, u.data());
    EXPECT_EQ(0, std::memcmp(u.data(), free_row.data(), m * sizeof(float)));
    std::size_t blocked = 0;
    for (std::size_t j = 0; j < m; ++j) {
      EXPECT_LE(row[j], u[j]);
      blocked += row[j] < u[j] ? 1 : 0;
    }
    EXPECT_GT(blocked, 0u);
    EXPECT_NEAR(Sum(u), 1.0, 2e-3);
    // ComputeTexels' optional unoccluded output comes from the same rays, bit for bit.
    std::vector<float> t(m), u2(m);
    sampler.ComputeTexels(s, i, all, t.data(), u2.data());
    EXPECT_EQ(0, std::memcmp(u2.data(), u.data(), m * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(t.data(), row.data(), m * sizeof(float)));
  }
}

// AppendRowRays reproduces the traced rays: as many as ComputeRow traces, from the robust
// origin, and re-tracing them reproduces the row's visibility.
// The benchmark's tracing clock: off by default, summing the threads' CPU time inside
// ComputeRow / ComputeTexels when on (here all on this thread: at most the thread's CPU time
// over the same calls, and most of it, since the loop does nothing else), reset by every
// MeasureTraceCpu call.
TEST(TransportSampler, MeasureTraceCpuSumsTheSamplersCpuTimeOnlyWhenOn) {
  const PartlyOccluded scene_data;
  const EmbreeScene scene(scene_data.geometry);
  TransportSampler sampler(scene, 32, {4, 1});
  const auto thread_cpu = [] {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  std::vector<float> row(sampler.layout().texel_count());
  sampler.ComputeRow(scene_data.samples[0], 0, row.data());
  EXPECT_EQ(sampler.trace_cpu_seconds(), 0.0);  // off by default

  sampler.MeasureTraceCpu(true);
  const std::vector<uint32_t> texels{0, 5, 77, 1000};
  std::vector<float> values(texels.size());
  const double c0 = thread_cpu();
  for (std::size_t i = 0; i < scene_data.samples.size(); ++i) {
    sampler.ComputeRow(scene_data.samples[i], i, row.data());
    sampler.ComputeTexels(scene_data.samples[i], i, texels, values.data());
  }
  const double thread = thread_cpu() - c0;
  const double traced = sampler.trace_cpu_seconds();
  EXPECT_GT(traced, 0.0);
  EXPECT_LE(traced, thread + 1e-6);
  EXPECT_GE(traced, 0.5 * thread);

  sampler.MeasureTraceCpu(false);
  EXPECT_EQ(sampler.trace_cpu_seconds(), 0.0);
  sampler.ComputeRow(scene_data.samples[0], 0, row.data());
  EXPECT_EQ(sampler.trace_cpu_seconds(), 0.0);
}

TEST(TransportSampler, AppendRowRaysReproducesTheTracedRays) {
  const PartlyOccluded scene_data;
  const EmbreeScene scene(scene_data.geometry);
  const TransportSampler sampler(scene, 8, {});
  const SpatialSample& s = scene_data.samples[8];
  SampleStats st;
  const std::vector<float> row = Row(sampler, s, 8, &st);
  std::vector<OcclusionRay> rays;
  sampler.AppendRowRays(s, 8, rays);
  ASSERT_EQ(rays.size(), st.rays_traced);
  float origin[3];
  scene.RobustOrigin(s.position, s.geometric_normal, origin);
  std::size_t open = 0;
  for (const OcclusionRay& r : rays) {
    EXPECT_EQ(0, std::memcmp(r.origin, origin, sizeof(origin)));
    EXPECT_NEAR(std::hypot(r.direction[0], r.direction[1], r.direction[2]), 1.0, 1e-6);
    open += scene.Occluded(r) ? 0 : 1;
  }
  EXPECT_EQ(scene.CountOccluded(rays), rays.size() - open);
  EXPECT_GT(open, 0u);
  EXPECT_LT(open, rays.size());
}

TEST(TransportSampler, RejectsNonFiniteSamples) {
  const EmbreeScene none{SceneGeometry{}};
  const TransportSampler sampler(none, 4, {});
  std::vector<float> row(sampler.layout().texel_count());
  EXPECT_THROW(sampler.ComputeRow({{0, 0, 0}, {0, 0, 0}, {0, 1, 0}}, 0, row.data()),
               NumericalError);
  EXPECT_THROW(sampler.ComputeRow({{std::nan(""), 0, 0}, {0, 1, 0}, {0, 1, 0}}, 0, row.data()),
               NumericalError);
}

}  // namespace
}  // namespace prt
