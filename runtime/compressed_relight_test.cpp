#include "runtime/compressed_relight.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

namespace prt {
namespace {

// A shuffled mesh segment of `mesh_count` samples followed by a width×height grid.
SpatialDomain TwoSegmentDomain(uint32_t mesh_count = 45, uint32_t width = 9, uint32_t height = 6,
                               unsigned shuffle_seed = 11) {
  SpatialDomain d;
  SpatialSegment mesh;
  mesh.kind = SpatialSegment::Kind::kMesh1D;
  mesh.count = mesh_count;
  mesh.order.resize(mesh_count);
  std::iota(mesh.order.begin(), mesh.order.end(), 0u);
  std::shuffle(mesh.order.begin(), mesh.order.end(), std::mt19937(shuffle_seed));
  SpatialSegment grid;
  grid.kind = SpatialSegment::Kind::kGrid2D;
  grid.width = width;
  grid.height = height;
  grid.count = width * height;
  d.segments = {mesh, grid};
  return d;
}

double RelErr(const std::vector<double>& got, const std::vector<double>& want) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    num += (got[i] - want[i]) * (got[i] - want[i]);
    den += want[i] * want[i];
  }
  return std::sqrt(num / std::max(den, 1e-300));
}

// B = T̂ · L̂ per channel in double: ref[ch·S + s] = Σ_j That[s·M + j] · Lhat[ch·M + j].
std::vector<double> DenseProduct(const std::vector<float>& That, const std::vector<float>& Lhat,
                                 std::size_t S, std::size_t M, int channels) {
  std::vector<double> ref(S * static_cast<std::size_t>(channels));
  for (std::size_t ch = 0; ch < static_cast<std::size_t>(channels); ++ch)
    for (std::size_t s = 0; s < S; ++s) {
      double a = 0;
      for (std::size_t j = 0; j < M; ++j)
        a += static_cast<double>(That[s * M + j]) * Lhat[ch * M + j];
      ref[ch * S + s] = a;
    }
  return ref;
}

TEST(ColumnTransform, ForwardInverseRoundTripAtEveryDepth) {
  const SpatialDomain d = TwoSegmentDomain();
  EXPECT_EQ(MaxColumnDepth(d), 6);  // ⌈log2 45⌉
  std::mt19937 rng(1);
  std::vector<float> x(d.sample_count());
  for (float& v : x) v = std::uniform_real_distribution<float>(-1, 1)(rng);
  for (ColumnWavelet w : {ColumnWavelet::kLeGall53, ColumnWavelet::kCdf97}) {
    for (int depth = 0; depth <= MaxColumnDepth(d); ++depth) {
      std::vector<float> y = x;
      ForwardColumnTransform(d, w, depth, y.data());
      // Single inverse steps from the deepest level equal the full inverse.
      std::vector<float> z = y;
      for (int t = depth; t >= 1; --t) InverseColumnTransformStep(d, w, t, z.data());
      std::vector<float> zs(z.size());
      CoefficientOrderToSamples(d, z.data(), zs.data());
      InverseColumnTransform(d, w, depth, y.data());
      for (std::size_t i = 0; i < x.size(); ++i) {
        EXPECT_NEAR(y[i], x[i], 2e-6) << depth;
        EXPECT_NEAR(zs[i], x[i], 2e-6) << depth;
      }
    }
  }
}

