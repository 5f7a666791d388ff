#include "vocabulary/wavelets.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <ctime>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "vocabulary/cubemap.h"

namespace prt {
namespace {

constexpr WaveletFilter kAllFilters[] = {WaveletFilter::kHaar, WaveletFilter::kDaubechies4,
                                         WaveletFilter::kLeGall53, WaveletFilter::kCdf97};
constexpr WaveletFilter kLiftingFilters[] = {WaveletFilter::kLeGall53, WaveletFilter::kCdf97};

std::vector<float> RandomSignal(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> v(n);
  for (float& x : v) x = u(rng);
  return v;
}

double Norm2(const std::vector<float>& v) {
  double s = 0;
  for (float x : v) s += static_cast<double>(x) * x;
  return s;
}

double RelativeError(const std::vector<float>& got, const std::vector<float>& want) {
  double num = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double d = static_cast<double>(got[i]) - want[i];
    num += d * d;
  }
  const double den = Norm2(want);
  return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

std::string Name(WaveletFilter f) {
  return WaveletFilterName(f);
}

// Sizes every filter accepts in 2D: square powers of two for Haar/D4, anything for lifting.
std::vector<std::pair<int, int>> Sizes2D(WaveletFilter f) {
  if (!IsLiftingFilter(f)) return {{1, 1}, {2, 2}, {4, 4}, {8, 8}, {32, 32}, {64, 64}};
  return {{1, 1}, {1, 5}, {7, 1}, {2, 3}, {3, 2}, {5, 7}, {17, 17}, {64, 64}, {100, 37}, {3, 100}};
}

std::vector<int> Lengths1D(WaveletFilter f) {
  if (!IsLiftingFilter(f)) return {1, 2, 4, 8, 64, 256};
  return {1, 2, 3, 4, 5, 7, 17, 64, 100, 257};
}

// ---- perfect reconstruction ------------------------------------------------------------------

// Inverse ∘ forward = identity to 1e-6 relative in float, for every filter, size and depth.
TEST(Wavelets, PerfectReconstruction1D) {
  for (WaveletFilter f : kAllFilters) {
    for (int n : Lengths1D(f)) {
      const int max_depth = WaveletMaxDepth(f, n);
      for (int k = 0; k <= max_depth; ++k) {
        const std::vector<float> x = RandomSignal(static_cast<std::size_t>(n), 11u + n);
        std::vector<float> y = x;
        ForwardWavelet1D(f, y.data(), n, k);
        InverseWavelet1D(f, y.data(), n, k);
        EXPECT_LE(RelativeError(y, x), 1e-6) << Name(f) << " n=" << n << " k=" << k;
      }
    }
  }
}

TEST(Wavelets, PerfectReconstruction2D) {
  for (WaveletFilter f : kAllFilters) {
    for (auto [w, h] : Sizes2D(f)) {
      const int max_depth = WaveletMaxDepth2D(f, w, h);
      for (int k = 0; k <= max_depth; ++k) {
        const std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 5u + w + 7u * h);
        std::vector<float> y = x;
        ForwardWavelet2D(f, y.data(), w, h, k);
        if (k > 0 && w * h > 1) {
          EXPECT_GT(RelativeError(y, x), 1e-3) << "transform did nothing";
        }
        InverseWavelet2D(f, y.data(), w, h, k);
        EXPECT_LE(RelativeError(y, x), 1e-6) << Name(f) << " " << w << "x" << h << " k=" << k;
      }
    }
  }
}

// Depth k is steps 1 … k applied one at a time, and the inverse undoes them in reverse order.
TEST(Wavelets, SingleStepsComposeToDepth) {
  for (WaveletFilter f : kAllFilters) {
    for (auto [w, h] : Sizes2D(f)) {
      const int max_depth = WaveletMaxDepth2D(f, w, h);
      const std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 3u + w * h);
      for (int k = 1; k <= max_depth; ++k) {
        std::vector<float> whole = x, steps = x;
        ForwardWavelet2D(f, whole.data(), w, h, k);
        for (int t = 1; t <= k; ++t) ForwardWavelet2DStep(f, steps.data(), w, h, t);
        EXPECT_LE(RelativeError(steps, whole), 1e-6) << Name(f) << " " << w << "x" << h;
        for (int t = k; t >= 1; --t) InverseWavelet2DStep(f, steps.data(), w, h, t);
        EXPECT_LE(RelativeError(steps, x), 1e-6) << Name(f) << " " << w << "x" << h;
      }
    }
  }
}

TEST(Wavelets, SingleStepsComposeToDepth1D) {
  for (WaveletFilter f : kAllFilters) {
    for (int n : Lengths1D(f)) {
      const std::vector<float> x = RandomSignal(static_cast<std::size_t>(n), 21u + n);
      for (int k = 1; k <= WaveletMaxDepth(f, n); ++k) {
        std::vector<float> whole = x, steps = x;
        ForwardWavelet1D(f, whole.data(), n, k);
        for (int t = 1; t <= k; ++t) ForwardWavelet1DStep(f, steps.data(), n, t);
        EXPECT_LE(RelativeError(steps, whole), 1e-6) << Name(f) << " n=" << n;
        for (int t = k; t >= 1; --t) InverseWavelet1DStep(f, steps.data(), n, t);
        EXPECT_LE(RelativeError(steps, x), 1e-6) << Name(f) << " n=" << n;
      }
    }
  }
}

