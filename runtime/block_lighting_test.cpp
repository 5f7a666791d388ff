#include "runtime/block_lighting.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include "formats/visibility_blocks.h"
#include "runtime/brdf.h"

namespace prt {
namespace {

CubemapRgb RandomLight(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 2);
  CubemapRgb l;
  l.n = n;
  for (int c = 0; c < 3; ++c) {
    l.Channel(c).resize(l.TexelCount());
    for (float& x : l.Channel(c)) x = u(rng);
  }
  l.r[100] = 5000.f;  // a one-texel sun
  return l;
}

TEST(CubemapBlocks, CoverEveryTexelOnceAndTheSphere) {
  const CubemapBlocks blocks(32);
  std::vector<int> seen(6 * 32 * 32, 0);
  double omega = 0;
  for (int b = 0; b < blocks.block_count(); ++b)
    for (int k = 0; k < 256; ++k) {
      ++seen[blocks.Texel(b, k)];
      omega += blocks.SolidAngle(b, k);
      EXPECT_EQ(blocks.Texel(b, k), VisibilityBlockTexel(32, b, k));
    }
  for (int s : seen) EXPECT_EQ(s, 1);
  EXPECT_NEAR(omega, 4 * std::numbers::pi, 1e-4);
}

TEST(BlockLighting, PrefixSumIdentityAndDct) {
  const int n = 32;
  const CubemapBlocks blocks(n);
  const CubemapRgb light = RandomLight(n, 1);
  const BlockLighting bl = ComputeBlockLighting(light, blocks);
  const auto power = CubemapPower(light);
  std::mt19937 rng(2);
  for (int c = 0; c < 3; ++c) {
    double sum = 0;
    for (int b = 0; b < blocks.block_count(); ++b) {
      sum += bl.Suffix(b, c)[0];
      EXPECT_EQ(bl.Suffix(b, c)[256], 0.f);
      // DC coefficient of the block is Σ L' / 16.
      EXPECT_NEAR(bl.Dct(b, c)[0] * 16.0, bl.Suffix(b, c)[0], 1e-4 * bl.Suffix(b, c)[0] + 1e-6);
      // Eq. 5–6: Σ_k L'[k]·V[k] = Σ_k L_int[k]·V_d[k] for any visibility vector, binary or not.
      for (int bits : {1, 6}) {
        const int max_level = (1 << bits) - 1;
        uint8_t v[256];
        int level = 0;
        for (int k = 0; k < 256; ++k) {
          if (rng() % 9 == 0) level = static_cast<int>(rng() % (max_level + 1));
          v[k] = static_cast<uint8_t>(level);
        }
        double direct = 0, dual = 0;
        int prev = 0;
        for (int k = 0; k < 256; ++k) {
          direct += static_cast<double>(bl.Pixels(b, c)[k]) * v[k];
          dual += static_cast<double>(bl.Suffix(b, c)[k]) * (v[k] - prev);
          prev = v[k];
        }
        EXPECT_NEAR(
            dual, direct,
            1e-5 * (std::abs(direct) + bl.Suffix(b, c)[0] * static_cast<double>(max_level)) + 1e-7);
      }
    }
    EXPECT_NEAR(sum, power[c], 1e-5 * power[c]);
  }
  // Updating in place with the same lighting gives the same numbers.
  BlockLighting again = bl;
  UpdateBlockLighting(RandomLight(n, 9), blocks, again);
  UpdateBlockLighting(light, blocks, again);
  EXPECT_EQ(again.dct, bl.dct);
  EXPECT_EQ(again.suffix, bl.suffix);
  EXPECT_THROW(ComputeBlockLighting(RandomLight(16, 1), blocks), std::invalid_argument);
  // The interleaved table holds the same suffix sums, 64-byte aligned rows, also in a copy.
  const BlockLighting copy = bl;
  for (const BlockLighting* p : {&bl, static_cast<const BlockLighting*>(&again), &copy}) {
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p->SuffixRgbXyz(0)) % 64, 0u);
    for (int b = 0; b < blocks.block_count(); b += 7)
      for (int k = 0; k <= 256; k += 5)
        for (int c = 0; c < 3; ++c) {
          const float* q = p->SuffixRgbXyz(b) + k * BlockLighting::kRgbXyzStride;
          EXPECT_EQ(q[c], bl.Suffix(b, c)[k]);
          for (int a = 0; a < 3; ++a) EXPECT_EQ(q[4 * (a + 1) + c], bl.SuffixVec(b, c)[3 * k + a]);
        }
  }
}

}  // namespace
}  // namespace prt