TEST(ColumnTransform, DepthZeroIsTheHilbertPermutationAndLevelsMatchWavelets) {
  const SpatialDomain d = TwoSegmentDomain();
  std::vector<float> x(d.sample_count());
  std::iota(x.begin(), x.end(), 0.0f);
  std::vector<float> y = x;
  ForwardColumnTransform(d, ColumnWavelet::kLeGall53, 0, y.data());
  for (uint32_t k = 0; k < 45; ++k) EXPECT_EQ(y[k], static_cast<float>(d.segments[0].order[k]));
  for (uint32_t k = 45; k < 99; ++k) EXPECT_EQ(y[k], static_cast<float>(k));
  std::vector<uint8_t> levels(d.sample_count());
  ColumnLevelMap(d, 6, levels.data());
  EXPECT_EQ(levels[0], 0);   // mesh scaling coefficient (1 left after 6 steps)
  EXPECT_EQ(levels[44], 6);  // finest mesh detail
  EXPECT_EQ(levels[45], 0);  // grid: clamped to its own depth ⌈log2 9⌉ = 4
  EXPECT_EQ(levels[45 + 53], 4);
  // §4.3 scaling in half-octaves: level × segment dimension (mesh 1, grid 2).
  std::vector<uint8_t> scale(d.sample_count());
  ColumnScaleMap(d, 6, scale.data());
  EXPECT_EQ(scale[44], 6);
  EXPECT_EQ(scale[45 + 53], 8);
  EXPECT_DOUBLE_EQ(ScaleFactor(8), 16.0);
  EXPECT_DOUBLE_EQ(ScaleFactor(3), 2.0 * std::sqrt(2.0));
}

TEST(Dither, OffsetsAreUniformInHalfOpenUnitIntervalAndDeterministic) {
  double sum = 0, sum2 = 0;
  const int N = 200000;
  for (int i = 0; i < N; ++i) {
    const double r = DitherOffset(7, static_cast<uint32_t>(i % 97), static_cast<uint32_t>(i));
    ASSERT_GE(r, -0.5);
    ASSERT_LT(r, 0.5);
    sum += r;
    sum2 += r * r;
  }
  EXPECT_NEAR(sum / N, 0.0, 0.005);
  EXPECT_NEAR(sum2 / N, 1.0 / 12.0, 0.002);
  EXPECT_EQ(DitherOffset(7, 3, 4), DitherOffset(7, 3, 4));
  EXPECT_NE(DitherOffset(7, 3, 4), DitherOffset(8, 3, 4));
}

// Random compressed columns at random depths: Eq. 8 relighting against the dense decompressed
// matrix times the lighting, and T̂·L̂ against T·L (orthonormal row transform).
TEST(CompressedRelighter, Equation8MatchesDenseProductForEveryWaveletPair) {
  for (RowWavelet rw : {RowWavelet::kHaar, RowWavelet::kD4}) {
    for (ColumnWavelet cw : {ColumnWavelet::kLeGall53, ColumnWavelet::kCdf97}) {
      CompressedTransport t;
      t.header.cubemap_n = 4;
      t.header.row_wavelet = rw;
      t.header.column_wavelet = cw;
      t.header.bits = 11;
      t.header.domain = TwoSegmentDomain();
      t.header.sample_count = static_cast<uint32_t>(t.header.domain.sample_count());
      std::mt19937 rng(static_cast<unsigned>(rw) * 2 + static_cast<unsigned>(cw));
      const int maxd = MaxColumnDepth(t.header.domain);
      for (uint32_t j = 0; j < t.header.column_count(); ++j) {
        if (rng() % 5 == 0) continue;
        CompressedColumn c;
        c.column = j;
        c.depth = static_cast<uint8_t>(rng() % (maxd + 1));
        c.scale = std::uniform_real_distribution<float>(0.1f, 2.0f)(rng);
        for (uint32_t i = 0; i < t.header.sample_count; ++i) {
          if (rng() % 4) continue;
          c.index.push_back(i);
          const int32_t q = static_cast<int32_t>(rng() % 2001) - 1000;
          c.q.push_back(q == 0 ? 1 : q);
        }
        if (c.index.empty()) continue;
        t.columns.push_back(c);
      }
      const std::size_t S = t.header.sample_count, M = t.header.column_count();
      const int channels = 3;
      std::vector<float> L(M * channels);
      for (float& v : L) v = std::uniform_real_distribution<float>(0, 1)(rng);
      const std::vector<float> Lhat = LightingToRowWaveletBasis(rw, 4, L, channels);
      const std::vector<float> That = DecompressToRowWaveletBasis(t);
      const std::vector<float> T = DecompressTransport(t);
      std::vector<double> ref(S * channels), ref_texel(S * channels);
      for (int ch = 0; ch < channels; ++ch)
        for (std::size_t s = 0; s < S; ++s) {
          double a = 0, b = 0;
          for (std::size_t j = 0; j < M; ++j) {
            a += static_cast<double>(That[s * M + j]) * Lhat[ch * M + j];
            b += static_cast<double>(T[s * M + j]) * L[ch * M + j];
          }
          ref[ch * S + s] = a;
          ref_texel[ch * S + s] = b;
        }
      EXPECT_LT(RelErr(ref_texel, ref), 1e-5);
      CompressedRelighter relighter(t);
      std::vector<float> B(S * channels);
      relighter.Relight(Lhat, channels, B);
      std::vector<double> Bd(B.begin(), B.end());
      EXPECT_LT(RelErr(Bd, ref), 1e-5) << ToString(rw) << " " << ToString(cw);
      // Sparse lighting: the first 20 columns only.
      std::vector<uint32_t> cols(20);
      std::iota(cols.begin(), cols.end(), 0u);
      std::vector<float> w(20 * channels), Lsparse(M * channels, 0.0f);
      for (uint32_t k = 0; k < 20; ++k)
        for (int ch = 0; ch < channels; ++ch) {
          w[k * channels + ch] = Lhat[ch * M + k];
          Lsparse[ch * M + k] = Lhat[ch * M + k];
        }
      std::vector<float> Bs(S * channels), Bs_ref(S * channels);
      relighter.RelightSparse(cols, w, channels, Bs);
      relighter.Relight(Lsparse, channels, Bs_ref);
      for (std::size_t i = 0; i < Bs.size(); ++i) EXPECT_NEAR(Bs[i], Bs_ref[i], 1e-5);
    }
  }
}

