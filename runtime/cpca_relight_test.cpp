// CPCA relighting (Overbeck et al. 2006 §6.3): Eq. 7–8 equal the product of the decoded rows
// with the lighting, for exact and sparse (NWA) lighting, one and three channels; Eq. 10's
// incremental step 2 reaches the exact image under static lighting; BlendDelta of every entry
// equals Blend.
#include "runtime/cpca_relight.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "formats/cpca_transport.h"
#include "worker/cpca.h"
#include "worker/transport_compressor.h"

namespace prt {
namespace {

struct Fixture {
  CpcaTransport t;
  std::vector<float> decoded;  // rows × 6n², what t decodes to
};

// Smooth random rows in 3 groups (so that clusters matter), n = 4 (96 coefficients).
Fixture Make(std::size_t samples, uint32_t channels, uint32_t K, uint32_t S, double keep) {
  const int n = 4;
  const std::size_t d = 96, rows = samples * channels;
  std::mt19937 rng(17);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> base(3 * d), dir(3 * 4 * d);
  for (float& x : base) x = 3 * g(rng);
  for (float& x : dir) x = g(rng);
  std::vector<float> X(rows * d);
  for (std::size_t r = 0; r < rows; ++r) {
    const std::size_t k = (r / 7) % 3;
    for (std::size_t j = 0; j < d; ++j) X[r * d + j] = base[k * d + j];
    for (int i = 0; i < 4; ++i) {
      const float a = g(rng);
      for (std::size_t j = 0; j < d; ++j) X[r * d + j] += a * dir[(k * 4 + i) * d + j];
    }
  }
  SpatialDomain domain;
  SpatialSegment seg;
  seg.count = static_cast<uint32_t>(samples);
  domain.segments.push_back(seg);
  CompressionOptions o;
  o.scheme = CompressionScheme::kCpca;
  o.cpca_clusters = K;
  o.cpca_bases = S;
  o.bits = 12;
  o.keep_fraction = keep;
  o.cpca_coefficient_bits = 14;
  const CompressedTransportHeader h =
      MakeCompressedHeader(o, n, PerChannelDomain(domain, channels), channels);
  Fixture f;
  f.t = CompressCpca(X.data(), h, CpcaOptionsFrom(h));
  f.decoded.resize(rows * d);
  for (std::size_t r = 0; r < rows; ++r)
    DecodeCpcaRow(f.t, r, std::span<float>(f.decoded.data() + r * d, d));
  return f;
}

std::vector<LightingTerm> RandomTerms(std::size_t d, std::size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<LightingTerm> terms;
  for (std::size_t j = 0; j < d; ++j)
    if (count >= d || rng() % d < count)
      terms.push_back({static_cast<uint32_t>(j), {u(rng), u(rng), u(rng)}});
  return terms;
}

void ExpectNear(const SampleRadiance& a, const SampleRadiance& b, double tol) {
  ASSERT_EQ(a.size(), b.size());
  double scale = 0;
  for (int c = 0; c < 3; ++c)
    for (double v : b.channel[c]) scale = std::max(scale, std::fabs(v));
  for (int c = 0; c < 3; ++c)
    for (std::size_t s = 0; s < a.size(); ++s)
      EXPECT_NEAR(a.channel[c][s], b.channel[c][s], tol * scale) << c << " " << s;
}

TEST(CpcaRelight, EqualsTheDecodedRowsTimesTheLighting) {
  for (uint32_t channels : {1u, 3u}) {
    const Fixture f = Make(60, channels, 4, 3, 0.5);
    const CpcaRelighter relighter(f.t);
    const DenseTransport dense(f.decoded, 60, 96, channels);
    EXPECT_EQ(relighter.sample_count(), 60u);
    for (std::size_t count : {96u, 10u}) {  // exact lighting, a 10-term approximation
      const std::vector<LightingTerm> terms = RandomTerms(96, count, 3);
      ExpectNear(relighter.Apply(terms), dense.Apply(terms), 1e-5);
      SampleRadiance acc = dense.Apply(terms);
      relighter.Accumulate(terms, acc);  // adds: twice the image
      SampleRadiance twice = dense.Apply(terms);
      twice += dense.Apply(terms);
      ExpectNear(acc, twice, 1e-5);
    }
  }
}

TEST(CpcaRelight, BlendDeltaOfEveryEntryEqualsBlend) {
  const Fixture f = Make(40, 1, 3, 4, 1.0);
  const CpcaRelighter relighter(f.t);
  const std::vector<LightingTerm> terms = RandomTerms(96, 96, 5);
  const SampleRadiance P = relighter.projection().Apply(terms);
  SampleRadiance full;
  relighter.Blend(P, full);
  SampleRadiance inc(40);
  std::vector<uint32_t> k;
  std::vector<std::array<double, 3>> delta;
  for (std::size_t e = 0; e < P.size(); ++e) {
    k.push_back(static_cast<uint32_t>(e));
    delta.push_back({P.channel[0][e], P.channel[1][e], P.channel[2][e]});
  }
  relighter.BlendDelta(k, delta, inc);
  ExpectNear(inc, full, 1e-12);
}

WaveletLighting RandomLighting(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  WaveletLighting l;
  l.n = n;
  for (auto& c : l.coefficient) {
    c.resize(static_cast<std::size_t>(6 * n * n));
    for (double& v : c) v = u(rng) * u(rng);
  }
  return l;
}

TEST(CpcaRelight, IncrementalReachesTheExactImageUnderStaticLighting) {
  const Fixture f = Make(80, 1, 3, 8, 1.0);
  const CpcaRelighter relighter(f.t);
  CpcaIncrementalRelighter inc(relighter, 4, 12);  // N = 12 lighting terms, S/4 = 2 basis terms
  EXPECT_EQ(inc.basis_terms(), 2u);
  inc.Initialize(RandomLighting(4, 1));
  const WaveletLighting l = RandomLighting(4, 2);
  const SampleRadiance exact = relighter.Apply(ExactLightingTerms(l));
  ExpectNear(inc.Radiance(), relighter.Apply(ExactLightingTerms(RandomLighting(4, 1))), 1e-9);
  // Step 1 converges in ⌈96 / 12⌉ = 8 frames, step 2 in ⌈8 / 2⌉ = 4 more at most.
  double last_error = 1e300;
  int frames = 0;
  for (; frames < 12; ++frames) {
    const IncrementalFrame fr = inc.Update(l);
    double e = 0;
    for (int c = 0; c < 3; ++c)
      for (std::size_t s = 0; s < 80; ++s)
        e += std::pow(inc.Radiance().channel[c][s] - exact.channel[c][s], 2);
    EXPECT_LE(e, last_error * (1 + 1e-9) + 1e-24) << frames;
    last_error = e;
    if (fr.exact) break;
  }
  EXPECT_LT(frames, 12);
  ExpectNear(inc.Radiance(), exact, 1e-9);
}

}  // namespace
}  // namespace prt
