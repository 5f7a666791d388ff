#include "worker/transport_compressor.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numbers>
#include <random>

#include "runtime/compressed_relight.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"
#include "worker/block_spill.h"
#include "worker/column_order.h"

namespace prt {
namespace {

// A synthetic diffuse transport matrix that is smooth over space: samples on a Hilbert-ordered
// bumpy sheet (mesh) and a ground grid, each with a smoothly varying normal and a soft occluder
// whose direction drifts with position. T[s][j] = Ω_j/π · max(0, n·ω_j) · V(s, ω_j).
struct Synthetic {
  SpatialDomain domain;
  std::vector<float> T;
  int n;
};

Synthetic MakeSynthetic(int n, int mesh_side, int grid_w, int grid_h) {
  Synthetic s;
  s.n = n;
  const CubemapLayout layout(n);
  const std::size_t M = layout.texel_count();
  std::vector<Vec3> pos, nrm;
  for (int i = 0; i < mesh_side; ++i)
    for (int j = 0; j < mesh_side; ++j) {
      const double u = (i + 0.5) / mesh_side, v = (j + 0.5) / mesh_side;
      pos.push_back({u, 0.2 * std::sin(3 * u) * std::cos(2 * v), v});
      nrm.push_back(Normalize(Vec3{-0.6 * std::cos(3 * u) * std::cos(2 * v), 1,
                                   0.4 * std::sin(3 * u) * std::sin(2 * v)}));
    }
  // Shuffle the mesh's file order: only the Hilbert order makes it a smooth 1D signal.
  std::vector<std::size_t> perm(pos.size());
  for (std::size_t i = 0; i < perm.size(); ++i) perm[i] = i;
  std::shuffle(perm.begin(), perm.end(), std::mt19937(3));
  std::vector<Vec3> p2, n2;
  for (std::size_t i : perm) {
    p2.push_back(pos[i]);
    n2.push_back(nrm[i]);
  }
  s.domain.segments.push_back(MeshSegment(p2));
  for (int y = 0; y < grid_h; ++y)
    for (int x = 0; x < grid_w; ++x) {
      p2.push_back({2.0 * x / grid_w - 1, 0, 2.0 * y / grid_h - 1});
      n2.push_back({0, 1, 0});
    }
  s.domain.segments.push_back(GridSegment(grid_w, grid_h));
  const std::size_t S = p2.size();
  s.T.resize(S * M);
  for (std::size_t r = 0; r < S; ++r) {
    const Vec3 occ = Normalize(Vec3{p2[r].x + 0.3, 0.8, p2[r].z - 0.2});
    for (std::size_t j = 0; j < M; ++j) {
      const Vec3 w = layout.TexelCenter(j);
      const double cosine = std::max(0.0, Dot(n2[r], w));
      const double vis = 1.0 / (1.0 + std::exp(12.0 * (Dot(w, occ) - 0.7)));
      s.T[r * M + j] =
          static_cast<float>(layout.TexelSolidAngle(j) / std::numbers::pi * cosine * vis);
    }
  }
  return s;
}

std::vector<float> RandomLighting(std::size_t M, int channels, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<float> L(M * channels);
  for (float& v : L) v = std::uniform_real_distribution<float>(0, 1)(rng);
  L[M / 3] = 400.0f;  // a small bright sun
  return L;
}

std::vector<double> DenseProduct(const std::vector<float>& T, std::size_t S, std::size_t M,
                                 const std::vector<float>& L, int channels) {
  std::vector<double> B(S * channels);
  for (int c = 0; c < channels; ++c)
    for (std::size_t s = 0; s < S; ++s) {
      double a = 0;
      for (std::size_t j = 0; j < M; ++j) a += static_cast<double>(T[s * M + j]) * L[c * M + j];
      B[c * S + s] = a;
    }
  return B;
}

double RelRms(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    num += (a[i] - b[i]) * (a[i] - b[i]);
    den += b[i] * b[i];
  }
  return std::sqrt(num / den);
}

double RelFrobenius(const std::vector<float>& a, const std::vector<float>& b) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double d = static_cast<double>(a[i]) - b[i];
    num += d * d;
    den += static_cast<double>(b[i]) * b[i];
  }
  return std::sqrt(num / den);
}