// Columns of t (its header set): column j at depth j mod (maximum + 1), storing coefficient i
// where stored(j, i), each with a random non-zero quantised value; columns storing nothing are
// left out.
template <class Stored>
void AddColumns(CompressedTransport& t, std::mt19937& rng, Stored stored) {
  const uint32_t S = t.header.sample_count;
  const auto M = static_cast<uint32_t>(t.header.column_count());
  const int maxd = MaxColumnDepth(t.header.domain);
  for (uint32_t j = 0; j < M; ++j) {
    CompressedColumn c;
    c.column = j;
    c.depth = static_cast<uint8_t>(j % static_cast<uint32_t>(maxd + 1));
    c.scale = 1.0f;
    for (uint32_t i = 0; i < S; ++i) {
      if (!stored(j, i)) continue;
      c.index.push_back(i);
      const int32_t q = static_cast<int32_t>(rng() % 2001) - 1000;
      c.q.push_back(q == 0 ? 1 : q);
    }
    if (!c.index.empty()) t.columns.push_back(c);
  }
}

// A transport at n = 2 (24 columns), 11 bits, on TwoSegmentDomain(mesh_count, 67, 61, 5): column
// j has depth j mod (maximum + 1) and stores coefficient i where stored(j, i), with a random
// non-zero quantised value (no column where it stores nothing).
// With `channels` = 3, the rows of 3 colour channels over 3 copies of that domain.
template <class Stored>
CompressedTransport TiledTransport(uint32_t mesh_count, std::mt19937& rng, Stored stored,
                                   uint32_t channels = 1) {
  CompressedTransport t;
  t.header.cubemap_n = 2;
  t.header.bits = 11;
  t.header.domain = PerChannelDomain(TwoSegmentDomain(mesh_count, 67, 61, 5), channels);
  t.header.channels = channels;
  t.header.sample_count = static_cast<uint32_t>(t.header.domain.sample_count());
  AddColumns(t, rng, stored);
  return t;
}