// The float step on interleaved channels equals the double step on each channel alone, for
// every filter, shape (w×1 is a mesh's 1D segment), step and channel count; coefficients outside
// the step's region stay untouched.
TEST(Wavelets, InterleavedFloatStepMatchesThePerChannelStep) {
  for (WaveletFilter f : kAllFilters) {
    for (auto [w, h] : Sizes2D(f)) {
      for (int channels : {1, 3, 4}) {
        const std::size_t area = static_cast<std::size_t>(w) * h;
        const std::vector<float> x = RandomSignal(area * channels, 7u + w * h + channels);
        for (int t = 1; t <= WaveletMaxDepth2D(f, w, h); ++t) {
          std::vector<float> got = x, scratch(area * channels, -7.0f);
          InverseWavelet2DStepInterleaved(f, got.data(), w, h, channels, t, scratch.data());
          for (int c = 0; c < channels; ++c) {
            std::vector<float> plane(area), mine(area);
            for (std::size_t i = 0; i < area; ++i) {
              plane[i] = x[i * channels + c];
              mine[i] = got[i * channels + c];
            }
            const std::vector<float> before = plane;
            InverseWavelet2DStep(f, plane.data(), w, h, t);
            // Float rounding of up to four lifting steps (CDF 9/7 reaches 4.3e-7); the terms it
            // sums carry 9-bit quantisation (~2e-3).
            EXPECT_LE(RelativeError(mine, plane), 1e-6)
                << Name(f) << " " << w << "x" << h << " step " << t << " channel " << c;
            const int wc = SizeAtDepth(w, t - 1), hc = SizeAtDepth(h, t - 1);
            for (int y = 0; y < h; ++y)
              for (int i = 0; i < w; ++i)
                if (i >= wc || y >= hc) {
                  const std::size_t k = static_cast<std::size_t>(y) * w + i;
                  ASSERT_EQ(mine[k], before[k]) << Name(f) << " " << w << "x" << h;
                }
          }
        }
      }
    }
  }
}

// The split 1D step gives InverseWavelet2DStepInterleaved's numbers on a length×1 region, with
// its bands in two buffers, both when it writes to a third buffer and when it writes over the
// high band's own buffer (the relighter's alternation of X and its scratch).
TEST(Wavelets, SplitOneDimensionalStepMatchesTheInterleavedStep) {
  const WaveletFilter f = WaveletFilter::kLeGall53;
  EXPECT_TRUE(InverseWavelet1DStepSplitSupported(f, 4));
  EXPECT_FALSE(InverseWavelet1DStepSplitSupported(WaveletFilter::kCdf97, 4));
  EXPECT_FALSE(InverseWavelet1DStepSplitSupported(f, 3));
  for (int length = 1; length <= 70; ++length) {
    for (int channels : {1, 4}) {
      const std::size_t n = static_cast<std::size_t>(length) * channels;
      const std::vector<float> x = RandomSignal(n, 3u + length * channels);
      for (int t = 1; t <= WaveletMaxDepth2D(f, length, 1); ++t) {
        std::vector<float> want = x, scratch(n);
        InverseWavelet2DStepInterleaved(f, want.data(), length, 1, channels, t, scratch.data());
        const int len = SizeAtDepth(length, t - 1), ns = (len + 1) / 2;
        const std::size_t region = static_cast<std::size_t>(len) * channels;
        // Low band elsewhere, output to a third buffer.
        std::vector<float> low(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(ns * channels));
        std::vector<float> out(n, -9.0f);
        InverseWavelet1DStepSplit(f, low.data(), x.data() + ns * channels, out.data(), length,
                                  channels, t);
        for (std::size_t i = 0; i < region; ++i)
          ASSERT_EQ(out[i], want[i]) << length << " " << channels << " step " << t;
        // Output over the buffer that holds the high band (its low band poisoned).
        std::vector<float> same = x;
        for (std::size_t i = 0; i < static_cast<std::size_t>(ns) * channels; ++i) same[i] = NAN;
        InverseWavelet1DStepSplit(f, low.data(), same.data() + ns * channels, same.data(), length,
                                  channels, t);
        for (std::size_t i = 0; i < n; ++i)
          ASSERT_EQ(same[i], i < region ? want[i] : x[i]) << length << " " << channels << " " << t;
      }
    }
  }
  float v = 0;
  EXPECT_THROW(InverseWavelet1DStepSplit(WaveletFilter::kCdf97, &v, &v, &v, 1, 4, 1),
               std::invalid_argument);
}

// The AVX synthesis (two 4-channel elements per vector) gives the 128-bit code's bits, for the
// split step in both aliasing modes and for the 2D interleaved step, at every length and step.
TEST(Wavelets, AvxSynthesisHasTheSameBitsAsThe128BitCode) {
  const WaveletFilter f = WaveletFilter::kLeGall53;
  const bool had = SetWaveletAvx(true);
  if (!SetWaveletAvx(true)) GTEST_SKIP() << "no AVX on this CPU";
  for (int length = 1; length <= 90; ++length) {
    for (int height : {1, 3}) {
      const std::size_t n = static_cast<std::size_t>(length) * height * 4;
      const std::vector<float> x = RandomSignal(n, 7u + length * height);
      for (int t = 1; t <= WaveletMaxDepth2D(f, length, height); ++t) {
        std::vector<float> r[2];
        for (int avx = 0; avx < 2; ++avx) {
          SetWaveletAvx(avx == 1);
          r[avx] = x;
          std::vector<float> scratch(n);
          InverseWavelet2DStepInterleaved(f, r[avx].data(), length, height, 4, t, scratch.data());
          if (height == 1) {
            const int len = SizeAtDepth(length, t - 1), ns = (len + 1) / 2;
            std::vector<float> same = x;
            InverseWavelet1DStepSplit(f, x.data(), same.data() + ns * 4, same.data(), length, 4, t);
            r[avx].insert(r[avx].end(), same.begin(), same.end());
          }
        }
        ASSERT_EQ(r[0].size(), r[1].size());
        for (std::size_t i = 0; i < r[0].size(); ++i)
          ASSERT_EQ(r[0][i], r[1][i]) << length << "x" << height << " step " << t << " at " << i;
      }
    }
  }
  SetWaveletAvx(had);
}