// No truncation and 16 bits: the round trip reproduces T to quantisation error. Each stored
// coefficient is off by at most Δ_j/2 = m_j/(2A) (a dropped one by less than Δ_j), so the
// coefficient-domain error energy is at most Σ_terms Δ_j²; the transforms are (near-)orthonormal.
TEST(TransportCompressor, NoTruncationAt16BitsReproducesTToQuantisationError) {
  const Synthetic syn = MakeSynthetic(4, 9, 8, 6);
  const std::size_t S = syn.domain.sample_count(), M = 6 * 16;
  for (CompressionScheme scheme :
       {CompressionScheme::k2D, CompressionScheme::k4D, CompressionScheme::kAdaptive4D}) {
    for (RowWavelet rw : {RowWavelet::kHaar, RowWavelet::kD4}) {
      CompressionOptions o;
      o.scheme = scheme;
      o.row_wavelet = rw;
      o.bits = 16;
      o.keep_fraction = 1.0;
      std::vector<ColumnStats> stats;
      const CompressedTransport ct = CompressTransport(syn.T.data(), 4, syn.domain, o, &stats);
      const std::vector<float> back = DecompressTransport(ct);
      double bound = 0, err = 0;
      for (const auto& c : ct.columns) {
        const double delta = static_cast<double>(c.scale) / QuantiserMax(o.bits);
        bound += delta * delta * static_cast<double>(S);
      }
      for (std::size_t i = 0; i < S * M; ++i) {
        const double d = static_cast<double>(back[i]) - syn.T[i];
        err += d * d;
      }
      EXPECT_LE(err, 2.0 * bound) << ToString(scheme);
      EXPECT_LT(RelFrobenius(back, syn.T), 2e-4) << ToString(scheme);
    }
  }
}

// A 3-channel T (rows channel-major, row c·V + v; issue #22) over PerChannelDomain: at 16 bits
// with no truncation it comes back to quantisation error, and no column transform mixes two
// channels: with channels 1 and 2 zero, their rows decode to exactly zero (a transform across
// the channel boundary would spread channel 0's energy into them).
TEST(TransportCompressor, ThreeChannelTransportKeepsItsChannelsApart) {
  const Synthetic syn = MakeSynthetic(4, 9, 8, 6);
  const std::size_t V = syn.domain.sample_count(), M = 6 * 16;
  const SpatialDomain domain = PerChannelDomain(syn.domain, 3);
  ASSERT_EQ(domain.sample_count(), 3 * V);
  for (CompressionScheme scheme : {CompressionScheme::k2D, CompressionScheme::kAdaptive4D}) {
    CompressionOptions o;
    o.scheme = scheme;
    o.bits = 16;
    o.keep_fraction = 1.0;
    const CompressedTransportHeader h = MakeCompressedHeader(o, 4, domain, 3);
    EXPECT_EQ(h.channels, 3u);
    EXPECT_EQ(h.sample_count, 3 * V);
    // Channel c: T scaled by (1, 0.6, 0.3) plus a channel-dependent ripple.
    std::vector<float> T(3 * V * M);
    for (std::size_t c = 0; c < 3; ++c)
      for (std::size_t v = 0; v < V; ++v)
        for (std::size_t j = 0; j < M; ++j)
          T[(c * V + v) * M + j] = static_cast<float>(
              (1.0 - 0.35 * static_cast<double>(c)) * syn.T[v * M + j] +
              0.01 * static_cast<double>(c) * std::sin(0.3 * static_cast<double>(v + 7 * j)));
    const CompressedTransport ct = CompressTransport(T.data(), h, o);
    EXPECT_EQ(ct.header.channels, 3u);
    EXPECT_LT(RelFrobenius(DecompressTransport(ct), T), 2e-4) << ToString(scheme);
    std::vector<float> only_red(T.size(), 0.0f);
    std::copy(T.begin(), T.begin() + static_cast<std::ptrdiff_t>(V * M), only_red.begin());
    const std::vector<float> back = DecompressTransport(CompressTransport(only_red.data(), h, o));
    EXPECT_LT(RelFrobenius(back, only_red), 2e-4) << ToString(scheme);
    EXPECT_TRUE(std::all_of(back.begin() + static_cast<std::ptrdiff_t>(V * M), back.end(),
                            [](float x) { return x == 0.0f; }))
        << ToString(scheme) << ": channel 0's energy reached channels 1 and 2";
  }
  CompressionOptions o;
  EXPECT_THROW(MakeCompressedHeader(o, 4, syn.domain, 3), InputError);  // V rows, 3 channels
  EXPECT_THROW(MakeCompressedHeader(o, 4, domain, 2), InputError);
}