// A domain of several scatter tiles (4096 coefficients each) with columns of every depth, dense
// and sparse: every channel count (4 is X's padded width, 1 and 2 use the scalar paths), the
// sparse entry points, RelightSparseAdd and a frame with no lights against the dense product.
TEST(CompressedRelighter, ManyTilesEveryChannelCountMatchesDenseProduct) {
  std::mt19937 rng(17);
  const CompressedTransport t = TiledTransport(9001, rng, [&](uint32_t j, uint32_t) {
    if (j % 7 == 3) return false;                                  // absent columns
    const uint32_t keep = j % 3 == 0 ? 1 : (j % 3 == 1 ? 5 : 50);  // 100 %, 20 %, 2 % dense
    return rng() % keep == 0;
  });
  const std::size_t S = t.header.sample_count, M = t.header.column_count();
  ASSERT_GT(S, 3u * 4096u);
  const int maxd = MaxColumnDepth(t.header.domain);
  const std::vector<float> That = DecompressToRowWaveletBasis(t);
  const CompressedRelighter relighter(t);
  for (int channels = 1; channels <= 4; ++channels) {
    std::vector<float> Lhat(M * channels);
    for (float& v : Lhat) v = std::uniform_real_distribution<float>(-1, 1)(rng);
    const std::vector<double> ref = DenseProduct(That, Lhat, S, M, channels);
    std::vector<float> B(S * channels, -7.0f);
    relighter.Relight(Lhat, channels, B);
    EXPECT_LT(RelErr(std::vector<double>(B.begin(), B.end()), ref), 1e-5) << channels;
    // The same lights as a sparse list (every column, in reverse order) added into doubles.
    std::vector<uint32_t> cols(M);
    std::vector<float> w(M * channels);
    for (uint32_t k = 0; k < M; ++k) {
      cols[k] = static_cast<uint32_t>(M - 1 - k);
      for (int ch = 0; ch < channels; ++ch) w[k * channels + ch] = Lhat[ch * M + cols[k]];
    }
    std::vector<double> acc(S * channels, 1.0);
    std::vector<double*> out(channels);
    for (int ch = 0; ch < channels; ++ch) out[ch] = acc.data() + ch * S;
    relighter.RelightSparseAdd(cols, w, channels, out);
    for (double& v : acc) v -= 1.0;
    EXPECT_LT(RelErr(acc, ref), 1e-5) << channels;
    // Written over (assign) instead of added, in the coefficient order: position
    // coefficient_of_sample()[s] holds sample s, bit for bit the same values.
    std::vector<double> lay(S * channels, std::nan(""));
    for (int ch = 0; ch < channels; ++ch) out[ch] = lay.data() + ch * S;
    relighter.RelightSparseAdd(cols, w, channels, out, SampleOrder::kCoefficients, true);
    std::vector<double> once(S * channels, std::nan(""));
    for (int ch = 0; ch < channels; ++ch) out[ch] = once.data() + ch * S;
    relighter.RelightSparseAdd(cols, w, channels, out, SampleOrder::kSamples, true);
    EXPECT_LT(RelErr(once, ref), 1e-5) << channels;
    const std::span<const uint32_t> coef = relighter.coefficient_of_sample();
    ASSERT_EQ(coef.size(), S);
    std::size_t moved = 0, mismatched = 0;
    for (int ch = 0; ch < channels; ++ch)
      for (std::size_t s = 0; s < S; ++s) {
        moved += coef[s] != s;
        mismatched += lay[ch * S + coef[s]] != once[ch * S + s];
      }
    EXPECT_EQ(mismatched, 0u) << channels;
    EXPECT_GT(moved, S / 2);  // the mesh segment really is permuted
    std::vector<float> Blay(S * channels, -7.0f);
    relighter.Relight(Lhat, channels, Blay, SampleOrder::kCoefficients);
    mismatched = 0;
    for (int ch = 0; ch < channels; ++ch)
      for (std::size_t s = 0; s < S; ++s) mismatched += Blay[ch * S + coef[s]] != B[ch * S + s];
    EXPECT_EQ(mismatched, 0u) << channels;
    // No lights at all: zero radiance, whatever the buffers held before.
    std::vector<float> zero(S * channels, -7.0f);
    relighter.RelightSparse({}, {}, channels, zero);
    EXPECT_TRUE(std::all_of(zero.begin(), zero.end(), [](float v) { return v == 0.0f; }));
    std::fill(lay.begin(), lay.end(), std::nan(""));
    for (int ch = 0; ch < channels; ++ch) out[ch] = lay.data() + ch * S;
    relighter.RelightSparseAdd({}, {}, channels, out, SampleOrder::kCoefficients, true);
    EXPECT_TRUE(std::all_of(lay.begin(), lay.end(), [](double v) { return v == 0.0; }));
    // A few lights: of every depth the column with the fewest terms, so that the frame runs on
    // the calling thread and the low-band ("late") terms join between the inverse steps.
    std::vector<uint32_t> few;
    for (int d = 0; d <= maxd; ++d) {
      uint32_t best = UINT32_MAX;
      for (uint32_t j = 0; j < M; ++j)
        if (relighter.ColumnDepth(j) == d &&
            (best == UINT32_MAX || relighter.ColumnTermCount(j) < relighter.ColumnTermCount(best)))
          best = j;
      if (best != UINT32_MAX) few.push_back(best);
    }
    ASSERT_GE(few.size(), 10u);
    std::vector<float> wf(few.size() * channels);
    for (float& v : wf) v = std::uniform_real_distribution<float>(-1, 1)(rng);
    std::vector<double> ref_few(S * channels, 0.0);
    for (int ch = 0; ch < channels; ++ch)
      for (std::size_t s = 0; s < S; ++s)
        for (std::size_t k = 0; k < few.size(); ++k)
          ref_few[ch * S + s] += static_cast<double>(That[s * M + few[k]]) * wf[k * channels + ch];
    std::vector<float> Bf(S * channels, -7.0f);
    relighter.RelightSparse(few, wf, channels, Bf);
    EXPECT_LT(RelErr(std::vector<double>(Bf.begin(), Bf.end()), ref_few), 1e-5) << channels;
  }
}