// A single step touches only the region SizeAtDepth(·, t−1) of its step.
TEST(Wavelets, SingleStepLeavesOuterCoefficientsAlone) {
  const int w = 13, h = 9;
  const std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 99);
  std::vector<float> y = x;
  ForwardWavelet2DStep(WaveletFilter::kCdf97, y.data(), w, h, 2);
  const int wc = SizeAtDepth(w, 1), hc = SizeAtDepth(h, 1);
  for (int yy = 0; yy < h; ++yy) {
    for (int xx = 0; xx < w; ++xx) {
      if (xx >= wc || yy >= hc) {
        EXPECT_EQ(y[yy * w + xx], x[yy * w + xx]) << xx << "," << yy;
      }
    }
  }
}

// Cheslack-Postava et al. Eq. 6–8: relighting from columns compressed to different depths with
// one single-step inverse per level equals inverse-transforming every column separately.
TEST(Wavelets, AdaptiveRelightingWithSingleStepsMatchesPerColumnInverse) {
  for (WaveletFilter f : kLiftingFilters) {
    const int w = 23, h = 14;
    const std::size_t area = static_cast<std::size_t>(w) * h;
    const int max_depth = WaveletMaxDepth2D(f, w, h);
    std::mt19937 rng(5);
    std::vector<std::vector<float>> columns;
    std::vector<int> depths;
    std::vector<float> weights;
    for (int i = 0; i < 12; ++i) {
      columns.push_back(RandomSignal(area, 100u + i));
      depths.push_back(static_cast<int>(rng() % static_cast<unsigned>(max_depth + 1)));
      weights.push_back(0.25f + 0.1f * static_cast<float>(i));
    }
    std::vector<double> reference(area, 0.0);
    for (std::size_t i = 0; i < columns.size(); ++i) {
      std::vector<float> c = columns[i];  // already "pixels"; transform to its depth
      ForwardWavelet2D(f, c.data(), w, h, depths[i]);
      columns[i] = c;
      InverseWavelet2D(f, c.data(), w, h, depths[i]);
      for (std::size_t j = 0; j < area; ++j) reference[j] += weights[i] * c[j];
    }
    std::vector<float> b(area, 0.0f);
    for (int level = max_depth; level >= 0; --level) {
      for (std::size_t i = 0; i < columns.size(); ++i) {
        if (depths[i] != level) continue;
        for (std::size_t j = 0; j < area; ++j) b[j] += weights[i] * columns[i][j];
      }
      if (level > 0) InverseWavelet2DStep(f, b.data(), w, h, level);
    }
    double num = 0, den = 0;
    for (std::size_t j = 0; j < area; ++j) {
      num += (b[j] - reference[j]) * (b[j] - reference[j]);
      den += reference[j] * reference[j];
    }
    EXPECT_LE(std::sqrt(num / den), 1e-6) << Name(f);
  }
}

TEST(Wavelets, CubemapIsPerFaceTransform) {
  for (WaveletFilter f : kAllFilters) {
    const int n = 8;
    const std::size_t fs = 64;
    const std::vector<float> x = RandomSignal(6 * fs, 17);
    for (int k : {1, 3}) {
      std::vector<float> cube = x, faces = x;
      ForwardWaveletCubemap(f, cube.data(), n, k);
      for (int face = 0; face < 6; ++face) ForwardWavelet2D(f, faces.data() + face * fs, n, n, k);
      EXPECT_EQ(cube, faces) << Name(f);
      InverseWaveletCubemap(f, cube.data(), n, k);
      EXPECT_LE(RelativeError(cube, x), 1e-6) << Name(f);
    }
  }
}

// ---- orthonormality --------------------------------------------------------------------------

// Parseval: Haar and D4 preserve energy to 1e-6 at every depth.
TEST(Wavelets, HaarAndD4PreserveEnergy) {
  for (WaveletFilter f : {WaveletFilter::kHaar, WaveletFilter::kDaubechies4}) {
    for (auto [w, h] : Sizes2D(f)) {
      for (int k = 0; k <= WaveletMaxDepth2D(f, w, h); ++k) {
        std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 40u + w);
        const double e0 = Norm2(x);
        ForwardWavelet2D(f, x.data(), w, h, k);
        EXPECT_NEAR(Norm2(x) / e0, 1.0, 1e-6) << Name(f) << " n=" << w << " k=" << k;
      }
    }
    for (int n : Lengths1D(f)) {
      std::vector<float> x = RandomSignal(static_cast<std::size_t>(n), 41u + n);
      const double e0 = Norm2(x);
      ForwardWavelet1D(f, x.data(), n, WaveletMaxDepth(f, n));
      EXPECT_NEAR(Norm2(x) / e0, 1.0, 1e-6) << Name(f) << " n=" << n;
    }
  }
}

// Brute force: the transform matrix M (columns = transforms of unit vectors) of a full Haar or
// D4 face transform satisfies MᵀM = I.
TEST(Wavelets, HaarAndD4MatricesAreOrthonormal) {
  for (WaveletFilter f : {WaveletFilter::kHaar, WaveletFilter::kDaubechies4}) {
    for (int n : {2, 4, 8}) {
      const int m = n * n;
      for (int k = 1; k <= WaveletMaxDepth2D(f, n, n); ++k) {
        std::vector<std::vector<float>> cols(m, std::vector<float>(m, 0.0f));
        for (int i = 0; i < m; ++i) {
          cols[i][i] = 1.0f;
          ForwardWavelet2D(f, cols[i].data(), n, n, k);
        }
        double worst = 0;
        for (int i = 0; i < m; ++i) {
          for (int j = 0; j < m; ++j) {
            double dot = 0;
            for (int r = 0; r < m; ++r) dot += static_cast<double>(cols[i][r]) * cols[j][r];
            worst = std::max(worst, std::abs(dot - (i == j ? 1.0 : 0.0)));
          }
        }
        EXPECT_LE(worst, 1e-6) << Name(f) << " n=" << n << " k=" << k;
      }
    }
  }
}