// Eq. 8 relighting from the compressed columns equals the dense decompressed T times L.
TEST(TransportCompressor, Equation8RelightingEqualsDenseDecompressedProduct) {
  const Synthetic syn = MakeSynthetic(8, 12, 16, 10);
  const std::size_t S = syn.domain.sample_count(), M = 6 * 64;
  for (CompressionScheme scheme :
       {CompressionScheme::k2D, CompressionScheme::k4D, CompressionScheme::kAdaptive4D}) {
    CompressionOptions o;
    o.scheme = scheme;
    o.keep_fraction = 0.08;
    o.row_wavelet = RowWavelet::kD4;
    o.column_wavelet = ColumnWavelet::kCdf97;
    const CompressedTransport ct = CompressTransport(syn.T.data(), 8, syn.domain, o);
    const std::vector<float> dense = DecompressTransport(ct);
    const int channels = 3;
    const std::vector<float> L = RandomLighting(M, channels, 5);
    const std::vector<double> ref = DenseProduct(dense, S, M, L, channels);
    const std::vector<float> Lhat = LightingToRowWaveletBasis(o.row_wavelet, 8, L, channels);
    CompressedRelighter relighter(ct);
    std::vector<float> B(S * channels);
    relighter.Relight(Lhat, channels, B);
    EXPECT_LT(RelRms(std::vector<double>(B.begin(), B.end()), ref), 1e-5) << ToString(scheme);
  }
}

// On a smooth T, adaptive 4D reaches the 2D baseline's relit error with fewer stored terms.
TEST(TransportCompressor, Adaptive4DUsesFewerTermsThan2DAtEqualError) {
  const Synthetic syn = MakeSynthetic(8, 16, 24, 16);
  const std::size_t S = syn.domain.sample_count(), M = 6 * 64;
  const std::vector<float> L = RandomLighting(M, 1, 9);
  const std::vector<double> ref = DenseProduct(syn.T, S, M, L, 1);
  auto measure = [&](CompressionScheme scheme, double keep, std::size_t* terms) {
    CompressionOptions o;
    o.scheme = scheme;
    o.keep_fraction = keep;
    const CompressedTransport ct = CompressTransport(syn.T.data(), 8, syn.domain, o);
    *terms = ct.term_count();
    CompressedRelighter relighter(ct);
    std::vector<float> B(S);
    relighter.Relight(LightingToRowWaveletBasis(o.row_wavelet, 8, L, 1), 1, B);
    return RelRms(std::vector<double>(B.begin(), B.end()), ref);
  };
  std::size_t terms_2d = 0;
  const double err_2d = measure(CompressionScheme::k2D, 0.05, &terms_2d);
  std::size_t best_terms = SIZE_MAX;
  for (double keep : {0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05}) {
    std::size_t t = 0;
    const double e = measure(CompressionScheme::kAdaptive4D, keep, &t);
    std::printf("adaptive keep %.3f: terms %zu error %.5f (2D: %zu, %.5f)\n", keep, t, e, terms_2d,
                err_2d);
    if (e <= err_2d) best_terms = std::min(best_terms, t);
  }
  EXPECT_LT(best_terms, terms_2d / 2) << "2D error " << err_2d;
}