// B_c = T̂_c·L̂_c for a 3-channel transport (rows channel-major, row c·V + v): what one relight
// of all 3·V rows with all three lighting channels gives when channel c of sample v is read
// from row c·V + v, the dense reference here.
std::vector<double> ChannelProduct(const std::vector<float>& That, const std::vector<float>& Lhat,
                                   std::size_t V, std::size_t M) {
  std::vector<double> ref(3 * V);
  for (std::size_t c = 0; c < 3; ++c)
    for (std::size_t v = 0; v < V; ++v) {
      double a = 0;
      for (std::size_t j = 0; j < M; ++j)
        a += static_cast<double>(That[(c * V + v) * M + j]) * Lhat[c * M + j];
      ref[c * V + v] = a;
    }
  return ref;
}

// A 3-channel transport (issue #22): every entry point relights channel c of sample v from row
// c·V + v with lighting channel c, against the dense product of the decompressed rows; small
// (one tile, the calling thread) and large (tiles that straddle the channel boundaries, the
// parallel scatter), with columns of every depth, dense lights, sparse lists, a few lights (the
// low-band terms between the inverse steps), both output orders, and adding or assigning.
TEST(CompressedRelighter, ThreeChannelTransportRelightsEachChannelFromItsRows) {
  std::mt19937 rng(31);
  for (uint32_t mesh_count : {40u, 9001u}) {
    const CompressedTransport t = TiledTransport(
        mesh_count, rng,
        [&](uint32_t j, uint32_t) {
          if (j % 7 == 3) return false;
          const uint32_t keep = j % 3 == 0 ? 1 : (j % 3 == 1 ? 5 : 50);
          return rng() % keep == 0;
        },
        3);
    const std::size_t V = t.header.spatial_count(), M = t.header.column_count();
    const int maxd = MaxColumnDepth(t.header.domain);
    const std::vector<float> That = DecompressToRowWaveletBasis(t);
    ASSERT_EQ(That.size(), 3 * V * M);
    const CompressedRelighter relighter(t);
    EXPECT_EQ(relighter.sample_count(), V);
    EXPECT_EQ(relighter.row_count(), 3 * V);
    EXPECT_EQ(relighter.channels(), 3u);
    const std::span<const uint32_t> coef = relighter.coefficient_of_sample();
    ASSERT_EQ(coef.size(), V);
    std::vector<float> Lhat(3 * M);
    for (float& v : Lhat) v = std::uniform_real_distribution<float>(-1, 1)(rng);
    const std::vector<double> ref = ChannelProduct(That, Lhat, V, M);
    // Not what lighting every channel's rows with one lighting channel would give.
    std::vector<float> same(3 * M);
    for (int c = 0; c < 3; ++c)
      std::copy(Lhat.begin(), Lhat.begin() + static_cast<std::ptrdiff_t>(M),
                same.begin() + static_cast<std::ptrdiff_t>(c * M));
    EXPECT_GT(RelErr(ChannelProduct(That, same, V, M), ref), 0.1);
    std::vector<float> B(3 * V, -7.0f);
    relighter.Relight(Lhat, 3, B);
    EXPECT_LT(RelErr(std::vector<double>(B.begin(), B.end()), ref), 1e-5) << mesh_count;
    std::vector<float> Blay(3 * V, -7.0f);
    relighter.Relight(Lhat, 3, Blay, SampleOrder::kCoefficients);
    std::size_t mismatched = 0;
    for (std::size_t c = 0; c < 3; ++c)
      for (std::size_t v = 0; v < V; ++v) mismatched += Blay[c * V + coef[v]] != B[c * V + v];
    EXPECT_EQ(mismatched, 0u) << mesh_count;
    // Every column as a sparse list, added into doubles and written over them.
    std::vector<uint32_t> cols(M);
    std::vector<float> w(3 * M);
    for (uint32_t k = 0; k < M; ++k) {
      cols[k] = static_cast<uint32_t>(M - 1 - k);
      for (int c = 0; c < 3; ++c) w[3 * k + c] = Lhat[c * M + cols[k]];
    }
    std::vector<double> acc(3 * V, 1.0);
    std::vector<double*> out = {acc.data(), acc.data() + V, acc.data() + 2 * V};
    relighter.RelightSparseAdd(cols, w, 3, out);
    for (double& v : acc) v -= 1.0;
    EXPECT_LT(RelErr(acc, ref), 1e-5) << mesh_count;
    std::vector<double> lay(3 * V, std::nan(""));
    out = {lay.data(), lay.data() + V, lay.data() + 2 * V};
    relighter.RelightSparseAdd(cols, w, 3, out, SampleOrder::kCoefficients, true);
    mismatched = 0;
    for (std::size_t c = 0; c < 3; ++c)
      for (std::size_t v = 0; v < V; ++v)
        mismatched +=
            std::abs(lay[c * V + coef[v]] - ref[c * V + v]) > 1e-4 * (1 + std::abs(ref[c * V + v]));
    EXPECT_EQ(mismatched, 0u) << mesh_count;
    // A few lights: every depth's smallest column.
    std::vector<uint32_t> few;
    for (int d = 0; d <= maxd; ++d) {
      uint32_t best = UINT32_MAX;
      for (uint32_t j = 0; j < M; ++j)
        if (relighter.ColumnDepth(j) == d &&
            (best == UINT32_MAX || relighter.ColumnTermCount(j) < relighter.ColumnTermCount(best)))
          best = j;
      if (best != UINT32_MAX) few.push_back(best);
    }
    ASSERT_GE(few.size(), 5u);
    std::vector<float> wf(3 * few.size());
    for (float& v : wf) v = std::uniform_real_distribution<float>(-1, 1)(rng);
    std::vector<float> Lfew(3 * M, 0.0f);
    for (std::size_t k = 0; k < few.size(); ++k)
      for (int c = 0; c < 3; ++c) Lfew[c * M + few[k]] += wf[3 * k + c];
    std::vector<float> Bf(3 * V, -7.0f);
    relighter.RelightSparse(few, wf, 3, Bf);
    EXPECT_LT(RelErr(std::vector<double>(Bf.begin(), Bf.end()), ChannelProduct(That, Lfew, V, M)),
              1e-5)
        << mesh_count;
    // One or two lighting channels cannot light three transport channels.
    std::vector<float> L1(M), B1(V);
    EXPECT_THROW(relighter.Relight(L1, 1, B1), std::invalid_argument);
    std::vector<float> w2(2 * few.size()), B2(2 * V);
    EXPECT_THROW(relighter.RelightSparse(few, w2, 2, B2), std::invalid_argument);
  }
}

