// The estimate's sums (worker/transport_error_estimate.h): ExactSum is exact over the whole range
// of doubles and independent of the order of its terms; Σ B² of RadianceNormAccumulator has the
// same bits for any chunking of the rows and any number of processes adding their Flat() forms.
#include "worker/transport_error_estimate.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

namespace prt {
namespace {

TEST(ExactSumTest, IsExactAndTheSameInAnyOrder) {
  // Terms from subnormals to 1e300: a double sum of them depends on the order; this one does not.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> exponent(-320, 300);
  std::vector<double> terms;
  for (int i = 0; i < 2000; ++i) terms.push_back(std::pow(10.0, exponent(rng)));
  terms.push_back(0.0);
  terms.push_back(std::numeric_limits<double>::denorm_min());
  ExactSum forward;
  for (double t : terms) forward.Add(t);
  for (uint32_t seed : {1u, 2u, 3u}) {
    std::vector<double> shuffled = terms;
    std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(seed));
    // Partial sums too, as TBB's parallel_reduce and the ranks make them.
    ExactSum a, b;
    for (std::size_t i = 0; i < shuffled.size(); ++i) (i % 3 == 0 ? a : b).Add(shuffled[i]);
    b.Add(a);
    EXPECT_EQ(b.Digits(), forward.Digits());
    EXPECT_EQ(b.Value(), forward.Value());
  }
  // 2^-80 + 3 + 2^-80 keeps both small terms (a double sum would drop them).
  ExactSum t;
  t.Add(0x1p-80);
  t.Add(3.0);
  t.Add(0x1p-80);
  ExactSum u;
  u.Add(0x1p-79);
  u.Add(3.0);
  EXPECT_EQ(t.Digits(), u.Digits());
  ExactSum big;
  for (int i = 0; i < 1000; ++i) big.Add(0x1p1000);
  EXPECT_EQ(big.Value(), 1000 * 0x1p1000);
}

TEST(ExactSumTest, DigitsSummedElementWiseAreTheExactSum) {
  // Three "ranks"' digits added as doubles element by element (MPI_SUM), in two orders.
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> exponent(-30, 10);
  ExactSum whole, part[3];
  for (int i = 0; i < 3000; ++i) {
    const double v = std::pow(2.0, exponent(rng));
    whole.Add(v);
    part[i % 3].Add(v);
  }
  for (const std::vector<int>& order : {std::vector<int>{0, 1, 2}, {2, 0, 1}}) {
    std::vector<double> flat = part[order[0]].Digits();
    ASSERT_EQ(flat.size(), ExactSum::kFlatSize);
    for (int i = 1; i < 3; ++i) {
      const std::vector<double> d = part[order[static_cast<std::size_t>(i)]].Digits();
      for (std::size_t k = 0; k < flat.size(); ++k) flat[k] += d[k];
    }
    ExactSum back;
    back.SetDigits(flat.data());
    EXPECT_EQ(back.Digits(), whole.Digits());
  }
}

TEST(RadianceNormAccumulatorTest, SameBitsForAnyChunkingAndProcessCount) {
  const int n = 4;
  const std::size_t T = 6 * n * n;
  CubemapRgb sky;
  sky.n = n;
  sky.r.assign(T, 1.0f);
  sky.g.assign(T, 1.0f);
  sky.b.assign(T, 1.0f);
  CubemapRgb coloured = sky;
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(0.0f, 5.0f);
  for (std::size_t j = 0; j < T; ++j) {
    coloured.r[j] = u(rng);
    coloured.g[j] = u(rng) * 100;
    coloured.b[j] = u(rng) * 1e-3f;
  }
  const std::vector<CubemapRgb> lights = {sky, coloured};
  const std::vector<uint64_t> meshes = {150, 350};
  std::vector<float> rows(500 * T);
  for (float& x : rows) x = u(rng) * 1e-3f;

  RadianceNormAccumulator all(lights, meshes);
  all.AddRows(0, 500, rows.data());
  // 1, 2 and 3 processes, rows in chunks of various sizes, their Flat() summed element-wise.
  for (int procs : {1, 2, 3}) {
    std::vector<RadianceNormAccumulator> mine(static_cast<std::size_t>(procs),
                                              RadianceNormAccumulator(lights, meshes));
    uint64_t first = 0;
    for (uint64_t i = 0; first < 500; ++i) {
      const uint64_t count = std::min<uint64_t>(7 + 13 * (i % 3), 500 - first);
      mine[i % static_cast<uint64_t>(procs)].AddRows(first, count, rows.data() + first * T);
      first += count;
    }
    std::vector<double> flat(mine[0].Flat().size(), 0.0);
    for (const RadianceNormAccumulator& m : mine) {
      const std::vector<double> f = m.Flat();
      for (std::size_t k = 0; k < f.size(); ++k) flat[k] += f[k];
    }
    RadianceNormAccumulator reduced(lights, meshes);
    reduced.Set(flat);
    EXPECT_EQ(reduced.norms(), all.norms()) << procs << " processes";
  }
  // And the values are the sums: uniform sky, mesh 0, one channel, from long doubles.
  long double truth = 0;
  for (uint64_t v = 0; v < 150; ++v) {
    double b = 0;
    for (std::size_t j = 0; j < T; ++j) b += rows[v * T + j];
    truth += static_cast<long double>(b) * b;
  }
  EXPECT_NEAR(all.norms()[0][0][0], static_cast<double>(truth), 1e-6 * static_cast<double>(truth));
  EXPECT_EQ(all.norms()[0][0][0], all.norms()[0][0][2]);  // a grey light
  EXPECT_THROW(all.Set(std::vector<double>(3)), std::invalid_argument);
}

}  // namespace
}  // namespace prt