// The lifting filters with √2 normalisation are not orthonormal: on white noise one 1D step
// multiplies the expected energy by (‖h‖² + ‖g‖²)/2 of the scaled analysis filters, 1.0117 for
// CDF 9/7 (nearly orthonormal) and 1.0938 for LeGall 5/3; one 2D step by its square.
TEST(Wavelets, LiftingEnergyGainOnWhiteNoiseMatchesFilterNorms) {
  const double gain97 = 0.5 * (2 * 0.520216 + 1.965907 / 2);  // JPEG 2000 9/7 tap norms
  const double gain53 = 0.5 * (2 * 0.71875 + 1.5 / 2);  // 5/3: ‖h‖² = 23/32, ‖g‖² = 3/2
  const int w = 256, h = 256;
  const std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 8);
  const double e0 = Norm2(x);
  for (auto [f, gain] :
       {std::pair{WaveletFilter::kCdf97, gain97}, std::pair{WaveletFilter::kLeGall53, gain53}}) {
    std::vector<float> y = x;
    ForwardWavelet2D(f, y.data(), w, h, 1);
    EXPECT_NEAR(Norm2(y) / e0, gain * gain, 0.01) << Name(f);
  }
}

// ---- constants, deltas, closed forms ---------------------------------------------------------

// A constant has no detail: Haar details are exactly zero, D4 to round-off, 5/3 and 9/7 (two and
// four vanishing moments, symmetric extension keeps constants constant) to 1e-6. The low part is
// the constant times 2^(k/2) per 1D step of length > 1.
TEST(Wavelets, ConstantHasOnlyScalingCoefficients) {
  const float c = 0.75f;
  for (WaveletFilter f : kAllFilters) {
    for (auto [w, h] : Sizes2D(f)) {
      for (int k = 0; k <= WaveletMaxDepth2D(f, w, h); ++k) {
        std::vector<float> x(static_cast<std::size_t>(w) * h, c);
        ForwardWavelet2D(f, x.data(), w, h, k);
        double gain = 1;
        for (int t = 1; t <= k; ++t) {
          if (SizeAtDepth(w, t - 1) > 1) gain *= std::numbers::sqrt2;
          if (SizeAtDepth(h, t - 1) > 1) gain *= std::numbers::sqrt2;
        }
        const int wk = SizeAtDepth(w, k), hk = SizeAtDepth(h, k);
        for (int y = 0; y < h; ++y) {
          for (int xx = 0; xx < w; ++xx) {
            const float v = x[static_cast<std::size_t>(y) * w + xx];
            if (xx < wk && y < hk) {
              ASSERT_NEAR(v / (c * gain), 1.0, 1e-6) << Name(f) << " " << w << "x" << h;
            } else if (f == WaveletFilter::kHaar) {
              ASSERT_EQ(v, 0.0f) << w << "x" << h << " k=" << k;
            } else {
              const double tol = f == WaveletFilter::kDaubechies4 ? 1e-12 : 1e-6;
              ASSERT_LE(std::abs(v), tol * c * gain) << Name(f) << " " << w << "x" << h;
            }
          }
        }
      }
    }
  }
}

// 1D: 5/3 and 9/7 details of a constant vanish for every length, odd ones included.
TEST(Wavelets, LiftingConstant1D) {
  for (WaveletFilter f : kLiftingFilters) {
    for (int n : Lengths1D(f)) {
      const int k = WaveletMaxDepth(f, n);
      std::vector<float> x(static_cast<std::size_t>(n), -2.0f);
      ForwardWavelet1D(f, x.data(), n, k);
      EXPECT_NEAR(x[0], -2.0 * std::pow(std::numbers::sqrt2, k), 1e-5) << Name(f) << " n=" << n;
      for (int i = 1; i < n; ++i) EXPECT_LE(std::abs(x[i]), 1e-6) << Name(f) << " n=" << n;
    }
  }
}

// A linear ramp: 5/3 and 9/7 details vanish away from the boundary (two and four vanishing
// moments), where symmetric extension turns the ramp into a tent.
TEST(Wavelets, LiftingDetailsOfRampVanishInInterior) {
  for (WaveletFilter f : kLiftingFilters) {
    const int n = 40;
    std::vector<float> x(n);
    for (int i = 0; i < n; ++i) x[i] = 0.25f * static_cast<float>(i) - 3.0f;
    ForwardWavelet1D(f, x.data(), n, 1);
    for (int j = 2; j < n / 2 - 2; ++j) EXPECT_LE(std::abs(x[n / 2 + j]), 1e-5) << Name(f) << j;
    EXPECT_GT(std::abs(x[n - 1]), 1e-3) << "boundary detail of the folded ramp";
  }
}

// Orthonormal normalisation: the Haar scaling coefficient of an n×n face is sum / n.
TEST(Wavelets, HaarScalingCoefficientIsSumOverN) {
  for (int n : {1, 2, 8, 32, 64}) {
    std::vector<float> x = RandomSignal(static_cast<std::size_t>(n) * n, 3u + n);
    double sum = 0;
    for (float v : x) sum += v;
    ForwardHaarFace(x.data(), n, WaveletMaxDepth2D(WaveletFilter::kHaar, n, n));
    EXPECT_NEAR(x[0], sum / n, 1e-6 * std::max(1.0, std::abs(sum / n))) << n;
  }
}