// Terms piled into the first tile (as the Mallat layout piles the coarse coefficients), one in
// 64 elsewhere: the frame splits the tiles between its threads by work, so one thread gets the
// first tile alone and another the rest; every tile must still be zeroed and added exactly
// once, in every frame (the second frame finds the first one's X in the pooled buffer).
// Enough terms for the parallel path.
TEST(CompressedRelighter, TermsPiledIntoOneTileMatchDenseProduct) {
  std::mt19937 rng(23);
  const CompressedTransport t =
      TiledTransport(20000, rng, [&](uint32_t, uint32_t i) { return i < 4096 || rng() % 64 == 0; });
  const std::size_t S = t.header.sample_count, M = t.header.column_count();
  ASSERT_GT(S, 5u * 4096u);
  ASSERT_GT(M * 4096, std::size_t{1} << 15);
  const std::vector<float> That = DecompressToRowWaveletBasis(t);
  const CompressedRelighter relighter(t);
  const int channels = 3;
  for (int frame = 0; frame < 2; ++frame) {
    std::vector<float> Lhat(M * channels);
    for (float& v : Lhat) v = std::uniform_real_distribution<float>(-1, 1)(rng);
    const std::vector<double> ref = DenseProduct(That, Lhat, S, M, channels);
    std::vector<float> B(S * channels, -7.0f);
    relighter.Relight(Lhat, channels, B);
    EXPECT_LT(RelErr(std::vector<double>(B.begin(), B.end()), ref), 1e-5) << frame;
  }
}

}  // namespace
}  // namespace prt

