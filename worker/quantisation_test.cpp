#include "worker/quantisation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "formats/column_coding.h"

namespace prt {
namespace {

// Subtractive dither: the error is uniform on (−Δ/2, Δ/2], RMS Δ/√12, whatever the input.
TEST(DitheredQuantiser, ErrorIsUniformWithRmsDeltaOverSqrt12From6To16Bits) {
  std::mt19937_64 rng(9);
  for (int bits = 6; bits <= 16; ++bits) {
    const double delta = 1.0 / QuantiserMax(bits);
    const int N = 40000;
    double sum = 0, sum2 = 0, maxerr = 0;
    int hist[10] = {};
    for (int i = 0; i < N; ++i) {
      // Half the inputs uniform, half a constant (the error must not depend on the signal).
      const double u = (i % 2) ? std::uniform_real_distribution<double>(-1, 1)(rng) : 0.3 * delta;
      const double r = DitherOffset(rng(), static_cast<uint32_t>(i), 0);
      const int32_t q = QuantiseDithered(u, r, bits);
      ASSERT_LE(std::abs(q), QuantiserMax(bits));
      const double e = DequantiseDithered(q, r, bits) - u;
      sum += e;
      sum2 += e * e;
      maxerr = std::max(maxerr, std::fabs(e));
      const int b = std::min(9, static_cast<int>((e / delta + 0.5) * 10));
      ++hist[std::max(0, b)];
    }
    EXPECT_LE(maxerr, delta / 2 * (1 + 1e-9)) << bits;
    EXPECT_NEAR(sum / N / delta, 0.0, 0.01) << bits;
    EXPECT_NEAR(std::sqrt(sum2 / N) / (delta / std::sqrt(12.0)), 1.0, 0.02) << bits;
    for (int b = 0; b < 10; ++b) EXPECT_NEAR(hist[b] / static_cast<double>(N), 0.1, 0.01) << bits;
  }
}

TEST(QuantiseColumn, ScalesByTwoToTheLevelNormalisesAndDecodesWithinHalfAStep) {
  const int bits = 9;
  std::vector<float> c = {0.5f, -0.25f, 0.125f, 1e-6f, 0.0f, -0.0625f};
  // Scale map in half-octaves: factors 1, 2, 4, 8, 8, 8.
  std::vector<uint8_t> levels = {0, 2, 4, 6, 6, 6};
  std::vector<uint32_t> kept = {0, 1, 2, 3, 5};
  const CompressedColumn col = QuantiseColumn(17, 3, c.data(), kept, levels.data(), bits, 5);
  // Scaled magnitudes 0.5, 0.5, 0.5, 8e-6, 0.5: m = 0.5.
  EXPECT_FLOAT_EQ(col.scale, 0.5f);
  EXPECT_EQ(col.column, 17u);
  EXPECT_EQ(col.depth, 3);
  const double A = QuantiserMax(bits);
  for (std::size_t k = 0; k < col.index.size(); ++k) {
    const uint32_t i = col.index[k];
    EXPECT_NE(i, 3u) << "the tiny term quantises to zero and is dropped";
    const double v = DequantiseTerm(col.q[k], DitherOffset(5, 17, i), col.scale, bits, levels[i]);
    EXPECT_NEAR(v, c[i], col.scale / A / 2 / ScaleFactor(levels[i]) * 1.0000001);
    EXPECT_LE(std::abs(col.q[k]), A);
  }
  EXPECT_EQ(col.index.size(), 4u);
  const std::vector<float> zeros(4, 0.0f);
  const std::vector<uint32_t> k2 = {0, 1};
  EXPECT_TRUE(QuantiseColumn(1, 0, zeros.data(), k2, levels.data(), bits, 5).index.empty());
}

}  // namespace
}  // namespace prt
