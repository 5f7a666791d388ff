#include "worker/sparse_indirect.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "vocabulary/hash.h"
#include "vocabulary/scene.h"
#include "worker/grid_scene_test_support.h"

namespace prt {
namespace {

using grid_scenes::Grid;
using grid_scenes::Scene;

// A ground with a wall standing on it and a small patch facing down 1 cm above a coarse part of
// the ground (so that bounce 1 has a near field).
SceneGeometry WallScene() {
  return Scene(
      {Grid("ground", {-1, -1, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}, 10, {0.6f, 0.6f, 0.6f}),
       Grid("wall", {-1, 0.2, 0}, {2, 0, 0}, {0, 0, 1}, {0, -1, 0}, 12, {0.8f, 0.5f, 0.3f}),
       Grid("patch", {0.3, -0.6, 0.01}, {0.05, 0, 0}, {0, 0.05, 0}, {0, 0, -1}, 3,
            {0.7f, 0.7f, 0.7f})});
}

// Its T⁰ coarsened to m: what bounce 1 gathers from.
std::vector<float> CoarseDirect(const EmbreeScene& scene, std::span<const SpatialSample> samples,
                                int n, int m) {
  const TransportSampler sampler(scene, n, {4, 1});
  const CubemapLayout fine(n), coarse(m);
  std::vector<float> direct(samples.size() * fine.texel_count());
  sampler.ComputeRows(samples, 0, direct.data());
  std::vector<float> out(samples.size() * coarse.texel_count());
  for (std::size_t v = 0; v < samples.size(); ++v)
    CoarsenRow(fine, coarse, direct.data() + v * fine.texel_count(),
               out.data() + v * coarse.texel_count());
  return out;
}

TEST(SparseIndirectTest, GatheringTexelsEqualsTheWholeRowThereBitForBit) {
  const SceneGeometry g = WallScene();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const int m = 4;
  const std::size_t cols = CubemapLayout(m).texel_count();
  const std::vector<float> prev = CoarseDirect(scene, samples, 8, m);
  BounceGatherOptions go;
  go.paths = 256;
  go.indirect_n = m;
  const BounceGatherer gatherer(scene, surfaces, go);
  const GatheredBounce bounce(gatherer, 1, 3, prev.data(), samples.size(), 1, cols);
  const std::vector<uint32_t> texels{0, 5, 17, 40, 63, 64, 95};
  uint64_t near_vertices = 0;
  for (std::size_t v = 0; v < samples.size(); ++v) {
    std::vector<float> row(3 * cols), some(3 * texels.size());
    bounce.Evaluate(samples[v], v, {}, row.data());
    bounce.Evaluate(samples[v], v, texels, some.data());
    for (int c = 0; c < 3; ++c)
      for (std::size_t i = 0; i < texels.size(); ++i)
        ASSERT_EQ(some[c * texels.size() + i], row[c * cols + texels[i]]) << v << " " << i;
    std::vector<GatherTerm> terms;
    std::vector<float> near(3 * cols);
    near_vertices += gatherer.Terms(samples[v], v, 1, 3, terms, near.data()).near_hits > 0;
  }
  EXPECT_GT(near_vertices, 0u);  // the near field's subset path was exercised
}

TEST(SparseIndirectTest, PathTracedTexelsEqualTheWholeIndirectRowThere) {
  const SceneGeometry g = WallScene();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  PathTraceOptions po;
  po.bounces = 2;
  po.paths = 16;
  const PathTraceReference reference(scene, surfaces, 4, po);
  const PathTracedIndirect component(reference, 3);
  const std::size_t cols = component.cols();
  const std::vector<uint32_t> texels{3, 9, 50, 77};
  for (std::size_t v = 0; v < samples.size(); v += 7) {
    std::vector<float> row(3 * cols), some(3 * texels.size()), full(3 * cols),
        bounce_rows(3 * 3 * cols);
    component.Evaluate(samples[v], v, {}, row.data());
    component.Evaluate(samples[v], v, texels, some.data());
    for (int c = 0; c < 3; ++c)
      for (std::size_t i = 0; i < texels.size(); ++i)
        ASSERT_EQ(some[c * texels.size() + i], row[c * cols + texels[i]]);
    // The indirect part of ComputeRow's row (its bounces 1 and 2), to float rounding.
    PathTraceExtras ex;
    ex.bounce_rows = bounce_rows.data();
    reference.ComputeRow(samples[v], v, 3, full.data(), ex);
    for (int c = 0; c < 3; ++c)
      for (std::size_t j = 0; j < cols; ++j) {
        const float want =
            bounce_rows[(1 * 3 + c) * cols + j] + bounce_rows[(2 * 3 + c) * cols + j];
        ASSERT_NEAR(row[c * cols + j], want, 1e-6f + 1e-5f * std::fabs(want));
      }
  }
}

// A component whose rows are exact combinations: I(s) = a(s)·R₁ + b(s)·R₂ (two fixed rows), so
// any vertex is a combination of two neighbours.
class TwoRowComponent final : public IndirectComponent {
 public:
  explicit TwoRowComponent(std::size_t cols) : cols_(cols), r1_(cols), r2_(cols) {
    for (std::size_t j = 0; j < cols; ++j) {
      r1_[j] = static_cast<float>(0.5 + 0.5 * std::sin(0.3 * double(j)));
      r2_[j] = static_cast<float>(double(SplitMix64(j) % 1000) / 1000.0);
    }
  }
  int channels() const override { return 1; }
  std::size_t cols() const override { return cols_; }
  uint64_t Evaluate(const SpatialSample& x, uint64_t, std::span<const uint32_t> texels,
                    float* out) const override {
    const double a = 1.0 + x.position.x, b = 0.5 + x.position.y;
    if (texels.empty()) {
      for (std::size_t j = 0; j < cols_; ++j) out[j] = static_cast<float>(a * r1_[j] + b * r2_[j]);
    } else {
      for (std::size_t i = 0; i < texels.size(); ++i)
        out[i] = static_cast<float>(a * r1_[texels[i]] + b * r2_[texels[i]]);
    }
    ++evaluations;
    return 1;
  }
  mutable uint64_t evaluations = 0;