// A delta at texel (px, py): exactly one coefficient per band and level is non-zero, with
// magnitude 1/side of its support (orthonormal Haar functions are ±1/side on their square), plus
// the scaling coefficient 1/n; the sign is + on the delta's quadrant (left/top halves positive).
TEST(Wavelets, HaarDeltaClosedForm) {
  const int n = 16, depth = 4;
  for (auto [px, py] : {std::pair{0, 0}, std::pair{5, 11}, std::pair{15, 15}, std::pair{8, 3}}) {
    std::vector<float> x(static_cast<std::size_t>(n) * n, 0.0f);
    x[static_cast<std::size_t>(py) * n + px] = 1.0f;
    ForwardHaarFace(x.data(), n, depth);
    int nonzero = 0;
    for (int y = 0; y < n; ++y) {
      for (int xx = 0; xx < n; ++xx) {
        const float v = x[static_cast<std::size_t>(y) * n + xx];
        const HaarSupport s = HaarCoefficientSupport(n, depth, xx, y);
        const bool covers = px >= s.x0 && px < s.x0 + s.side && py >= s.y0 && py < s.y0 + s.side;
        if (!covers) {
          EXPECT_EQ(v, 0.0f);
          continue;
        }
        ++nonzero;
        const CoefficientClass c = CoefficientClass2D(n, n, depth, xx, y);
        const bool left = px < s.x0 + s.side / 2, top = py < s.y0 + s.side / 2;
        double sign = 1;
        if (c.band == WaveletBand::kHL || c.band == WaveletBand::kHH) sign *= left ? 1 : -1;
        if (c.band == WaveletBand::kLH || c.band == WaveletBand::kHH) sign *= top ? 1 : -1;
        EXPECT_NEAR(v, sign / s.side, 1e-7) << xx << "," << y;
      }
    }
    EXPECT_EQ(nonzero, 1 + 3 * depth);
  }
}

// A Haar basis function (inverse transform of a unit coefficient) lives exactly on the support
// HaarCoefficientSupport reports, with constant magnitude 1/side there.
TEST(Wavelets, HaarBasisFunctionsLiveOnTheirSupport) {
  const int n = 8;
  for (int depth = 0; depth <= 3; ++depth) {
    for (int c = 0; c < n * n; ++c) {
      std::vector<float> x(static_cast<std::size_t>(n) * n, 0.0f);
      x[c] = 1.0f;
      InverseHaarFace(x.data(), n, depth);
      const HaarSupport s = HaarCoefficientSupport(n, depth, c % n, c / n);
      for (int y = 0; y < n; ++y) {
        for (int xx = 0; xx < n; ++xx) {
          const bool in = xx >= s.x0 && xx < s.x0 + s.side && y >= s.y0 && y < s.y0 + s.side;
          const float v = x[static_cast<std::size_t>(y) * n + xx];
          if (in) {
            ASSERT_NEAR(std::abs(v), 1.0 / s.side, 1e-7) << depth << " " << c;
          } else {
            ASSERT_EQ(v, 0.0f) << depth << " " << c;
          }
        }
      }
    }
  }
}

// ---- brute-force references for the lifting filters -----------------------------------------

// Whole-sample symmetric extension: …, x2, x1 | x0, x1, …, x(n−1) | x(n−2), …
int Mirror(int i, int n) {
  if (n == 1) return 0;
  const int period = 2 * n - 2;
  i %= period;
  if (i < 0) i += period;
  return i > n - 1 ? period - i : i;
}

// One step by direct convolution with the JPEG 2000 analysis filters (Part 1, Annex F tables),
// low band times √2 and high band over √2.
std::vector<double> ReferenceStep(WaveletFilter f, const std::vector<float>& x) {
  const int n = static_cast<int>(x.size());
  std::vector<double> lo, hi;  // taps for offsets 0, ±1, ±2, …
  if (f == WaveletFilter::kLeGall53) {
    lo = {0.75, 0.25, -0.125};
    hi = {1.0, -0.5};
  } else {
    lo = {0.602949018236358, 0.266864118442872, -0.078223266528988, -0.016864118442875,
          0.026748757410810};
    hi = {1.115087052456994, -0.591271763114247, -0.057543526228500, 0.091271763114249};
  }
  const int ns = (n + 1) / 2, nd = n / 2;
  std::vector<double> y(static_cast<std::size_t>(n));
  if (n == 1) {
    y[0] = x[0];
    return y;
  }
  auto filter = [&](const std::vector<double>& taps, int centre) {
    double s = taps[0] * x[Mirror(centre, n)];
    for (int k = 1; k < static_cast<int>(taps.size()); ++k) {
      s += taps[k] * (x[Mirror(centre - k, n)] + x[Mirror(centre + k, n)]);
    }
    return s;
  };
  for (int j = 0; j < ns; ++j) y[j] = std::numbers::sqrt2 * filter(lo, 2 * j);
  for (int j = 0; j < nd; ++j) y[ns + j] = filter(hi, 2 * j + 1) / std::numbers::sqrt2;
  return y;
}

TEST(Wavelets, LiftingMatchesDirectConvolutionWithSymmetricExtension) {
  for (WaveletFilter f : kLiftingFilters) {
    for (int n : {1, 2, 3, 4, 5, 6, 7, 8, 9, 17, 100}) {
      const std::vector<float> x = RandomSignal(static_cast<std::size_t>(n), 70u + n);
      const std::vector<double> want = ReferenceStep(f, x);
      std::vector<float> got = x;
      if (n > 1) ForwardWavelet1D(f, got.data(), n, 1);
      for (int i = 0; i < n; ++i) EXPECT_NEAR(got[i], want[i], 2e-6) << Name(f) << " n=" << n;
    }
  }
}

