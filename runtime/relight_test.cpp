// Transport operators against brute-force products: dense and sparse rows, partial blocks,
// duplicates, the orthonormal-basis identity T·L = T̂·L̂, the B = 1 convention, albedo.
#include "runtime/relight.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "formats/column_coding.h"
#include "formats/compressed_transport.h"
#include "runtime/compressed_relight.h"
#include "runtime/error_test_support.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"
#include "vocabulary/wavelets.h"

namespace prt {
namespace {

std::vector<float> RandomMatrix(std::size_t rows, std::size_t cols, double density, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::bernoulli_distribution keep(density);
  std::vector<float> m(rows * cols);
  for (float& v : m) v = keep(rng) ? u(rng) : 0.0f;
  return m;
}

std::vector<LightingTerm> RandomTerms(std::size_t count, std::size_t cols, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<uint32_t> idx(0, static_cast<uint32_t>(cols - 1));
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  std::vector<LightingTerm> terms(count);
  for (auto& t : terms) t = {idx(rng), {u(rng), u(rng), u(rng)}};
  return terms;
}

SampleRadiance BruteForce(const std::vector<float>& m, std::size_t rows, std::size_t cols,
                          const std::vector<LightingTerm>& terms) {
  SampleRadiance out(rows);
  for (std::size_t s = 0; s < rows; ++s) {
    for (const auto& t : terms) {
      for (int c = 0; c < 3; ++c) out.channel[c][s] += double(m[s * cols + t.index]) * t.value[c];
    }
  }
  return out;
}

void ToCsr(const std::vector<float>& m, std::size_t rows, std::size_t cols,
           std::vector<uint64_t>& offsets, std::vector<uint32_t>& idx, std::vector<float>& val) {
  offsets.assign(1, 0);
  for (std::size_t s = 0; s < rows; ++s) {
    for (std::size_t j = 0; j < cols; ++j) {
      if (m[s * cols + j] != 0.0f) {
        idx.push_back(static_cast<uint32_t>(j));
        val.push_back(m[s * cols + j]);
      }
    }
    offsets.push_back(idx.size());
  }
}

void ExpectNear(const SampleRadiance& a, const SampleRadiance& b, double tol) {
  ASSERT_EQ(a.size(), b.size());
  for (int c = 0; c < 3; ++c) {
    for (std::size_t s = 0; s < a.size(); ++s) {
      ASSERT_NEAR(a.channel[c][s], b.channel[c][s], tol) << "channel " << c << " sample " << s;
    }
  }
}

TEST(RelightTest, DenseAndSparseMatchBruteForceWithPartialBlocks) {
  const std::size_t rows = 1500, cols = 384;  // 1500 = 5·256 + 220 = 1024 + 476
  const auto m = RandomMatrix(rows, cols, 0.2, 1);
  auto terms = RandomTerms(60, cols, 2);
  terms.push_back(terms[3]);  // a repeated index adds
  const SampleRadiance ref = BruteForce(m, rows, cols, terms);

  const DenseTransport dense(m, rows, cols);
  ExpectNear(dense.Apply(terms), ref, 1e-12);

  std::vector<uint64_t> off;
  std::vector<uint32_t> idx;
  std::vector<float> val;
  ToCsr(m, rows, cols, off, idx, val);
  const SparseTransport sparse(off, idx, val, cols);
  EXPECT_EQ(sparse.nonzero_count(), val.size());
  ExpectNear(sparse.Apply(terms), ref, 1e-12);

  // Accumulate adds to what is there.
  SampleRadiance twice = dense.Apply(terms);
  sparse.Accumulate(terms, twice);
  for (int c = 0; c < 3; ++c) {
    for (std::size_t s = 0; s < rows; ++s) {
      ASSERT_NEAR(twice.channel[c][s], 2.0 * ref.channel[c][s], 1e-12);
    }
  }
}

// With 3 colour channels (rows channel-major: row c·samples + s), channel c of sample s is
// Σ_k T[c·samples + s][k]·L_c[k]: the dense and sparse operators against brute force.
TEST(RelightTest, ThreeChannelDenseAndSparseLightEachChannelFromItsRows) {
  const std::size_t samples = 700, cols = 96;  // 700 = 2·256 + 188 = 1024 − 324
  const auto m = RandomMatrix(3 * samples, cols, 0.3, 5);
  const auto terms = RandomTerms(40, cols, 6);
  SampleRadiance ref(samples);
  for (int c = 0; c < 3; ++c)
    for (std::size_t s = 0; s < samples; ++s)
      for (const auto& t : terms)
        ref.channel[c][s] += double(m[(c * samples + s) * cols + t.index]) * t.value[c];
  const DenseTransport dense(m, samples, cols, 3);
  EXPECT_EQ(dense.sample_count(), samples);
  EXPECT_EQ(dense.channels(), 3u);
  ExpectNear(dense.Apply(terms), ref, 1e-12);
  std::vector<uint64_t> off;
  std::vector<uint32_t> idx;
  std::vector<float> val;
  ToCsr(m, 3 * samples, cols, off, idx, val);
  const SparseTransport sparse(off, idx, val, cols, 3);
  EXPECT_EQ(sparse.sample_count(), samples);
  ExpectNear(sparse.Apply(terms), ref, 1e-12);
  // Not the one-channel reading of the same rows.
  const DenseTransport first(std::span<const float>(m).first(samples * cols), samples, cols);
  EXPECT_GT(std::abs(first.Apply(terms).channel[2][5] - ref.channel[2][5]), 1e-6);
  EXPECT_THROW(DenseTransport(m, samples, cols, 2), std::invalid_argument);
  EXPECT_THROW(DenseTransport(m, samples + 1, cols, 3), std::invalid_argument);
  std::vector<uint64_t> short_off(off.begin(), off.end() - 1);
  short_off.back() = off[off.size() - 2];
  std::vector<uint32_t> short_idx(idx.begin(), idx.begin() + std::ptrdiff_t(short_off.back()));
  std::vector<float> short_val(val.begin(), val.begin() + std::ptrdiff_t(short_off.back()));
  EXPECT_THROW(SparseTransport(short_off, short_idx, short_val, cols, 3), std::invalid_argument);
  EXPECT_THROW(SparseTransport(off, idx, val, cols, 0), std::invalid_argument);
}

TEST(RelightTest, RejectsBadInput) {
  const auto m = RandomMatrix(4, 6, 1.0, 3);
  const DenseTransport dense(m, 4, 6);
  SampleRadiance out(4);
  const std::vector<LightingTerm> bad = {{6, {1, 1, 1}}};
  EXPECT_THROW(dense.Accumulate(bad, out), std::out_of_range);
  SampleRadiance wrong(3);
  EXPECT_THROW(dense.Accumulate({}, wrong), std::invalid_argument);
  EXPECT_THROW(DenseTransport(m, 4, 5), std::invalid_argument);
  std::vector<float> nan = m;
  nan[7] = std::nanf("");
  EXPECT_THROW(DenseTransport(nan, 4, 6), std::invalid_argument);
  const std::vector<uint64_t> off = {0, 1};
  const std::vector<uint32_t> idx = {9};
  const std::vector<float> val = {1.0f};
  EXPECT_THROW(SparseTransport(off, idx, val, 6), std::invalid_argument);
}

// T·L over texels equals T̂·L̂ over Haar coefficients (orthonormal transform), and a white
// unoccluded diffuse sample under a uniform environment of radiance 1 gets B = 1 (DESIGN.md).
TEST(RelightTest, HaarBasisPreservesProductAndUniformEnvironmentGivesOne) {
  const int n = 16;
  const CubemapLayout layout(n);
  const std::size_t m = layout.texel_count();
  const std::vector<Vec3> normals = {{0, 1, 0}, {0, 0, -1}, Normalize(Vec3{1, -2, 0.5})};
  std::vector<float> rows(normals.size() * m);
  for (std::size_t s = 0; s < normals.size(); ++s) {
    for (std::size_t j = 0; j < m; ++j) {
      // Exact-ish texel integral: 4×4 sub-samples of the cosine, times the exact solid angle.
      double sum = 0.0;
      for (int a = 0; a < 4; ++a) {
        for (int b = 0; b < 4; ++b) {
          sum +=
              std::max(0.0, Dot(normals[s], layout.TexelDirection(j, (a + .5) / 4, (b + .5) / 4)));
        }
      }
      rows[s * m + j] = static_cast<float>(layout.TexelSolidAngle(j) * sum / 16 / std::numbers::pi);
    }
  }
  // A smooth non-uniform environment in texel space.
  CubemapRgb env;
  env.n = n;
  for (int c = 0; c < 3; ++c) {
    env.Channel(c).resize(m);
    for (std::size_t j = 0; j < m; ++j) {
      const Vec3 d = layout.TexelCenter(j);
      env.Channel(c)[j] = static_cast<float>(1.0 + 0.5 * d.x + 0.25 * c * d.y * d.y);
    }
  }
  std::vector<double> texel_space(normals.size() * 3, 0.0);
  for (std::size_t s = 0; s < normals.size(); ++s) {
    for (int c = 0; c < 3; ++c) {
      for (std::size_t j = 0; j < m; ++j)
        texel_space[3 * s + c] += rows[s * m + j] * env.Channel(c)[j];
    }
  }
  std::vector<float> haar_rows = rows;
  for (std::size_t s = 0; s < normals.size(); ++s)
    ForwardHaarCubemap(haar_rows.data() + s * m, n, 4);
  const DenseTransport t(haar_rows, normals.size(), m);
  const SampleRadiance b = t.Apply(ExactLightingTerms(ProjectLighting(env)));
  for (std::size_t s = 0; s < normals.size(); ++s) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(b.channel[c][s], texel_space[3 * s + c], 1e-5);
  }
  // Uniform radiance 1: ∫ max(0, n·ω)/π dω = 1 (to the sub-sampling accuracy).
  CubemapRgb one;
  one.n = n;
  for (int c = 0; c < 3; ++c) one.Channel(c).assign(m, 1.0f);
  const SampleRadiance u = t.Apply(ExactLightingTerms(ProjectLighting(one)));
  for (std::size_t s = 0; s < normals.size(); ++s) EXPECT_NEAR(u.channel[1][s], 1.0, 2e-3);
}

TEST(RelightTest, ShadeSamplesAppliesAlbedo) {
  SampleRadiance r(2);
  r.channel[0] = {1.0, 2.0};
  r.channel[1] = {0.5, 3.0};
  r.channel[2] = {4.0, 1.0};
  const std::vector<Rgb> albedo = {{0.5f, 1.0f, 0.25f}, {1.0f, 1.0f, 1.0f}};
  const auto rgb = ShadeSamples(r, albedo);
  EXPECT_EQ(rgb, (std::vector<float>{0.5f, 0.5f, 1.0f, 2.0f, 3.0f, 1.0f}));
  const std::vector<Rgb> uniform = {{2.0f, 2.0f, 2.0f}};
  EXPECT_EQ(ShadeSamples(r, uniform)[0], 2.0f);
  EXPECT_EQ(ShadeSamples(r, {})[2], 4.0f);
  const std::vector<Rgb> three(3);
  EXPECT_THROW(ShadeSamples(r, three), std::invalid_argument);
}

// No silent zeroing (docs/viewer.md, "NaN and Inf"): a NaN radiance, and a finite radiance whose
// shaded colour does not fit in float (finite T and L with T·L = 1e39, summed in double), are
// errors naming the source and the sample (by its name when the caller gives names), never a
// black sample.
TEST(RelightTest, ShadeSamplesRefusesWhatIsNotAFiniteFloat) {
  SampleRadiance r(3);
  r.channel[0] = {1.0, 2.0, 3.0};
  r.channel[1] = {0.5, std::nan(""), 1.0};
  r.channel[2] = {4.0, 1.0, 1.0};
  const auto message = [&](const std::vector<Rgb>& albedo, std::span<const uint32_t> names) {
    try {
      ShadeSamples(r, albedo, "scene.prtpack", names);
    } catch (const NumericalError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_EQ(message({}, {}),
            "scene.prtpack: the shaded radiance of sample 1 (channel 1): T·L is NaN");
  const std::vector<uint32_t> names = {7, 8, 9};
  EXPECT_NE(message({}, names).find("sample 8 (channel 1)"), std::string::npos);
  // Finite T and L whose product overflows float: a dense operator sums T·L in double.
  const std::vector<float> rows = {1e30f, 1e30f, 1e30f, 1e30f};  // 2 samples × 2 coefficients
  const DenseTransport dense(rows, 2, 2);
  const std::vector<LightingTerm> light = {{0, {1e9, 1.0, 1.0}}, {1, {1e9, 1.0, 1.0}}};
  const SampleRadiance big = dense.Apply(light);
  ASSERT_TRUE(std::isfinite(big.channel[0][0]));
  EXPECT_NEAR(big.channel[0][0], 2e39, 1e33);
  try {
    ShadeSamples(big, {}, "scene.prtpack");
    FAIL() << "2e39 became a float";
  } catch (const NumericalError& e) {
    EXPECT_EQ(std::string(e.what()),
              "scene.prtpack: the shaded radiance of sample 0 (channel 0), albedo 1 × T·L 2e+39, "
              "is outside the float range (3.4e38); the lighting is too bright");
  }
  // The albedo may bring it back into range (0.5 × 2e39 is still too bright; 1e-10 × 2e39 is
  // not): the check is on the colour written.
  EXPECT_THROW(ShadeSamples(big, std::vector<Rgb>{{0.5f, 0.5f, 0.5f}}), NumericalError);
  const std::vector<float> dim = ShadeSamples(big, std::vector<Rgb>{{1e-10f, 1.0f, 1.0f}});
  EXPECT_NEAR(dim[0], 2e29f, 1e23f);
}

// An empty compressed transport over n = 2 and one mesh of 19 samples in a permuted order.
CompressedTransport NineteenSampleTransport() {
  CompressedTransport t;
  t.header.cubemap_n = 2;
  t.header.sample_count = 19;
  t.header.bits = 9;
  SpatialSegment seg;
  seg.kind = SpatialSegment::Kind::kMesh1D;
  seg.count = 19;
  for (uint32_t k = 0; k < 19; ++k) seg.order.push_back((7 * k + 3) % 19);
  t.header.domain.segments = {seg};
  return t;
}

// The compressed 4D path plugs in through CompressedTransportOperator: it relights like the
// dense matrix its columns decompress to. Columns are built by hand (random depths, quantised
// values, a permuted mesh order), so no compressor is needed here.
TEST(RelightTest, CompressedOperatorMatchesItsDecompressedMatrix) {
  CompressedTransport t = NineteenSampleTransport();
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> q(-255, 255), depth(0, 5);
  std::bernoulli_distribution keep(0.4);
  for (uint32_t col = 0; col < 24; ++col) {
    if (col % 5 == 4) continue;  // some columns absent (all zero)
    CompressedColumn c;
    c.column = col;
    c.depth = static_cast<uint8_t>(depth(rng));
    c.scale = 0.5f + 0.1f * static_cast<float>(col);
    for (uint32_t i = 0; i < 19; ++i) {
      const int v = q(rng);
      if (v != 0 && keep(rng)) {
        c.index.push_back(i);
        c.q.push_back(v);
      }
    }
    if (!c.index.empty()) t.columns.push_back(c);
  }
  const CompressedRelighter relighter(t);
  const CompressedTransportOperator op(relighter);
  ASSERT_EQ(op.sample_count(), 19u);
  ASSERT_EQ(op.coefficient_count(), 24u);
  const DenseTransport dense(DecompressToRowWaveletBasis(t), 19, 24);
  const auto terms = RandomTerms(12, 24, 4);
  const SampleRadiance a = op.Apply(terms), b = dense.Apply(terms);
  double scale = 0.0;
  for (int c = 0; c < 3; ++c) {
    for (double v : b.channel[c]) scale = std::max(scale, std::abs(v));
  }
  ASSERT_GT(scale, 0.0);
  ExpectNear(a, b, 1e-5 * scale);
  // Assign overwrites whatever the buffer held (and sizes it); the dense operator's default
  // Assign does the same.
  SampleRadiance assigned(19);
  for (auto& ch : assigned.channel) std::fill(ch.begin(), ch.end(), 1e30);
  op.Assign(terms, assigned);
  ExpectNear(assigned, b, 1e-5 * scale);
  SampleRadiance sized;
  dense.Assign(terms, sized);
  ExpectNear(sized, b, 1e-5 * scale);
  op.Assign({}, assigned);
  for (const auto& ch : assigned.channel)
    for (double v : ch) EXPECT_EQ(v, 0.0);
  // In the coefficient order, sample s sits at coefficient_of_sample()[s].
  const CompressedTransportOperator lay(relighter, SampleOrder::kCoefficients);
  const SampleRadiance l = lay.Apply(terms);
  for (int c = 0; c < 3; ++c)
    for (std::size_t v = 0; v < 19; ++v)
      EXPECT_EQ(l.channel[c][relighter.coefficient_of_sample()[v]], a.channel[c][v]);
}

// A 3-channel compressed transport (57 rows: 3 channels × 19 samples) through the operator: 19
// samples, channel c lit from rows 19c … 19c + 18, like the 3-channel dense matrix it
// decompresses to, in both sample orders.
TEST(RelightTest, ThreeChannelCompressedOperatorMatchesItsDecompressedMatrix) {
  CompressedTransport t = NineteenSampleTransport();
  t.header.domain = PerChannelDomain(t.header.domain, 3);
  t.header.sample_count = 57;
  t.header.channels = 3;
  std::mt19937 rng(10);
  std::uniform_int_distribution<int> q(-255, 255), depth(0, 5);
  std::bernoulli_distribution keep(0.4);
  for (uint32_t col = 0; col < 24; ++col) {
    if (col % 5 == 4) continue;
    CompressedColumn c;
    c.column = col;
    c.depth = static_cast<uint8_t>(depth(rng));
    c.scale = 0.5f + 0.1f * static_cast<float>(col);
    for (uint32_t i = 0; i < 57; ++i) {
      const int v = q(rng);
      if (v != 0 && keep(rng)) {
        c.index.push_back(i);
        c.q.push_back(v);
      }
    }
    if (!c.index.empty()) t.columns.push_back(c);
  }
  const CompressedRelighter relighter(t);
  const CompressedTransportOperator op(relighter);
  ASSERT_EQ(op.sample_count(), 19u);
  const DenseTransport dense(DecompressToRowWaveletBasis(t), 19, 24, 3);
  const auto terms = RandomTerms(12, 24, 7);
  const SampleRadiance a = op.Apply(terms), b = dense.Apply(terms);
  double scale = 0.0;
  for (int c = 0; c < 3; ++c)
    for (double v : b.channel[c]) scale = std::max(scale, std::abs(v));
  ASSERT_GT(scale, 0.0);
  ExpectNear(a, b, 1e-5 * scale);
  SampleRadiance assigned(19);
  for (auto& ch : assigned.channel) std::fill(ch.begin(), ch.end(), 1e30);
  op.Assign(terms, assigned);
  ExpectNear(assigned, b, 1e-5 * scale);
  const CompressedTransportOperator lay(relighter, SampleOrder::kCoefficients);
  const SampleRadiance l = lay.Apply(terms);
  for (int c = 0; c < 3; ++c)
    for (std::size_t v = 0; v < 19; ++v)
      EXPECT_EQ(l.channel[c][relighter.coefficient_of_sample()[v]], a.channel[c][v]);
}

// The compressed path takes its lighting and accumulates in float (Eq. 8's X): a lighting value
// past the float range, an X that overflows, and a term that dequantises past it are errors
// naming the transport (the pack) and the coefficient or sample; nothing comes back as 0 or Inf.
TEST(RelightTest, CompressedPathRefusesOverflowNamingTheTransport) {
  CompressedTransport t = NineteenSampleTransport();
  CompressedColumn c;  // T = 1e30 (within dither and 9 bits) at every sample, depth 0
  c.column = 0;
  c.depth = 0;
  c.scale = 1e30f;
  for (uint32_t i = 0; i < 19; ++i) {
    c.index.push_back(i);
    c.q.push_back(QuantiserMax(9));
  }
  t.columns.push_back(c);
  const CompressedRelighter relighter(t, "scene.prtpack");
  EXPECT_EQ(relighter.name(), "scene.prtpack");
  const CompressedTransportOperator op(relighter);
  const SampleRadiance fine = op.Apply(std::vector<LightingTerm>{{0, {1.0, 2.0, 0.5}}});
  for (const auto& ch : fine.channel)
    for (double v : ch) EXPECT_TRUE(std::isfinite(v) && v > 4e29 && v < 3e30) << v;
  const auto message = [](const auto& f) { return testing::NumericalErrorOf(f); };
  // A lighting value past the float range (a double the float weights cannot hold).
  const std::string past = message([&] {
    op.Apply(std::vector<LightingTerm>{{0, {1.0, 1e39, 1.0}}});
  });
  EXPECT_EQ(past,
            "scene.prtpack: lighting coefficient 0 (channel 1) is 1e+39, outside the float range "
            "of the relighter; the environment is too bright");
  // Finite T (1e30) and L (1e10) whose product overflows X: named by sample, in either order.
  const std::vector<LightingTerm> bright = {{0, {1e10, 1.0, 1.0}}};
  EXPECT_EQ(message([&] { op.Apply(bright); }),
            "scene.prtpack: the relit radiance of sample 0 (channel 0) is Inf: T·L overflows the "
            "relighter's float range (3.4e38); the lighting is too bright for this transport");
  const CompressedTransportOperator lay(relighter, SampleOrder::kCoefficients);
  // Position 0 of the coefficient order holds the segment's order[0] = sample 3.
  EXPECT_NE(message([&] { lay.Apply(bright); }).find("of sample 3 (channel 0) is Inf"),
            std::string::npos);
  SampleRadiance acc = fine;
  EXPECT_NE(message([&] { op.Accumulate(bright, acc); }).find("is Inf"), std::string::npos);
  // The dense Eq. 8 path (float output) too.
  std::vector<float> lighting(3 * 24, 0.0f), radiance(3 * 19);
  lighting[0] = 1e10f;
  EXPECT_NE(message([&] { relighter.Relight(lighting, 3, radiance); }).find("is Inf"),
            std::string::npos);
  // A scale within 0.4 % of FLT_MAX dequantises past the float range at a negative dither.
  t.columns[0].scale = std::numeric_limits<float>::max();
  try {
    const CompressedRelighter too_big(t, "scene.prtpack");
    FAIL() << "a term past the float range was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("scene.prtpack: column 0: the term of sample"),
              std::string::npos)
        << e.what();
  }
}

// Measurement, not an assertion on time: throughput of the dense and sparse operators on 4096
// samples × 1536 columns (n = 16), for a 30-term update and an exact (all-column) product.
TEST(RelightTest, ReportsThroughput) {
  const std::size_t rows = 4096, cols = 1536;
  const auto m = RandomMatrix(rows, cols, 1.0, 5);
  const DenseTransport dense(m, rows, cols);
  std::vector<uint64_t> off;
  std::vector<uint32_t> idx;
  std::vector<float> val;
  const auto sparse_m = RandomMatrix(rows, cols, 0.1, 6);
  ToCsr(sparse_m, rows, cols, off, idx, val);
  const SparseTransport sparse(off, idx, val, cols);
  const auto few = RandomTerms(30, cols, 7);
  std::vector<LightingTerm> all(cols);
  for (std::size_t j = 0; j < cols; ++j) all[j] = {static_cast<uint32_t>(j), {1.0, 0.5, 0.25}};
  const auto time = [](const TransportOperator& op, const std::vector<LightingTerm>& terms) {
    SampleRadiance out(op.sample_count());
    op.Accumulate(terms, out);  // warm up
    const int reps = terms.size() > 100 ? 3 : 50;
    const auto t0 = std::chrono::steady_clock::now();
    for (int r = 0; r < reps; ++r) op.Accumulate(terms, out);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return s / reps;
  };
  const double d30 = time(dense, few), dall = time(dense, all);
  const double s30 = time(sparse, few), sall = time(sparse, all);
  std::printf("dense  4096×1536: 30 terms %.3f ms, all %.1f ms (%.2f G term·samples/s)\n",
              d30 * 1e3, dall * 1e3, rows * cols / dall * 1e-9);
  std::printf("sparse 10%% of 4096×1536: 30 terms %.3f ms, all %.1f ms (%.2f G nonzeros/s)\n",
              s30 * 1e3, sall * 1e3, double(val.size()) / sall * 1e-9);
  // One PBI frame (30 terms) against one NWA frame (selection + 30-term product) on the dense
  // operator: the per-band bookkeeping and the band sum are PBI's overhead (§5.3).
  const HaarLightingBasis basis(16);
  WaveletLighting l;
  l.n = 16;
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (auto& c : l.coefficient) {
    c.resize(cols);
    for (double& v : c) v = u(rng);
  }
  PerBandIncrementalRelighter pbi(dense, 16, 30);
  pbi.Initialize(l);
  const int frames = 20;
  const auto t0 = std::chrono::steady_clock::now();
  for (int f = 0; f < frames; ++f) {
    for (auto& c : l.coefficient) {
      for (double& v : c) v += 0.01 * u(rng);  // every coefficient moves: the full budget is spent
    }
    EXPECT_EQ(pbi.Update(l).terms, 30u);
    pbi.Radiance();
  }
  const auto t1 = std::chrono::steady_clock::now();
  for (int f = 0; f < frames; ++f) dense.Apply(NonlinearLightingApproximation(l, basis, 30));
  const auto t2 = std::chrono::steady_clock::now();
  std::printf("4096 samples, n = 16, 30 terms: PBI frame %.3f ms, NWA frame %.3f ms\n",
              std::chrono::duration<double, std::milli>(t1 - t0).count() / frames,
              std::chrono::duration<double, std::milli>(t2 - t1).count() / frames);
  EXPECT_GT(dall, 0.0);
}

}  // namespace
}  // namespace prt
