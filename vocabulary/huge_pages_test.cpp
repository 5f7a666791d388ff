#include "vocabulary/huge_pages.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <numeric>
#include <vector>

namespace prt {
namespace {

// The advice must never cost data: a wrong flag (MADV_DONTNEED, MADV_FREE, MADV_REMOVE) would
// silently zero touched pages, and the transposer advises buffers it may already have used.
TEST(HugePages, AdviceKeepsContentsAndIgnoresRangesWithoutAWholeHugePage) {
  std::vector<uint32_t> v(5u << 20);  // 20 MiB: several whole 2 MiB pieces
  std::iota(v.begin(), v.end(), 7u);
  AdviseHugePages(v.data(), v.size() * sizeof(uint32_t));
  AdviseHugePages(v.data() + 3, (v.size() - 5) * sizeof(uint32_t));  // unaligned ends
  for (std::size_t i = 0; i < v.size(); ++i) ASSERT_EQ(v[i], static_cast<uint32_t>(i + 7)) << i;
  EXPECT_FALSE(AdviseHugePages(nullptr, 1u << 30));
  EXPECT_FALSE(AdviseHugePages(v.data(), 0));
  EXPECT_FALSE(AdviseHugePages(v.data(), 4096));  // no whole 2 MiB piece inside
}

TEST(HugePages, ReserveFreshHugeKeepsAVectorThatIsLargeEnough) {
  std::vector<float> v(1000, 2.5f);
  const float* before = v.data();
  ReserveFreshHuge(v, 500);  // capacity suffices: untouched
  EXPECT_EQ(v.data(), before);
  EXPECT_EQ(v.size(), 1000u);
  EXPECT_EQ(v[999], 2.5f);
  ReserveFreshHuge(v, 3u << 20);  // reallocates: contents dropped, capacity at least n
  EXPECT_TRUE(v.empty());
  EXPECT_GE(v.capacity(), 3u << 20);
  v.assign(3u << 20, 1.0f);
  EXPECT_EQ(std::accumulate(v.begin(), v.end(), 0.0), static_cast<double>(3u << 20));
}

}  // namespace
}  // namespace prt