// The out-of-core path (row blocks → BlockTransposer with a tiny budget → column blocks) gives
// the in-memory compressor's result byte for byte.
TEST(TransportCompressor, OutOfCorePathWithSpillingIsByteIdentical) {
  const Synthetic syn = MakeSynthetic(4, 10, 9, 7);
  const std::size_t S = syn.domain.sample_count(), M = 6 * 16;
  CompressionOptions o;
  o.keep_fraction = 0.1;
  const CompressedTransport mem = CompressTransport(syn.T.data(), 4, syn.domain, o);
  CompressedTransport ooc;
  ooc.header = MakeCompressedHeader(o, 4, syn.domain);
  BlockSpillOptions so;
  so.memory_budget_bytes = 2048;
  so.columns_per_block = 7;
  so.spill_dir = std::filesystem::temp_directory_path().string();
  BlockTransposer tr(S, 0, static_cast<uint32_t>(M), so);
  for (std::size_t r0 = 0; r0 < S; r0 += 13) {
    const std::size_t cnt = std::min<std::size_t>(13, S - r0);
    std::vector<float> rows(syn.T.begin() + r0 * M, syn.T.begin() + (r0 + cnt) * M);
    PrepareRows(ooc.header, o, rows.data(), cnt);
    tr.AddRows(r0, cnt, rows.data(), M);
  }
  EXPECT_GT(tr.runs_spilled(), 3u);
  uint32_t first, count;
  std::vector<float> cols;
  while (tr.NextColumnBlock(first, count, cols))
    for (auto& c : CompressColumnBlock(ooc.header, first, count, cols.data()))
      ooc.columns.push_back(std::move(c));
  EXPECT_EQ(EncodeCompressedTransport(mem), EncodeCompressedTransport(ooc));
  // And the encoding round-trips to the same relit radiance, bit for bit.
  const CompressedTransport dec = DecodeCompressedTransport(EncodeCompressedTransport(mem), "m");
  const std::vector<float> Lhat =
      LightingToRowWaveletBasis(o.row_wavelet, 4, RandomLighting(M, 1, 2), 1);
  std::vector<float> b1(S), b2(S);
  CompressedRelighter(mem).Relight(Lhat, 1, b1);
  CompressedRelighter(dec).Relight(Lhat, 1, b2);
  EXPECT_EQ(b1, b2);
}

TEST(TransportCompressor, GlobalThresholdIsTheKthLargestMagnitude) {
  const std::vector<float> c = {0.5f, -3.0f, 0.0f, 2.0f, -1.0f, 0.25f};
  EXPECT_EQ(GlobalThreshold(c.data(), c.size(), 1), 3.0f);
  EXPECT_EQ(GlobalThreshold(c.data(), c.size(), 3), 1.0f);
  EXPECT_EQ(GlobalThreshold(c.data(), c.size(), 10), 0.25f);
  EXPECT_EQ(GlobalThreshold(c.data(), 3, 0), std::numeric_limits<float>::infinity());
}

// The histogram threshold: the lower edge of the bin where the count from the top reaches keep;
// values sharing that bin are all kept; histograms of parts add to the histogram of the whole.
TEST(TransportCompressor, HistogramThresholdKeepsWholeBinsAndAddsOverParts) {
  const std::vector<float> c = {0.5f, -3.0f, 0.0f, 2.0f, -1.0f, 0.25f, 3.01f};
  std::vector<uint64_t> hist(kMagnitudeBins, 0), part(kMagnitudeBins, 0);
  AddMagnitudeHistogram(c.data(), c.size(), hist.data());
  EXPECT_EQ(ThresholdFromHistogram(hist.data(), 1), 3.0f);  // 3.01 and 3 share a bin: 2 kept
  EXPECT_EQ(ThresholdFromHistogram(hist.data(), 3), 2.0f);
  EXPECT_EQ(ThresholdFromHistogram(hist.data(), 4), 1.0f);
  EXPECT_EQ(ThresholdFromHistogram(hist.data(), 6), 0.25f);
  // More than the non-zeros: every non-zero is kept (the smallest positive float).
  EXPECT_EQ(ThresholdFromHistogram(hist.data(), 100), std::numeric_limits<float>::denorm_min());
  AddMagnitudeHistogram(c.data(), 3, part.data());
  AddMagnitudeHistogram(c.data() + 3, c.size() - 3, part.data());
  EXPECT_EQ(part, hist);
  CompressedTransportHeader h;
  h.cubemap_n = 8;
  h.sample_count = 1000;
  h.keep_fraction = 0.01;
  EXPECT_EQ(GlobalTermBudget(h), 3840u);  // 0.01 · 1000 · 384
}

