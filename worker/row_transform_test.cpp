#include "worker/row_transform.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace prt {
namespace {

TEST(RowTransform, RoundTripsAndPreservesEnergyForHaarAndD4) {
  const int n = 8;
  const std::size_t M = 6 * n * n, rows = 5;
  std::mt19937 rng(2);
  std::vector<float> x(M * rows);
  for (float& v : x) v = std::uniform_real_distribution<float>(0, 1)(rng);
  for (RowWavelet w : {RowWavelet::kHaar, RowWavelet::kD4}) {
    std::vector<float> y = x;
    ForwardRowTransform(w, n, y.data(), rows);
    double ex = 0, ey = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      ex += static_cast<double>(x[i]) * x[i];
      ey += static_cast<double>(y[i]) * y[i];
    }
    EXPECT_NEAR(ey / ex, 1.0, 1e-6) << "orthonormal filters preserve energy";
    InverseRowTransform(w, n, y.data(), rows);
    for (std::size_t i = 0; i < x.size(); ++i) EXPECT_NEAR(y[i], x[i], 1e-5);
  }
}

TEST(RowTransform, LevelCountsAreThreeTimesFourToTheLevelPerFace) {
  const int n = 16;
  const std::vector<uint8_t> lv = RowCoefficientLevels(n);
  ASSERT_EQ(lv.size(), 6u * n * n);
  for (int l = 0; l <= 4; ++l) {
    const long c = std::count(lv.begin(), lv.end(), static_cast<uint8_t>(l));
    EXPECT_EQ(c, l == 0 ? 6 : 6 * 3 * (1L << (2 * (l - 1))));
  }
}

TEST(RowTransform, KeepLargestPerRowKeepsExactlyTheLargestMagnitudes) {
  std::mt19937 rng(3);
  const std::size_t cols = 50, rows = 4, keep = 7;
  std::vector<float> x(cols * rows);
  for (float& v : x) v = std::uniform_real_distribution<float>(-1, 1)(rng);
  std::vector<float> y = x;
  KeepLargestPerRow(y.data(), rows, cols, keep);
  for (std::size_t r = 0; r < rows; ++r) {
    std::vector<float> mags;
    for (std::size_t j = 0; j < cols; ++j) mags.push_back(std::fabs(x[r * cols + j]));
    std::sort(mags.rbegin(), mags.rend());
    std::size_t nz = 0;
    for (std::size_t j = 0; j < cols; ++j) {
      const float v = y[r * cols + j];
      if (v != 0) {
        ++nz;
        EXPECT_EQ(v, x[r * cols + j]);
        EXPECT_GE(std::fabs(v), mags[keep - 1]);
      }
    }
    EXPECT_EQ(nz, keep);
  }
}

}  // namespace
}  // namespace prt