 private:
  std::size_t cols_;
  std::vector<float> r1_, r2_;
};

SpatialSample At(double x, double y) {
  SpatialSample s;
  s.position = {x, y, 0};
  s.normal = {0, 0, 1};
  s.geometric_normal = {0, 0, 1};
  return s;
}

TEST(SparseIndirectTest, ReconstructsAnExactCombinationAndKeepsTheEvaluatedTexels) {
  const TwoRowComponent comp(96);
  const std::vector<SpatialSample> nb_at{At(0, 0), At(0.2, 0), At(0, 0.3), At(0.25, 0.1)};
  std::vector<std::vector<float>> rows(nb_at.size(), std::vector<float>(96));
  std::vector<IndirectNeighbor> nbs;
  for (std::size_t k = 0; k < nb_at.size(); ++k) {
    comp.Evaluate(nb_at[k], k, {}, rows[k].data());
    nbs.push_back({rows[k].data(), nb_at[k].normal});
  }
  const SpatialSample x = At(0.1, 0.15);
  std::vector<float> want(96), got(96);
  comp.Evaluate(x, 9, {}, want.data());
  SparseIndirectOptions o;
  o.features = 12;
  L1Solver solver(L1Options{1e-6});
  SparseIndirectStats st;
  EXPECT_EQ(ReconstructIndirectRow(comp, x, 9, nbs, o, solver, got.data(), st),
            SparseOutcome::kReconstructed);
  EXPECT_EQ(st.texels_evaluated, 12u);
  EXPECT_EQ(st.texels_total, 96u);
  double e2 = 0, w2 = 0;
  for (std::size_t j = 0; j < 96; ++j) {
    e2 += (got[j] - want[j]) * (got[j] - want[j]);
    w2 += want[j] * want[j];
  }
  EXPECT_LT(std::sqrt(e2 / w2), 1e-3);
  // The evaluated texels exactly.
  const std::vector<uint32_t> feats = ChooseIndirectFeatures(nbs, 1, 96, 12);
  ASSERT_EQ(feats.size(), 12u);
  for (uint32_t j : feats) EXPECT_EQ(got[j], want[j]);
}

TEST(SparseIndirectTest, TooFewNeighboursOrNeighboursFacingAwayEvaluateTheWholeRow) {
  const TwoRowComponent comp(96);
  std::vector<float> r0(96), want(96), got(96);
  comp.Evaluate(At(0, 0), 0, {}, r0.data());
  SpatialSample away = At(0.1, 0);
  away.normal = {0, 0, -1};
  const std::vector<IndirectNeighbor> nbs{
      {r0.data(), {0, 0, 1}}, {r0.data(), {0, 0, -1}}, {r0.data(), {0, 0, -1}}};
  const SpatialSample x = At(0.1, 0.1);
  comp.Evaluate(x, 3, {}, want.data());
  L1Solver solver;
  SparseIndirectStats st;
  EXPECT_EQ(ReconstructIndirectRow(comp, x, 3, nbs, {}, solver, got.data(), st),
            SparseOutcome::kTooFewNeighbors);  // 2 of 3 face away (min_normal_cos 0.5)
  EXPECT_EQ(got, want);
  EXPECT_EQ(st.fallback_too_few_neighbors, 1u);
  EXPECT_EQ(st.texels_evaluated, 96u);
}

TEST(SparseIndirectTest, EveryVertexDenseGivesBruteForceAndCombinationsAreExact) {
  const SceneGeometry g = WallScene();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const std::size_t V = samples.size();
  const int m = 4;
  const CubemapLayout fine(8), coarse(m);
  const std::size_t cols = coarse.texel_count();
  const std::vector<float> prev = CoarseDirect(scene, samples, 8, m);
  BounceGatherOptions go;
  go.paths = 64;
  go.indirect_n = m;
  const BounceGatherer gatherer(scene, surfaces, go);
  const GatheredBounce bounce(gatherer, 1, 3, prev.data(), V, 1, cols);
  std::vector<float> brute(3 * V * cols), all_dense(3 * V * cols);
  for (std::size_t v = 0; v < V; ++v) {
    std::vector<float> row(3 * cols);
    bounce.Evaluate(samples[v], v, {}, row.data());
    for (int c = 0; c < 3; ++c)
      std::copy_n(row.data() + c * cols, cols, brute.data() + (c * V + v) * cols);
  }
  SparseIndirectStats st;
  RunSparseIndirect(bounce, samples, std::vector<uint8_t>(V, 1), 0.3, 40, {}, all_dense.data(), st);
  EXPECT_EQ(all_dense, brute);
  EXPECT_EQ(st.SampledFraction(), 1.0);

  // Half dense; every other vertex a given combination of two dense ones: Σ α rows, ≥ 0.
  std::vector<uint8_t> is_dense(V, 0);
  std::vector<std::vector<SampleWeight>> comb(V);
  for (std::size_t v = 0; v < V; ++v) is_dense[v] = v % 2 == 0;
  for (std::size_t v = 1; v < V; v += 2)
    comb[v] = {{static_cast<uint32_t>(v - 1), 0.75f},
               {static_cast<uint32_t>((v + 1) % V), v % 4 == 1 ? 0.25f : -2.0f}};
  SparseIndirectOptions o;
  o.direct_weights = true;
  std::vector<float> out(3 * V * cols);
  SparseIndirectStats st2;
  RunSparseIndirect(bounce, samples, is_dense, 0.3, 40, o, out.data(), st2, comb);
  EXPECT_EQ(st2.reconstructed, V / 2);
  EXPECT_NEAR(st2.SampledFraction(), 0.5, 0.01);
  for (std::size_t v = 1; v < V; v += 2)
    for (int c = 0; c < 3; ++c)
      for (std::size_t j = 0; j < cols; ++j) {
        const float a = brute[(c * V + comb[v][0].sample) * cols + j];
        const float b = brute[(c * V + comb[v][1].sample) * cols + j];
        const float want = std::max(0.0f, 0.75f * a + comb[v][1].alpha * b);
        ASSERT_NEAR(out[(c * V + v) * cols + j], want, 1e-6f) << v;
      }
}

// The sparse bounce against brute force on a smooth scene: the relit bounce light (uniform sky)
// of the reconstructed vertices within 3 % RMS, and the evaluated share near the features' rate.
TEST(SparseIndirectTest, SparseBounceAgreesWithBruteForceOnASmoothScene) {
  const SceneGeometry g = WallScene();
  const EmbreeScene scene(g);
  const SceneSurfaces surfaces(g);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const std::size_t V = samples.size();
  const int m = 4;
  const std::size_t cols = CubemapLayout(m).texel_count();
  const std::vector<float> prev = CoarseDirect(scene, samples, 8, m);
  BounceGatherOptions go;
  go.paths = 1024;
  go.indirect_n = m;
  go.near_field = 0;
  const BounceGatherer gatherer(scene, surfaces, go);
  const GatheredBounce bounce(gatherer, 1, 1, prev.data(), V, 1, cols);
  std::vector<float> brute(V * cols), sparse(V * cols);
  SparseIndirectStats st;
  RunSparseIndirect(bounce, samples, std::vector<uint8_t>(V, 1), 0.3, 40, {}, brute.data(), st);
  std::vector<uint8_t> is_dense(V, 0);
  for (std::size_t v = 0; v < V; ++v) is_dense[v] = SplitMix64(v) % 3 == 0;
  SparseIndirectOptions o;
  o.features = 12;
  SparseIndirectStats st2;
  RunSparseIndirect(bounce, samples, is_dense, 0.5, 40, o, sparse.data(), st2);
  EXPECT_GT(st2.reconstructed, V / 3);
  EXPECT_LT(st2.SampledFraction(), 0.6);
  double e2 = 0, w2 = 0;
  for (std::size_t v = 0; v < V; ++v) {
    if (is_dense[v]) continue;
    const double a =
        std::accumulate(sparse.begin() + v * cols, sparse.begin() + (v + 1) * cols, 0.0);
    const double b = std::accumulate(brute.begin() + v * cols, brute.begin() + (v + 1) * cols, 0.0);
    e2 += (a - b) * (a - b);
    w2 += b * b;
  }
  EXPECT_LT(std::sqrt(e2 / w2), 0.03);
}

TEST(SparseIndirectTest, FeatureCountFollowsTheDirectRate) {
  EXPECT_EQ(IndirectFeatures(350, 32, 8), 22);
  EXPECT_EQ(IndirectFeatures(1400, 64, 16), 88);
  EXPECT_EQ(IndirectFeatures(10, 32, 8), 8);  // at least 8
}

}  // namespace
}  // namespace prt