// The global budget keeps the keep·S·M largest transformed coefficients: as many terms as the
// per-column budget (before zeros drop), a smaller error of T for 4D, and relighting that still
// agrees with the dense decompressed matrix.
TEST(TransportCompressor, GlobalBudgetKeepsTheRequestedTermsAndLowersTheError) {
  const Synthetic syn = MakeSynthetic(8, 12, 16, 10);
  const std::size_t S = syn.domain.sample_count(), M = 6 * 64;
  for (CompressionScheme scheme : {CompressionScheme::k2D, CompressionScheme::kAdaptive4D}) {
    CompressionOptions o;
    o.scheme = scheme;
    o.keep_fraction = 1.0 / 32;  // 12 terms per row exactly: both budgets keep S·M/32 terms
    o.bits = 16;
    std::vector<ColumnStats> col_stats, glob_stats;
    const CompressedTransport per = CompressTransport(syn.T.data(), 8, syn.domain, o, &col_stats);
    o.budget = CompressionBudget::kGlobal;
    const CompressedTransport glob = CompressTransport(syn.T.data(), 8, syn.domain, o, &glob_stats);
    EXPECT_EQ(glob.header.budget, CompressionBudget::kGlobal);
    std::size_t kept = 0;
    for (const auto& st : glob_stats) kept += st.kept_terms;
    // At least the budget, at most one histogram bin (2^-7 of the magnitude) more.
    EXPECT_GE(static_cast<double>(kept), static_cast<double>(S * M) / 32);
    EXPECT_LE(static_cast<double>(kept), static_cast<double>(S * M) / 32 * 1.05);
    const double e_per = RelFrobenius(DecompressTransport(per), syn.T);
    const double e_glob = RelFrobenius(DecompressTransport(glob), syn.T);
    EXPECT_LT(e_glob, e_per) << ToString(scheme);
    const std::vector<float> L = RandomLighting(M, 1, 4);
    const std::vector<double> ref = DenseProduct(DecompressTransport(glob), S, M, L, 1);
    std::vector<float> B(S);
    CompressedRelighter(glob).Relight(LightingToRowWaveletBasis(o.row_wavelet, 8, L, 1), 1, B);
    EXPECT_LT(RelRms(std::vector<double>(B.begin(), B.end()), ref), 1e-5);
  }
}

TEST(TransportCompressor, OptionsFromSceneSettingsAreValidated) {
  CompressionSettings s;
  const CompressionOptions o = CompressionOptionsFrom(s, "scene.toml");
  EXPECT_EQ(o.scheme, CompressionScheme::kAdaptive4D);
  EXPECT_EQ(o.bits, 9);
  s.bits = 40;
  EXPECT_THROW(CompressionOptionsFrom(s, "scene.toml"), InputError);
  s.bits = 9;
  s.column_wavelet = "haar";
  EXPECT_THROW(CompressionOptionsFrom(s, "scene.toml"), InputError);
  s.column_wavelet = "legall53";
  EXPECT_EQ(o.budget, CompressionBudget::kGlobal);  // the scene files' default
  s.budget = "column";
  EXPECT_EQ(CompressionOptionsFrom(s, "scene.toml").budget, CompressionBudget::kColumn);
  s.budget = "row";
  EXPECT_THROW(CompressionOptionsFrom(s, "scene.toml"), InputError);
  CompressionOptions b;
  b.keep_fraction = 0.05;
  EXPECT_EQ(ColumnTermBudget(b, 1000), 50u);
  EXPECT_EQ(RowTermBudget(b, 6144), 307u);
  b.terms_per_column = 12;
  EXPECT_EQ(ColumnTermBudget(b, 1000), 12u);
}

}  // namespace
}  // namespace prt