// The 2D step is the 1D step on every row, then on every column.
TEST(Wavelets, TwoDimensionalStepIsSeparable) {
  for (WaveletFilter f : kLiftingFilters) {
    for (auto [w, h] : {std::pair{5, 7}, std::pair{6, 3}, std::pair{1, 4}, std::pair{9, 1}}) {
      const std::vector<float> x = RandomSignal(static_cast<std::size_t>(w) * h, 9u + w);
      std::vector<float> want = x;
      if (w > 1) {
        for (int y = 0; y < h; ++y) ForwardWavelet1D(f, want.data() + y * w, w, 1);
      }
      if (h > 1) {
        std::vector<float> col(static_cast<std::size_t>(h));
        for (int xx = 0; xx < w; ++xx) {
          for (int y = 0; y < h; ++y) col[y] = want[y * w + xx];
          ForwardWavelet1D(f, col.data(), h, 1);
          for (int y = 0; y < h; ++y) want[y * w + xx] = col[y];
        }
      }
      std::vector<float> got = x;
      ForwardWavelet2D(f, got.data(), w, h, 1);
      EXPECT_LE(RelativeError(got, want), 1e-6) << Name(f) << " " << w << "x" << h;
    }
  }
}

// D4 one step against Σ_k h_k x[(2j+k) mod n] and the Haar step against (x0 ± x1)/√2.
TEST(Wavelets, D4AndHaarMatchTheirFilters) {
  const double r3 = std::numbers::sqrt3, d = 4 * std::numbers::sqrt2;
  const double h[4] = {(1 + r3) / d, (3 + r3) / d, (3 - r3) / d, (1 - r3) / d};
  const double g[4] = {h[3], -h[2], h[1], -h[0]};
  const int n = 16;
  const std::vector<float> x = RandomSignal(n, 1);
  std::vector<float> y = x;
  ForwardWavelet1D(WaveletFilter::kDaubechies4, y.data(), n, 1);
  for (int j = 0; j < n / 2; ++j) {
    double a = 0, b = 0;
    for (int k = 0; k < 4; ++k) {
      a += h[k] * x[(2 * j + k) % n];
      b += g[k] * x[(2 * j + k) % n];
    }
    EXPECT_NEAR(y[j], a, 1e-6);
    EXPECT_NEAR(y[n / 2 + j], b, 1e-6);
  }
  y = x;
  ForwardWavelet1D(WaveletFilter::kHaar, y.data(), n, 1);
  for (int j = 0; j < n / 2; ++j) {
    EXPECT_NEAR(y[j], (x[2 * j] + x[2 * j + 1]) / std::numbers::sqrt2, 1e-6);
    EXPECT_NEAR(y[n / 2 + j], (x[2 * j] - x[2 * j + 1]) / std::numbers::sqrt2, 1e-6);
  }
}

// ---- sizes, levels, bands --------------------------------------------------------------------

TEST(Wavelets, MaxDepthAndStepSizes) {
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kLeGall53, 1), 0);
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kLeGall53, 2), 1);
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kLeGall53, 3), 2);
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kCdf97, 5), 3);
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kCdf97, 100), 7);
  EXPECT_EQ(WaveletMaxDepth(WaveletFilter::kHaar, 64), 6);
  EXPECT_EQ(WaveletMaxDepth2D(WaveletFilter::kCdf97, 3, 100), 7);
  EXPECT_EQ(WaveletMaxDepth2D(WaveletFilter::kDaubechies4, 32, 32), 5);
  // 100 → 50|50 → 25|25 → 13|12 → 7|6 → 4|3 → 2|2 → 1|1
  const std::vector<WaveletStep1D> s = WaveletSteps1D(100, 7);
  const int low[] = {50, 25, 13, 7, 4, 2, 1}, high[] = {50, 25, 12, 6, 3, 2, 1};
  ASSERT_EQ(s.size(), 7u);
  for (int t = 0; t < 7; ++t) {
    EXPECT_EQ(s[t].step, t + 1);
    EXPECT_EQ(s[t].low, low[t]);
    EXPECT_EQ(s[t].high, high[t]);
    EXPECT_EQ(s[t].length, s[t].low + s[t].high);
  }
  // 3×5: 3×5 → LL 2×3, HL 1×3, LH 2×2, HH 1×2; then 2×3 → 1×2 …; then 1×2 → 1×1, LH 1×1.
  const std::vector<WaveletStep2D> r = WaveletSteps2D(3, 5, 3);
  ASSERT_EQ(r.size(), 3u);
  EXPECT_EQ(r[0].low_width, 2);
  EXPECT_EQ(r[0].low_height, 3);
  EXPECT_EQ(r[0].high_width, 1);
  EXPECT_EQ(r[0].high_height, 2);
  EXPECT_EQ(r[1].width, 2);
  EXPECT_EQ(r[1].height, 3);
  EXPECT_EQ(r[2].width, 1);
  EXPECT_EQ(r[2].height, 2);
  EXPECT_EQ(r[2].high_width, 0);
  EXPECT_EQ(r[2].high_height, 1);
}