namespace prt {
namespace {

// Two shuffled mesh segments (9001 and 2500 samples) at n = 2, columns of every depth, some
// dense, some sparse, some absent; `channels` = 3: three channels of rows.
// With `grid`, a 67×61 grid segment after them.
CompressedTransport MeshTransport(ColumnWavelet wavelet, uint32_t channels, std::mt19937& rng,
                                  bool grid) {
  SpatialDomain d;
  for (uint32_t count : {9001u, 2500u}) {
    SpatialSegment mesh;
    mesh.kind = SpatialSegment::Kind::kMesh1D;
    mesh.count = count;
    mesh.order.resize(count);
    std::iota(mesh.order.begin(), mesh.order.end(), 0u);
    std::shuffle(mesh.order.begin(), mesh.order.end(), rng);
    d.segments.push_back(mesh);
  }
  if (grid) {
    SpatialSegment g;
    g.kind = SpatialSegment::Kind::kGrid2D;
    g.width = 67;
    g.height = 61;
    g.count = 67 * 61;
    d.segments.push_back(g);
  }
  CompressedTransport t;
  t.header.cubemap_n = 2;
  t.header.bits = 11;
  t.header.column_wavelet = wavelet;
  t.header.domain = PerChannelDomain(d, channels);
  t.header.channels = channels;
  t.header.sample_count = static_cast<uint32_t>(t.header.domain.sample_count());
  AddColumns(t, rng, [&](uint32_t j, uint32_t) {
    if (j % 7 == 3) return false;  // absent columns
    const uint32_t keep = j % 3 == 0 ? 1 : (j % 3 == 1 ? 5 : 50);
    return rng() % keep == 0;
  });
  return t;
}

// RelightSparseAddRange's region of interest (the windows of the inverse steps, the terms that
// reach them) against the whole frame in the coefficient order: ranges of every size (one
// position, ranges straddling segments, a whole segment; in a grid part rows and bands of
// rows), meshes alone and with a grid, for both symmetric column
// wavelets, 1- and 3-channel lighting, 3-channel transports, every column, a few columns of
// every depth and a single depth-0 column; each range added onto what was there, or assigned.
TEST(CompressedRelighter, RangesAreTheWholeFramesPositions) {
  std::mt19937 rng(43);
  for (bool grid : {false, true})
    for (ColumnWavelet wavelet : {ColumnWavelet::kLeGall53, ColumnWavelet::kCdf97}) {
      for (uint32_t transport_channels : {1u, 3u}) {
        const CompressedTransport t = MeshTransport(wavelet, transport_channels, rng, grid);
        const CompressedRelighter relighter(t);
        const std::size_t V = relighter.sample_count(), M = relighter.column_count();
        ASSERT_EQ(V, grid ? 15588u : 11501u);
        EXPECT_TRUE(relighter.RangesAreLocal());
        const int maxd = MaxColumnDepth(t.header.domain);
        std::vector<std::vector<uint32_t>> light_sets(3);
        for (uint32_t j = 0; j < M; ++j)
          if (relighter.ColumnDepth(j) >= 0) light_sets[0].push_back(j);
        for (int d = 0; d <= maxd; ++d)
          for (uint32_t j = 0; j < M; ++j)
            if (relighter.ColumnDepth(j) == d) {
              light_sets[1].push_back(j);
              break;
            }
        ASSERT_GE(light_sets[1].size(), 10u);
        light_sets[2] = {light_sets[1][0]};  // depth 0
        ASSERT_EQ(relighter.ColumnDepth(light_sets[2][0]), 0);
        for (int channels : {1, 3}) {
          if (transport_channels == 3 && channels != 3) continue;
          for (const std::vector<uint32_t>& cols : light_sets) {
            std::vector<float> w(cols.size() * static_cast<std::size_t>(channels));
            for (float& v : w) v = std::uniform_real_distribution<float>(-1, 1)(rng);
            std::vector<double> whole(V * channels);
            std::vector<double*> out(channels);
            for (int c = 0; c < channels; ++c) out[c] = whole.data() + c * V;
            relighter.RelightSparseAdd(cols, w, channels, out, SampleOrder::kCoefficients, true);
            double scale = 0;
            for (double v : whole) scale = std::max(scale, std::abs(v));
            ASSERT_GT(scale, 0.0);
            const std::vector<std::pair<std::size_t, std::size_t>> ranges = {
                {0, 1},       {17, 1},    {9000, 1},    {9001, 1}, {V - 1, 1},   {0, 4000},
                {4000, 5001}, {8990, 40}, {9001, 2500}, {0, V},    {5555, 3333}, {123, 7}};
            for (auto [first, count] : ranges) {
              if (first + count > V) continue;
              std::vector<double> got(V * channels, 0.25);
              for (int c = 0; c < channels; ++c) out[c] = got.data() + c * V;
              relighter.RelightSparseAddRange(cols, w, channels, first, count, out, false);
              double worst = 0;
              std::size_t outside = 0;
              for (int c = 0; c < channels; ++c)
                for (std::size_t p = 0; p < V; ++p) {
                  const double g = got[c * V + p];
                  if (p >= first && p < first + count) {
                    worst = std::max(worst, std::abs(g - 0.25 - whole[c * V + p]));
                  } else {
                    outside += g != 0.25;
                  }
                }
              EXPECT_LT(worst, 1e-6 * scale)
                  << static_cast<int>(wavelet) << ' ' << transport_channels << ' ' << channels
                  << ' ' << cols.size() << " [" << first << ", +" << count << ")";
              EXPECT_EQ(outside, 0u);
            }
            // Ranges that tile the frame, assigned into NaN: the whole frame.
            std::vector<double> tiled(V * channels, std::nan(""));
            for (int c = 0; c < channels; ++c) out[c] = tiled.data() + c * V;
            for (std::size_t p = 0; p < V; p += 1000)
              relighter.RelightSparseAddRange(cols, w, channels, p,
                                              std::min<std::size_t>(1000, V - p), out, true);
            EXPECT_LT(RelErr(tiled, whole), 1e-7);
          }
        }
      }
    }
}

}  // namespace
}  // namespace prt
