#include "worker/adaptive_column_transform.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "formats/column_coding.h"

namespace prt {
namespace {

SpatialDomain MeshAndGrid() {
  SpatialDomain d;
  SpatialSegment mesh;
  mesh.kind = SpatialSegment::Kind::kMesh1D;
  mesh.count = 100;
  mesh.order.resize(100);
  std::iota(mesh.order.rbegin(), mesh.order.rend(), 0u);  // reversed
  SpatialSegment grid;
  grid.kind = SpatialSegment::Kind::kGrid2D;
  grid.width = 12;
  grid.height = 10;
  grid.count = 120;
  d.segments = {mesh, grid};
  return d;
}

TEST(NonLinearApproximation, KeptEnergyIsTheSumOfTheLargestSquares) {
  const std::vector<float> c = {3, 0, -4, 1, 0, -2};
  const ApproximationEnergy e = MeasureApproximation(c.data(), c.size(), 2);
  EXPECT_DOUBLE_EQ(e.total, 30.0);
  EXPECT_DOUBLE_EQ(e.kept, 25.0);
  EXPECT_EQ(e.terms, 2u);
  EXPECT_FALSE(e.keeps_all);
  const ApproximationEnergy all = MeasureApproximation(c.data(), c.size(), 4);
  EXPECT_TRUE(all.keeps_all);
  EXPECT_EQ(all.terms, 4u);
  EXPECT_EQ(LargestTerms(c.data(), c.size(), 3), (std::vector<uint32_t>{0, 2, 5}));
  EXPECT_EQ(LargestTerms(c.data(), c.size(), 10), (std::vector<uint32_t>{0, 2, 3, 5}));
}

// The histogram selection against a full sort, on columns that stress it: wide and narrow
// ranges (many values in the threshold bin), ties, denormals, signed zeros, budgets 0 … n.
TEST(NonLinearApproximation, HistogramSelectionEqualsAFullSort) {
  std::mt19937 rng(5);
  const auto check = [](const std::vector<float>& c, std::size_t budget) {
    std::vector<double> sq;
    double total = 0;
    for (float v : c)
      if (v != 0.0f) {
        sq.push_back(static_cast<double>(v) * v);
        total += static_cast<double>(v) * v;
      }
    std::sort(sq.begin(), sq.end(), std::greater<double>());
    const std::size_t take = std::min(budget, sq.size());
    double kept = 0;
    for (std::size_t k = 0; k < take; ++k) kept += sq[k];
    const ApproximationEnergy e = MeasureApproximation(c.data(), c.size(), budget);
    EXPECT_NEAR(e.total, total, 1e-14 * total);  // summed in four lanes
    EXPECT_NEAR(e.kept, kept, 1e-12 * total) << budget;
    EXPECT_EQ(e.terms, take);
    EXPECT_EQ(e.keeps_all, sq.size() <= budget);
  };
  for (int trial = 0; trial < 300; ++trial) {
    const std::size_t n = 1 + rng() % 3000;
    std::vector<float> c(n);
    const int kind = trial % 6;
    for (std::size_t i = 0; i < n; ++i) {
      const float u = std::uniform_real_distribution<float>(-1, 1)(rng);
      switch (kind) {
        case 0:
          c[i] = u;
          break;  // one decade
        case 1:
          c[i] = u * std::pow(10.0f, static_cast<float>(rng() % 60) - 30);
          break;  // 60
        case 2:
          c[i] = rng() % 3 == 0 ? 0.0f : (rng() % 2 ? 0.5f : -0.5f);
          break;  // ties
        case 3:
          c[i] = u * 1e-41f;
          break;  // denormals
        case 4:
          c[i] = rng() % 2 ? -0.0f : 1.0f + 1e-7f * static_cast<float>(rng() % 8);
          break;
        default:
          c[i] = 1.0f + 0.01f * u;
          break;  // everything in one or two bins
      }
    }
    for (std::size_t budget : {std::size_t{0}, std::size_t{1}, n / 3, n / 2, n - 1, n, n + 5})
      check(c, budget);
  }
}

TEST(PickDepth, FewestTermsAmongFullKeepersElseMostEnergy) {
  std::vector<ApproximationEnergy> m(4);
  m[0] = {8, 10, 5, false};
  m[1] = {9, 10, 5, false};
  m[2] = {7, 10, 5, false};
  m[3] = {9.5, 10, 5, false};
  EXPECT_EQ(PickDepth(m), 3);
  m[1] = {10, 10, 4, true};
  m[2] = {10, 10, 3, true};
  EXPECT_EQ(PickDepth(m), 2);
  m[0] = {10, 10, 3, true};
  EXPECT_EQ(PickDepth(m), 0) << "ties go to the shallower depth";
}

// §4.2: the chosen depth never keeps less energy than the untransformed column (depth 0), and
// the returned coefficients are the column transformed to that depth.
TEST(AdaptiveColumnTransform, NeverKeepsLessEnergyThanDepthZero) {
  const SpatialDomain d = MeshAndGrid();
  const std::size_t S = d.sample_count();
  std::mt19937 rng(6);
  int deeper = 0, shallow = 0;
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<float> x(S, 0.0f);
    const int kind = trial % 4;
    for (std::size_t i = 0; i < S; ++i) {
      const double t = static_cast<double>(i) / static_cast<double>(S);
      if (kind == 0) x[i] = static_cast<float>(std::sin(6 * t + trial) + 2);    // smooth
      if (kind == 1 && rng() % 40 == 0) x[i] = 1.0f;                            // spikes
      if (kind == 2) x[i] = std::uniform_real_distribution<float>(-1, 1)(rng);  // noise
      if (kind == 3) x[i] = (t > 0.3 && t < 0.6) ? 1.0f : 0.0f;                 // shadow edge
    }
    const std::size_t budget = 1 + rng() % 30;
    for (ColumnWavelet w : {ColumnWavelet::kLeGall53, ColumnWavelet::kCdf97}) {
      std::vector<float> c = x;
      std::vector<ApproximationEnergy> per;
      const int depth = TransformColumnAdaptive(d, w, budget, c.data(), &per);
      ASSERT_EQ(per.size(), static_cast<std::size_t>(MaxColumnDepth(d) + 1));
      EXPECT_EQ(depth, PickDepth(per));
      EXPECT_GE(per[depth].kept_fraction(), per[0].kept_fraction() - 1e-12);
      if (per[0].keeps_all) {
        EXPECT_LE(per[depth].terms, per[0].terms);
      }
      std::vector<float> ref = x;
      ForwardColumnTransform(d, w, depth, ref.data());
      for (std::size_t i = 0; i < S; ++i) EXPECT_NEAR(c[i], ref[i], 1e-5);
      (depth > 0 ? deeper : shallow)++;
    }
  }
  EXPECT_GT(deeper, 50);   // smooth columns go deep
  EXPECT_GT(shallow, 50);  // spikes and noise stay near the samples
}

TEST(AdaptiveColumnTransform, SmoothColumnGoesDeepAndIsolatedSpikeStaysAtDepthZero) {
  const SpatialDomain d = MeshAndGrid();
  std::vector<float> smooth(d.sample_count(), 1.0f), spike(d.sample_count(), 0.0f);
  spike[57] = 1.0f;
  EXPECT_EQ(TransformColumnAdaptive(d, ColumnWavelet::kLeGall53, 4, smooth.data()),
            MaxColumnDepth(d));
  EXPECT_EQ(TransformColumnAdaptive(d, ColumnWavelet::kLeGall53, 1, spike.data()), 0);
}

}  // namespace
}  // namespace prt
