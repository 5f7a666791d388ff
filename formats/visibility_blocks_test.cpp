#include "formats/visibility_blocks.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "vocabulary/errors.h"

namespace prt {
namespace {

// Maps with contiguous spans (what occluders produce): per vertex a random half-space cut of the
// cube faces plus a few random rectangles, levels 0 … 2^bits − 1.
std::vector<uint8_t> SyntheticMap(int n, int bits, std::mt19937& rng) {
  const int max_level = (1 << bits) - 1;
  std::vector<uint8_t> map(static_cast<std::size_t>(6) * n * n, 0);
  std::uniform_int_distribution<int> coord(0, n - 1), face(0, 5), lev(1, max_level);
  for (int f = 0; f < 6; ++f)
    if (rng() % 2)
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x)
          map[(static_cast<std::size_t>(f) * n + y) * n + x] = static_cast<uint8_t>(max_level);
  for (int r = 0; r < 6; ++r) {
    const int f = face(rng), x0 = coord(rng), y0 = coord(rng), x1 = coord(rng), y1 = coord(rng);
    const auto value = static_cast<uint8_t>(rng() % 3 == 0 ? 0 : lev(rng));
    for (int y = std::min(y0, y1); y <= std::max(y0, y1); ++y)
      for (int x = std::min(x0, x1); x <= std::max(x0, x1); ++x)
        map[(static_cast<std::size_t>(f) * n + y) * n + x] = value;
  }
  return map;
}

TEST(VisibilityBlocks, BinaryAndQuantisedRoundTripLossless) {
  std::mt19937 rng(7);
  for (int bits : {1, 6}) {
    for (int n : {16, 64}) {
      VisibilityBlocks blocks = MakeVisibilityBlocks(n, bits);
      std::vector<std::vector<uint8_t>> maps;
      for (int v = 0; v < 20; ++v) {
        maps.push_back(SyntheticMap(n, bits, rng));
        AppendVisibilityMap(blocks, maps.back());
      }
      for (int v = 0; v < 20; ++v) EXPECT_EQ(DecodeVisibilityMap(blocks, v), maps[v]);
      const std::vector<uint8_t> bytes = EncodeVisibilityBlocks(blocks);
      const VisibilityBlocks back = DecodeVisibilityBlocks(bytes);
      EXPECT_EQ(back.kind, blocks.kind);
      EXPECT_EQ(back.change_begin, blocks.change_begin);
      EXPECT_EQ(back.change_pos, blocks.change_pos);
      EXPECT_EQ(back.change_value, blocks.change_value);
      EXPECT_EQ(EncodeVisibilityBlocks(back), bytes);
      const VisibilityBlockCounts c = CountVisibilityBlocks(blocks);
      EXPECT_EQ(c.zero + c.one + c.mixed, 20u * blocks.blocks_per_map());
      EXPECT_GT(c.mixed, 0u);
    }
  }
}

TEST(VisibilityBlocks, DerivativeIsEquation5) {
  // One block: V = 0 0 1 1 1 0 1 … 1 → changes at 2 (+1), 5 (−1), 6 (+1).
  VisibilityBlocks blocks = MakeVisibilityBlocks(16, 1);
  std::vector<uint8_t> map(6 * 256, 0);
  for (int k = 2; k < 256; ++k) map[k] = (k == 5) ? 0 : 1;
  AppendVisibilityMap(blocks, map);
  ASSERT_EQ(blocks.kind[0], static_cast<uint8_t>(VisibilityBlockKind::kMixed));
  EXPECT_EQ(std::vector<uint8_t>(blocks.change_pos.begin(), blocks.change_pos.end()),
            (std::vector<uint8_t>{2, 5, 6}));
  for (int b = 1; b < 6; ++b) EXPECT_EQ(blocks.kind[b], 0);
  // Merging two databases keeps offsets consistent.
  VisibilityBlocks two = blocks;
  AppendVisibilityBlocks(two, blocks);
  EXPECT_EQ(DecodeVisibilityMap(two, 1), map);
}

TEST(VisibilityBlocks, CorruptedInputFailsCleanly) {
  std::mt19937 rng(3);
  for (int bits : {1, 4}) {
    VisibilityBlocks blocks = MakeVisibilityBlocks(16, bits);
    for (int v = 0; v < 4; ++v) AppendVisibilityMap(blocks, SyntheticMap(16, bits, rng));
    const std::vector<uint8_t> good = EncodeVisibilityBlocks(blocks);
    // Every truncation throws InputError.
    for (std::size_t len = 0; len < good.size(); ++len)
      EXPECT_THROW(DecodeVisibilityBlocks(std::span(good.data(), len)), InputError) << len;
    // Random corruptions either throw InputError or decode to a consistent database.
    int threw = 0;
    for (int trial = 0; trial < 3000; ++trial) {
      std::vector<uint8_t> bad = good;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int i = 0; i < flips; ++i) bad[rng() % bad.size()] = static_cast<uint8_t>(rng());
      try {
        const VisibilityBlocks d = DecodeVisibilityBlocks(bad);
        ASSERT_EQ(d.kind.size(), d.vertex_count * d.blocks_per_map());
        ASSERT_EQ(d.change_begin.size(), d.kind.size() + 1);
        for (std::size_t v = 0; v < d.vertex_count; ++v) {
          const std::vector<uint8_t> map = DecodeVisibilityMap(d, v);
          for (uint8_t x : map) ASSERT_LE(x, d.max_level());
        }
      } catch (const InputError&) {
        ++threw;
      }
    }
    EXPECT_GT(threw, 1000);
  }
  // A huge vertex count with no data behind it is refused before allocating.
  std::vector<uint8_t> bomb = {'V', 'B', 1, 64, 1, 0xff, 0xff, 0xff, 0xff, 0x0f};
  EXPECT_THROW(DecodeVisibilityBlocks(bomb), InputError);
  EXPECT_THROW(DecodeVisibilityBlocks(std::vector<uint8_t>{'X', 'B', 1}), InputError);
}

}  // namespace
}  // namespace prt
