#include "worker/block_spill.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <random>

namespace prt {
namespace {

struct Output {
  std::vector<uint32_t> first, count;
  std::vector<std::vector<float>> blocks;
};

Output Transpose(const std::vector<float>& rows, uint64_t nrows, std::size_t stride, uint32_t begin,
                 uint32_t end, uint64_t budget, uint64_t* runs) {
  BlockSpillOptions o;
  o.memory_budget_bytes = budget;
  o.spill_dir = std::filesystem::temp_directory_path().string();
  o.columns_per_block = 10;
  BlockTransposer t(nrows, begin, end, o);
  // Row slabs of random sizes in a shuffled order.
  std::vector<std::pair<uint64_t, uint64_t>> slabs;
  std::mt19937 rng(8);
  for (uint64_t r = 0; r < nrows;) {
    const uint64_t c = std::min<uint64_t>(nrows - r, 1 + rng() % 17);
    slabs.push_back({r, c});
    r += c;
  }
  std::shuffle(slabs.begin(), slabs.end(), rng);
  for (auto [r, c] : slabs) t.AddRows(r, c, rows.data() + r * stride + begin, stride);
  Output out;
  uint32_t f, n;
  std::vector<float> cols;
  while (t.NextColumnBlock(f, n, cols)) {
    out.first.push_back(f);
    out.count.push_back(n);
    out.blocks.push_back(cols);
  }
  *runs = t.runs_spilled();
  return out;
}

TEST(BlockTransposer, TinyBudgetSpillsAndGivesTheInMemoryResultBitForBit) {
  const uint64_t nrows = 203;
  const std::size_t stride = 90;
  const uint32_t begin = 5, end = 82;
  std::vector<float> rows(nrows * stride);
  std::mt19937 rng(1);
  for (float& v : rows) v = std::uniform_real_distribution<float>(-1, 1)(rng);
  uint64_t runs_small = 0, runs_big = 0, runs_below = 0, runs_exact = 0;
  const Output small = Transpose(rows, nrows, stride, begin, end, 600, &runs_small);
  const Output big = Transpose(rows, nrows, stride, begin, end, 1ull << 30, &runs_big);
  // The owned data is 203 × 77 floats: one byte less takes the buffered path (and spills at
  // least once), exactly that much the direct one (rows written into their column blocks).
  const uint64_t owned = nrows * (end - begin) * sizeof(float);
  const Output below = Transpose(rows, nrows, stride, begin, end, owned - 1, &runs_below);
  const Output exact = Transpose(rows, nrows, stride, begin, end, owned, &runs_exact);
  EXPECT_GT(runs_small, 20u);
  EXPECT_EQ(runs_big, 0u);
  EXPECT_GE(runs_below, 1u);
  EXPECT_EQ(runs_exact, 0u);
  EXPECT_EQ(below.blocks, big.blocks);
  EXPECT_EQ(exact.blocks, big.blocks);
  ASSERT_EQ(small.blocks.size(), 8u);  // ⌈77 / 10⌉
  ASSERT_EQ(big.blocks.size(), 8u);
  for (std::size_t b = 0; b < 8; ++b) {
    EXPECT_EQ(small.first[b], begin + 10 * b);
    EXPECT_EQ(small.count[b], b < 7 ? 10u : 7u);
    ASSERT_EQ(small.blocks[b].size(), big.blocks[b].size());
    EXPECT_EQ(std::memcmp(small.blocks[b].data(), big.blocks[b].data(),
                          small.blocks[b].size() * sizeof(float)),
              0);
    for (uint32_t k = 0; k < small.count[b]; ++k)
      for (uint64_t r = 0; r < nrows; ++r)
        ASSERT_EQ(small.blocks[b][k * nrows + r], rows[r * stride + small.first[b] + k]);
  }
}

TEST(BlockTransposer, DirectModeRejectsMissingAndDuplicateRows) {
  BlockSpillOptions o;
  o.memory_budget_bytes = 1ull << 20;  // all 4 × 7 floats fit: direct mode
  o.columns_per_block = 3;
  BlockTransposer t(4, 0, 7, o);
  std::vector<float> rows(4 * 7);
  std::iota(rows.begin(), rows.end(), 0.0f);
  t.AddRows(0, 2, rows.data(), 7);
  EXPECT_THROW(t.AddRows(1, 1, rows.data(), 7), std::invalid_argument);
  EXPECT_THROW(t.AddRows(3, 2, rows.data(), 7), std::invalid_argument);  // past the last row
  uint32_t f, n;
  std::vector<float> c;
  EXPECT_THROW(t.NextColumnBlock(f, n, c), std::invalid_argument);  // rows 2 and 3 missing
  t.AddRows(2, 2, rows.data() + 2 * 7, 7);
  ASSERT_TRUE(t.NextColumnBlock(f, n, c));
  EXPECT_EQ(f, 0u);
  EXPECT_EQ(n, 3u);
  EXPECT_EQ(c, (std::vector<float>{0, 7, 14, 21, 1, 8, 15, 22, 2, 9, 16, 23}));
  ASSERT_TRUE(t.NextColumnBlock(f, n, c));
  ASSERT_TRUE(t.NextColumnBlock(f, n, c));
  EXPECT_EQ(f, 6u);
  EXPECT_EQ(n, 1u);
  EXPECT_EQ(c, (std::vector<float>{6, 13, 20, 27}));
  EXPECT_FALSE(t.NextColumnBlock(f, n, c));
}

TEST(BlockTransposer, RejectsMissingAndDuplicateRowsAndCleansUp) {
  const auto dir = std::filesystem::temp_directory_path() / "prt-spill-test";
  std::filesystem::create_directories(dir);
  {
    BlockSpillOptions o;
    o.memory_budget_bytes = 1;
    o.spill_dir = dir.string();
    o.columns_per_block = 3;
    BlockTransposer t(4, 0, 7, o);
    std::vector<float> rows(4 * 7, 1.0f);
    t.AddRows(0, 2, rows.data(), 7);
    EXPECT_THROW(t.AddRows(1, 1, rows.data(), 7), std::invalid_argument);
    uint32_t f, n;
    std::vector<float> c;
    EXPECT_THROW(t.NextColumnBlock(f, n, c), std::invalid_argument);
    EXPECT_GT(t.runs_spilled(), 0u);
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir)) << "spill runs are removed";
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace prt
