// transport.variance's exact sums (formats/transport_variance.h): the same bits for any split of
// the rows into jobs, any order of the jobs and any number of ranks reducing them, values within
// a double's rounding of the true sums; the file and log formats round-trip, and version 1 files
// and log records (doubles) are still read.
#include "formats/transport_variance.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {
namespace {

constexpr uint32_t kN = 4;  // 96 texels
const std::vector<uint64_t> kMeshRows = {300, 700};

// Rows of per-texel variances spanning many orders of magnitude (as a partly occluded texel's
// do: from ~1e-14 to the largest a texel can have, 8/9), some exactly 0.
std::vector<float> RandomRows(std::size_t rows, std::size_t texels, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> exponent(-14, 0);
  std::uniform_int_distribution<int> zero(0, 9);
  std::vector<float> v(rows * texels);
  for (float& x : v)
    x = zero(rng) == 0 ? 0.0f : static_cast<float>(std::pow(10.0, exponent(rng)) * 0.88);
  return v;
}

// The sums of rows [0, rows) added in jobs of the given sizes, the jobs in the given order.
TransportVariance SumInJobs(const std::vector<float>& rows, const std::vector<uint64_t>& sizes,
                            const std::vector<std::size_t>& order) {
  const std::size_t T = 6 * kN * kN;
  std::vector<TransportVariance> jobs;
  uint64_t first = 0;
  for (uint64_t size : sizes) {
    TransportVariance job = MakeTransportVariance(kN, 4, kMeshRows);
    for (uint64_t r = first; r < first + size; ++r) job.AddRow(r, rows.data() + r * T);
    jobs.push_back(std::move(job));
    first += size;
  }
  TransportVariance total = MakeTransportVariance(kN, 4, kMeshRows);
  for (std::size_t j : order) total.Add(jobs[j]);
  return total;
}

std::vector<uint64_t> Split(uint64_t rows, uint64_t job) {
  std::vector<uint64_t> sizes;
  for (uint64_t at = 0; at < rows; at += job) sizes.push_back(std::min(job, rows - at));
  return sizes;
}

std::vector<std::size_t> Order(std::size_t n, uint32_t seed) {
  std::vector<std::size_t> o(n);
  std::iota(o.begin(), o.end(), 0);
  if (seed != 0) std::shuffle(o.begin(), o.end(), std::mt19937(seed));
  return o;
}

TEST(TransportVarianceTest, ExactSumsAreTheSameForAnyJobSplitAndOrder) {
  const std::size_t T = 6 * kN * kN;
  const std::vector<float> rows = RandomRows(1000, T, 7);
  const TransportVariance a = SumInJobs(rows, Split(1000, 1000), Order(1, 0));
  for (uint64_t job : {1, 5, 7, 64, 333}) {
    const std::vector<uint64_t> sizes = Split(1000, job);
    for (uint32_t seed : {0u, 1u, 2u}) {
      const TransportVariance b = SumInJobs(rows, sizes, Order(sizes.size(), seed));
      ASSERT_EQ(b.rows_covered, a.rows_covered);
      ASSERT_TRUE(b.sums == a.sums) << "jobs of " << job << " rows, order " << seed;
      ASSERT_EQ(EncodeTransportVariance(b), EncodeTransportVariance(a));
    }
  }
  EXPECT_EQ(a.rows_covered, (std::vector<uint64_t>{300, 700}));

  // The values are the true sums (long double here) to a double's rounding, and plain double sums
  // of these rows do depend on the order: what the exact form is for.
  int order_dependent = 0;
  for (std::size_t m = 0; m < 2; ++m) {
    const std::vector<double> s = a.MeshSums(m);
    const uint64_t first = m == 0 ? 0 : 300;
    for (std::size_t j = 0; j < T; ++j) {
      long double truth = 0;
      double forward = 0, backward = 0;
      for (uint64_t r = first; r < first + kMeshRows[m]; ++r) {
        truth += rows[r * T + j];
        forward += rows[r * T + j];
      }
      for (uint64_t r = first + kMeshRows[m]; r-- > first;) backward += rows[r * T + j];
      EXPECT_NEAR(s[j], static_cast<double>(truth), 1e-15 * static_cast<double>(truth) + 1e-26)
          << "mesh " << m << " texel " << j;
      order_dependent += forward != backward ? 1 : 0;
    }
  }
  EXPECT_GT(order_dependent, 10);
}

TEST(TransportVarianceTest, DigitsSummedWordByWordInAnyOrderGiveTheExactSum) {
  // Four "ranks" each hold some of the jobs; the element-wise sum of their digit vectors (what
  // MPI_SUM does, in whatever order) carried back equals adding their sums directly.
  const std::size_t T = 6 * kN * kN;
  const std::vector<float> rows = RandomRows(1000, T, 11);
  std::vector<TransportVariance> ranks(4, MakeTransportVariance(kN, 4, kMeshRows));
  for (uint64_t r = 0; r < 1000; ++r) ranks[(r / 13) % 4].AddRow(r, rows.data() + r * T);
  TransportVariance direct = MakeTransportVariance(kN, 4, kMeshRows);
  for (const TransportVariance& v : ranks) direct.Add(v);
  for (const std::vector<int>& order : {std::vector<int>{0, 1, 2, 3}, {3, 1, 0, 2}}) {
    std::vector<uint64_t> words = ranks[static_cast<std::size_t>(order[0])].Digits();
    for (std::size_t i = 1; i < order.size(); ++i) {
      const std::vector<uint64_t> d = ranks[static_cast<std::size_t>(order[i])].Digits();
      for (std::size_t k = 0; k < words.size(); ++k) words[k] += d[k];
    }
    TransportVariance reduced = MakeTransportVariance(kN, 4, kMeshRows);
    reduced.AddDigits(words);
    EXPECT_TRUE(reduced.sums == direct.sums);
  }
  EXPECT_THROW(direct.AddDigits(std::vector<uint64_t>(3)), std::invalid_argument);
}

TEST(TransportVarianceTest, FixedPointUnitsAndBounds) {
  // 1 is 2^88 units: hi = 2^24.
  const ExactVarianceSum one = ExactVarianceSum::FromValue(1.0);
  EXPECT_EQ(one.hi, uint64_t{1} << 24);
  EXPECT_EQ(one.lo, 0u);
  EXPECT_EQ(one.Value(), 1.0);
  EXPECT_EQ(ExactVarianceSum::FromValue(0x1p-88).lo, 1u);
  EXPECT_EQ(ExactVarianceSum::FromValue(0x1p-90).lo, 0u);  // below half a unit
  const ExactVarianceSum f = ExactVarianceSum::FromValue(static_cast<double>(0.1f));
  EXPECT_EQ(f.Value(), static_cast<double>(0.1f));  // a float's 24 bits are kept exactly
  // A carry from lo into hi.
  ExactVarianceSum a{~uint64_t{0}, 0};
  a.Add({1, 0});
  EXPECT_EQ(a.lo, 0u);
  EXPECT_EQ(a.hi, 1u);
  ExactVarianceSum full{~uint64_t{0}, ~uint64_t{0}};
  EXPECT_THROW(full.Add({1, 0}), std::overflow_error);

  // What AddRow refuses: values no sampler can produce (the bound that keeps sums below 2^128).
  TransportVariance v = MakeTransportVariance(1, 4, {2});
  std::vector<float> row(6, 0.5f);
  v.AddRow(0, row.data());
  row[3] = 17.0f;
  EXPECT_THROW(v.AddRow(1, row.data()), NumericalError);
  row[3] = -1e-9f;
  EXPECT_THROW(v.AddRow(1, row.data()), NumericalError);
  row[3] = std::nanf("");
  EXPECT_THROW(v.AddRow(1, row.data()), NumericalError);
  EXPECT_THROW(MakeTransportVariance(1, 4, {kMaxMeshRows}), std::invalid_argument);
}

// An image run's groups interleave (each pixel's mesh): AddRow adds each row to its sample's
// group, which then equals the sums of contiguous groups of the same rows regrouped.
TEST(TransportVarianceTest, InterleavedGroupsAddEachRowToItsSamplesGroup) {
  const std::size_t T = 6 * kN * kN;
  const std::vector<float> rows = RandomRows(90, T, 5);
  auto groups = std::make_shared<std::vector<uint32_t>>(90);
  std::vector<uint64_t> counts(3, 0);
  for (std::size_t s = 0; s < 90; ++s) ++counts[(*groups)[s] = static_cast<uint32_t>(s * 7 % 3)];
  TransportVariance mixed = MakeTransportVariance(kN, 4, counts, groups);
  for (uint64_t r = 0; r < 90; ++r) mixed.AddRow(r, rows.data() + r * T);
  // The same rows sorted by group, contiguous.
  std::vector<float> sorted;
  for (uint32_t g = 0; g < 3; ++g)
    for (std::size_t s = 0; s < 90; ++s)
      if ((*groups)[s] == g)
        sorted.insert(sorted.end(), rows.begin() + s * T, rows.begin() + (s + 1) * T);
  TransportVariance contiguous = MakeTransportVariance(kN, 4, counts);
  for (uint64_t r = 0; r < 90; ++r) contiguous.AddRow(r, sorted.data() + r * T);
  EXPECT_TRUE(mixed.sums == contiguous.sums);
  EXPECT_EQ(mixed.rows_covered, counts);
  // Groups that do not hold the counts, or a sample beyond them, are refused.
  EXPECT_THROW(MakeTransportVariance(kN, 4, {30, 30, 31}, groups), std::invalid_argument);
  EXPECT_THROW(mixed.AddRow(90, rows.data()), std::out_of_range);
}

TEST(TransportVarianceTest, FileRoundTripsAndDamageIsRefused) {
  const std::size_t T = 6 * kN * kN;
  const std::vector<float> rows = RandomRows(300, T, 3);
  TransportVariance v = MakeTransportVariance(kN, 4, kMeshRows);
  for (uint64_t r = 0; r < 300; ++r) v.AddRow(r, rows.data() + r * T);
  const std::string bytes = EncodeTransportVariance(v);
  EXPECT_EQ(bytes.substr(0, 8), "PRTVAR02");
  // Header 8 + 16, per mesh 16, mesh 0's 96 sums of 16 bytes (mesh 1 covers no row), checksum 8.
  EXPECT_EQ(bytes.size(), 8u + 16 + 2 * 16 + T * 16 + 8);
  const TransportVariance back = DecodeTransportVariance(bytes, "v");
  EXPECT_TRUE(back.sums == v.sums);
  EXPECT_EQ(back.rows_covered, v.rows_covered);
  EXPECT_EQ(back.mesh_rows, v.mesh_rows);

  std::string damaged = bytes;
  damaged[100] ^= 1;
  EXPECT_THROW(DecodeTransportVariance(damaged, "v"), InputError);
  EXPECT_THROW(DecodeTransportVariance(bytes.substr(0, 50), "v"), InputError);
  // A sum beyond what its covered rows can hold (checksum fixed up): refused.
  std::string huge = bytes.substr(0, bytes.size() - 8);
  const uint64_t hi = ~uint64_t{0};
  std::memcpy(huge.data() + 8 + 16 + 16 + 8, &hi, 8);  // mesh 0, texel 0, hi word
  const uint64_t sum = Checksum64(huge.data(), huge.size());
  huge.append(reinterpret_cast<const char*>(&sum), 8);
  EXPECT_THROW(DecodeTransportVariance(huge, "v"), InputError);

  // A hostile header: 20 uncovered meshes of n = 4096 would be 2·10⁹ zeros (32 GB); refused
  // before anything is allocated, as is a covered mesh whose sums the file does not hold.
  for (const uint64_t covered : {0, 1}) {
    ByteWriter w;
    w.PutBytes("PRTVAR02", 8);
    w.Put<uint32_t>(covered ? 1024 : 4096);
    w.Put<uint32_t>(4);
    w.Put<uint64_t>(covered ? 1 : 20);
    for (int m = 0; m < (covered ? 1 : 20); ++m) {
      w.Put<uint64_t>(1);
      w.Put<uint64_t>(covered);
    }
    std::string& b = w.bytes();
    w.Put<uint64_t>(Checksum64(b.data(), b.size()));
    EXPECT_THROW(DecodeTransportVariance(b, "hostile"), InputError) << covered;
  }
  EXPECT_THROW(MakeTransportVariance(4096, 4, std::vector<uint64_t>(3, 1)), std::invalid_argument);
}

// A version-1 file (doubles) as prt-farm wrote it before the sums were exact.
std::string VersionOneFile(double value, uint64_t covered) {
  ByteWriter w;
  w.PutBytes("PRTVAR01", 8);
  w.Put<uint32_t>(1);
  w.Put<uint32_t>(4);
  w.Put<uint64_t>(1);
  w.Put<uint64_t>(10);
  w.Put<uint64_t>(covered);
  for (int j = 0; j < 6; ++j) w.Put<double>(j == 2 ? value : 0.25);
  std::string& out = w.bytes();
  w.Put<uint64_t>(Checksum64(out.data(), out.size()));
  return std::move(out);
}

TEST(TransportVarianceTest, VersionOneFilesAndLogRecordsAreStillRead) {
  const TransportVariance v = DecodeTransportVariance(VersionOneFile(0.75, 3), "old");
  ASSERT_EQ(v.sums.size(), 1u);
  EXPECT_EQ(v.rows_covered[0], 3u);
  EXPECT_EQ(v.MeshSums(0), (std::vector<double>{0.25, 0.25, 0.75, 0.25, 0.25, 0.25}));
  EXPECT_THROW(DecodeTransportVariance(VersionOneFile(-1.0, 3), "old"), InputError);
  EXPECT_THROW(DecodeTransportVariance(VersionOneFile(1e30, 3), "old"), InputError);

  // A log: a version-1 record ("PVLG", doubles), then a current one; both are read.
  const std::string old_file = VersionOneFile(0.5, 2);
  ByteWriter body;
  body.Put<uint32_t>(5);
  body.PutBytes("brute", 5);
  body.Put<uint64_t>(0);
  body.Put<uint64_t>(2);
  body.PutBytes(old_file.data() + 8, old_file.size() - 16);  // the sums, without magic or sum
  ByteWriter rec;
  rec.Put<uint32_t>(0x474C5650);
  rec.Put<uint64_t>(body.bytes().size());
  rec.PutBytes(body.bytes().data(), body.bytes().size());
  rec.Put<uint64_t>(Checksum64(body.bytes().data(), body.bytes().size()));
  TransportVariance now = MakeTransportVariance(1, 4, {10});
  const std::vector<float> row(6, 0.125f);
  now.AddRow(2, row.data());
  const std::string log = rec.bytes() + EncodeVarianceLogRecord({"brute", 2, 1, now});
  const std::vector<VarianceLogRecord> records = DecodeVarianceLog(log, "log");
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].first, 0u);
  EXPECT_EQ(records[0].sums.MeshSums(0)[2], 0.5);
  EXPECT_EQ(records[1].first, 2u);
  EXPECT_TRUE(records[1].sums.sums == now.sums);
  // A torn last record is dropped, the ones before it kept.
  EXPECT_EQ(DecodeVarianceLog(log.substr(0, log.size() - 3), "log").size(), 1u);
}

}  // namespace
}  // namespace prt