TEST(Wavelets, CoefficientLevelsByHand) {
  // Length 5, depth 3: sizes 5 → 3 → 2 → 1: [scaling, step-3 detail, step-2, step-1, step-1].
  const int want3[] = {0, 1, 2, 3, 3};
  const int want1[] = {0, 0, 0, 1, 1};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(CoefficientLevel1D(5, 3, i), want3[i]);
    EXPECT_EQ(CoefficientLevel1D(5, 1, i), want1[i]);
  }
  // Haar 4×4, full depth:
  //   0 1 2 2      LL HL HL HL
  //   1 1 2 2      LH HH HL HL
  //   2 2 2 2      LH LH HH HH
  //   2 2 2 2      LH LH HH HH
  const int level[4][4] = {{0, 1, 2, 2}, {1, 1, 2, 2}, {2, 2, 2, 2}, {2, 2, 2, 2}};
  using B = WaveletBand;
  const B band[4][4] = {{B::kLL, B::kHL, B::kHL, B::kHL},
                        {B::kLH, B::kHH, B::kHL, B::kHL},
                        {B::kLH, B::kLH, B::kHH, B::kHH},
                        {B::kLH, B::kLH, B::kHH, B::kHH}};
  for (int y = 0; y < 4; ++y) {
    for (int x = 0; x < 4; ++x) {
      const CoefficientClass c = CoefficientClass2D(4, 4, 2, x, y);
      EXPECT_EQ(c.level, level[y][x]) << x << "," << y;
      EXPECT_EQ(c.band, band[y][x]) << x << "," << y;
    }
  }
  // 3×5 at depth 2: LL at depth 2 is 1×2; (0,2) is LH of step 2 → level 1; (1,0) HL of step 2;
  // (2,0) HL of step 1 → level 2; (0,4) LH of step 1; (2,4) HH of step 1.
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 0, 1).level, 0);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 0, 2).band, WaveletBand::kLH);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 0, 2).level, 1);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 1, 0).band, WaveletBand::kHL);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 1, 0).level, 1);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 1, 2).band, WaveletBand::kHH);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 2, 0).level, 2);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 2, 0).band, WaveletBand::kHL);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 0, 4).band, WaveletBand::kLH);
  EXPECT_EQ(CoefficientClass2D(3, 5, 2, 2, 4).band, WaveletBand::kHH);
}

TEST(Wavelets, LevelMapsAgreeWithPerCoefficientLevels) {
  for (int n : {1, 2, 3, 7, 17, 100}) {
    for (int k = 0; k <= WaveletMaxDepth(WaveletFilter::kLeGall53, n); ++k) {
      std::vector<std::uint8_t> map(static_cast<std::size_t>(n), 255);
      CoefficientLevelMap1D(n, k, map.data());
      for (int i = 0; i < n; ++i) ASSERT_EQ(map[i], CoefficientLevel1D(n, k, i)) << n << " " << k;
    }
  }
  for (auto [w, h] : {std::pair{1, 1}, std::pair{3, 5}, std::pair{16, 16}, std::pair{23, 9}}) {
    for (int k = 0; k <= WaveletMaxDepth2D(WaveletFilter::kCdf97, w, h); ++k) {
      std::vector<std::uint8_t> map(static_cast<std::size_t>(w) * h, 255);
      CoefficientLevelMap2D(w, h, k, map.data());
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          ASSERT_EQ(map[y * w + x], CoefficientClass2D(w, h, k, x, y).level) << w << "x" << h;
        }
      }
    }
  }
}

// Level ℓ ≥ 1 of a depth-k 2D transform has, per band, as many coefficients as its step's band
// sizes say (the bands tile the array).
TEST(Wavelets, BandsTileTheArray) {
  const int w = 23, h = 9, k = 4;
  std::vector<int> count(static_cast<std::size_t>(k + 1) * 4, 0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const CoefficientClass c = CoefficientClass2D(w, h, k, x, y);
      ++count[c.level * 4 + static_cast<int>(c.band)];
    }
  }
  EXPECT_EQ(count[0], SizeAtDepth(w, k) * SizeAtDepth(h, k));
  for (const WaveletStep2D& s : WaveletSteps2D(w, h, k)) {
    const int level = k - s.step + 1;
    EXPECT_EQ(count[level * 4 + 1], s.high_width * s.low_height);
    EXPECT_EQ(count[level * 4 + 2], s.low_width * s.high_height);
    EXPECT_EQ(count[level * 4 + 3], s.high_width * s.high_height);
  }
}

// ---- Haar supports ---------------------------------------------------------------------------

TEST(Wavelets, HaarSupportsByHand) {
  auto eq = [](HaarSupport s, int x0, int y0, int side) {
    return s.x0 == x0 && s.y0 == y0 && s.side == side;
  };
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 0, 0), 0, 0, 4));  // scaling
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 1, 0), 0, 0, 4));  // coarsest HL
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 1, 1), 0, 0, 4));  // coarsest HH
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 2, 0), 0, 0, 2));  // finest HL, first
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 3, 1), 2, 2, 2));  // finest HL, last
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 2, 1, 3), 2, 2, 2));  // finest LH
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 1, 1, 1), 2, 2, 2));  // depth 1: scaling of 2×2
  EXPECT_TRUE(eq(HaarCoefficientSupport(4, 0, 3, 2), 3, 2, 1));  // depth 0: the texel
  EXPECT_EQ(HaarSupportTexels(64, 6, 1, 0), 4096);
  EXPECT_EQ(HaarSupportTexels(64, 6, 63, 63), 4);
}

// Per level and band, the supports tile the face: texel areas sum to n² and solid angles to the
// face's 4π/6; each support's solid angle is the sum of its texels' exact solid angles.
TEST(Wavelets, HaarSupportAreasTileTheFacePerBand) {
  for (int n : {4, 8, 16}) {
    const CubemapLayout layout(n);
    const int full = WaveletMaxDepth2D(WaveletFilter::kHaar, n, n);
    for (int depth : {full, full - 1}) {
      const std::vector<double> table = HaarSupportSolidAngles(layout, depth);
      std::vector<double> texels(static_cast<std::size_t>(depth + 1) * 4, 0.0);
      std::vector<double> solid(texels.size(), 0.0);
      for (int face = 0; face < 6; ++face) {
        for (int y = 0; y < n; ++y) {
          for (int x = 0; x < n; ++x) {
            const std::size_t index = layout.Index(face, x, y);
            const CoefficientClass c = CoefficientClass2D(n, n, depth, x, y);
            const HaarSupport s = HaarCoefficientSupport(n, depth, x, y);
            const double omega = HaarSupportSolidAngle(layout, depth, index);
            EXPECT_DOUBLE_EQ(table[index], omega);
            if (face == 2) {
              double brute = 0;
              for (int yy = s.y0; yy < s.y0 + s.side; ++yy) {
                for (int xx = s.x0; xx < s.x0 + s.side; ++xx) {
                  brute += layout.TexelSolidAngle(layout.Index(face, xx, yy));
                }
              }
              EXPECT_NEAR(omega, brute, 1e-13);
              const std::size_t slot =
                  static_cast<std::size_t>(c.level) * 4 + static_cast<std::size_t>(c.band);
              texels[slot] += static_cast<double>(HaarSupportTexels(n, depth, x, y));
              solid[slot] += omega;
            }
          }
        }
      }
      const double face_solid = 4 * std::numbers::pi / 6;
      EXPECT_DOUBLE_EQ(texels[0], n * n);
      EXPECT_NEAR(solid[0], face_solid, 1e-12);
      for (int level = 1; level <= depth; ++level) {
        for (int band = 1; band < 4; ++band) {
          EXPECT_DOUBLE_EQ(texels[level * 4 + band], n * n) << level << " " << band;
          EXPECT_NEAR(solid[level * 4 + band], face_solid, 1e-12) << level << " " << band;
        }
      }
    }
  }
}

// ---- argument checks and names ---------------------------------------------------------------

TEST(Wavelets, RejectsInvalidArguments) {
  std::vector<float> x(64, 0.0f);
  EXPECT_THROW(ForwardWavelet2D(WaveletFilter::kHaar, x.data(), 4, 8, 1), std::invalid_argument);
  EXPECT_THROW(ForwardWavelet2D(WaveletFilter::kDaubechies4, x.data(), 6, 6, 1),
               std::invalid_argument);
  EXPECT_THROW(ForwardWavelet2D(WaveletFilter::kHaar, x.data(), 8, 8, 4), std::invalid_argument);
  EXPECT_THROW(ForwardWavelet2D(WaveletFilter::kCdf97, x.data(), 8, 8, -1), std::invalid_argument);
  EXPECT_THROW(InverseWavelet2DStep(WaveletFilter::kCdf97, x.data(), 8, 8, 0),
               std::invalid_argument);
  EXPECT_THROW(ForwardWavelet1D(WaveletFilter::kHaar, x.data(), 6, 1), std::invalid_argument);
  EXPECT_THROW(ForwardWavelet1DStep(WaveletFilter::kCdf97, x.data(), 7, 4), std::invalid_argument);
  EXPECT_THROW(ForwardWavelet1D(WaveletFilter::kLeGall53, x.data(), 0, 0), std::invalid_argument);
  EXPECT_THROW(CoefficientLevel1D(5, 1, 5), std::invalid_argument);
  EXPECT_THROW(CoefficientClass2D(5, 3, 1, 0, 3), std::invalid_argument);
  EXPECT_THROW(HaarCoefficientSupport(6, 1, 0, 0), std::invalid_argument);
}

TEST(Wavelets, FilterNamesRoundTrip) {
  for (WaveletFilter f : kAllFilters) {
    WaveletFilter g = WaveletFilter::kHaar;
    ASSERT_TRUE(ParseWaveletFilter(WaveletFilterName(f), &g));
    EXPECT_EQ(g, f);
  }
  WaveletFilter g = WaveletFilter::kHaar;
  EXPECT_TRUE(ParseWaveletFilter("9/7", &g));
  EXPECT_EQ(g, WaveletFilter::kCdf97);
  EXPECT_FALSE(ParseWaveletFilter("db6", &g));
  EXPECT_EQ(g, WaveletFilter::kCdf97);
}

// Throughput, printed (run with --gtest_also_run_disabled_tests
// --gtest_filter='*WaveletThroughput*'). Forward + inverse, full depth, one thread, CPU time.
TEST(Wavelets, DISABLED_WaveletThroughput) {
  struct Case {
    WaveletFilter f;
    int w, h;
    bool cubemap;
  };
  const Case cases[] = {
      {WaveletFilter::kHaar, 32, 32, true},     {WaveletFilter::kDaubechies4, 32, 32, true},
      {WaveletFilter::kHaar, 64, 64, true},     {WaveletFilter::kLeGall53, 256, 256, false},
      {WaveletFilter::kCdf97, 256, 256, false}, {WaveletFilter::kLeGall53, 1000, 1, false}};
  for (const Case& c : cases) {
    const std::size_t size = static_cast<std::size_t>(c.w) * c.h * (c.cubemap ? 6 : 1);
    std::vector<float> x = RandomSignal(size, 1);
    const int depth = WaveletMaxDepth2D(c.f, c.w, c.h);
    const int reps = static_cast<int>(std::max<std::size_t>(20, 20'000'000 / size));
    const std::clock_t t0 = std::clock();  // CPU time: robust on a shared, loaded machine
    for (int r = 0; r < reps; ++r) {
      if (c.cubemap) {
        ForwardWaveletCubemap(c.f, x.data(), c.w, depth);
        InverseWaveletCubemap(c.f, x.data(), c.w, depth);
      } else {
        ForwardWavelet2D(c.f, x.data(), c.w, c.h, depth);
        InverseWavelet2D(c.f, x.data(), c.w, c.h, depth);
      }
    }
    const double s = static_cast<double>(std::clock() - t0) / CLOCKS_PER_SEC;
    std::printf("%-9s %s %4dx%-4d depth %d: forward+inverse %8.2f us, %6.1f Msamples/s\n",
                WaveletFilterName(c.f), c.cubemap ? "cubemap" : "2D     ", c.w, c.h, depth,
                1e6 * s / reps, 1e-6 * static_cast<double>(size) * reps / s);
  }
}

}  // namespace
}  // namespace prt
