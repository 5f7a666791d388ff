#include "worker/cpca.h"

#include <gtest/gtest.h>

#include <barrier>
#include <cmath>
#include <mutex>
#include <random>
#include <thread>

#include "formats/cpca_transport.h"
#include "vocabulary/errors.h"
#include "worker/transport_compressor.h"

namespace prt {
namespace {

CompressedTransportHeader Header(int n, std::size_t rows, uint32_t K, uint32_t S) {
  SpatialDomain domain;
  SpatialSegment seg;
  seg.count = static_cast<uint32_t>(rows);
  domain.segments.push_back(seg);
  CompressionOptions o;
  o.scheme = CompressionScheme::kCpca;
  o.cpca_clusters = K;
  o.cpca_bases = S;
  o.bits = 16;
  o.keep_fraction = 1.0;
  o.cpca_coefficient_bits = 20;
  return MakeCompressedHeader(o, n, domain);
}

CpcaOptions Options(const CompressedTransportHeader& h) {
  CpcaOptions o = CpcaOptionsFrom(h);
  o.candidates = 0;
  return o;
}

// Rows of `clusters` true clusters, each an affine subspace of dimension `rank` of well
// separated means: x = μ_k + Σ_i a_i v_{k,i}.
std::vector<float> AffineClusters(int clusters, int rank, std::size_t rows, std::size_t d,
                                  std::vector<int>* truth, uint32_t seed = 7) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<std::vector<float>> mu(clusters, std::vector<float>(d)),
      v(static_cast<std::size_t>(clusters * rank), std::vector<float>(d));
  for (int k = 0; k < clusters; ++k)
    for (std::size_t j = 0; j < d; ++j) mu[k][j] = 20.0f * g(rng);
  for (auto& vec : v)
    for (float& x : vec) x = g(rng);
  std::vector<float> X(rows * d);
  if (truth) truth->resize(rows);
  for (std::size_t r = 0; r < rows; ++r) {
    const int k = static_cast<int>(r % static_cast<std::size_t>(clusters));
    if (truth) (*truth)[r] = k;
    for (std::size_t j = 0; j < d; ++j) X[r * d + j] = mu[k][j];
    for (int i = 0; i < rank; ++i) {
      const float a = g(rng);
      for (std::size_t j = 0; j < d; ++j) X[r * d + j] += a * v[k * rank + i][j];
    }
  }
  return X;
}

double DecodedError(const CpcaTransport& t, const std::vector<float>& X) {
  return CpcaDecodedRelativeError(t, X.data());
}

TEST(Cpca, RecoversAffineClustersExactly) {
  // n = 2: 24 coefficients. Three clusters of rank 2, K = 3, S = 2: the representation is exact
  // up to quantisation (16-bit vectors, 20-bit coefficients).
  std::vector<int> truth;
  const std::vector<float> X = AffineClusters(3, 2, 300, 24, &truth);
  const CompressedTransportHeader h = Header(2, 300, 3, 2);
  CpcaStats st;
  const CpcaTransport t = CompressCpca(X.data(), h, Options(h), nullptr, &st);
  EXPECT_LT(st.relative_error, 2e-4);
  EXPECT_NEAR(DecodedError(t, X), st.relative_error, 1e-6);
  // The clustering is the true one (up to naming).
  for (std::size_t r = 3; r < 300; ++r) EXPECT_EQ(t.cluster_of[r], t.cluster_of[r % 3]) << r;
  EXPECT_NE(t.cluster_of[0], t.cluster_of[1]);
  EXPECT_NE(t.cluster_of[1], t.cluster_of[2]);
  EXPECT_EQ(st.empty_clusters, 0u);
}

TEST(Cpca, ErrorFallsWithBasesAndMatchesTheDecodedError) {
  std::vector<int> truth;
  const std::vector<float> X = AffineClusters(4, 6, 400, 24, &truth, 3);
  double last = 2;
  for (uint32_t S : {0u, 1u, 2u, 4u, 6u}) {
    const CompressedTransportHeader h = Header(2, 400, 4, S);
    CpcaStats st;
    const CpcaTransport t = CompressCpca(X.data(), h, Options(h), nullptr, &st);
    EXPECT_NEAR(DecodedError(t, X), st.relative_error, 1e-6) << S;
    EXPECT_LT(st.relative_error, last) << S;
    last = st.relative_error;
  }
  EXPECT_LT(last, 2e-4);  // S = 6: exact up to quantisation
}

TEST(Cpca, QuantisationErrorFollowsTheBits) {
  const std::vector<float> X = AffineClusters(2, 2, 200, 24, nullptr, 5);
  CompressedTransportHeader h = Header(2, 200, 2, 2);
  double previous = 1;
  for (int bits : {6, 9, 12}) {
    h.bits = static_cast<uint8_t>(bits);
    h.cpca_coefficient_bits = static_cast<uint8_t>(bits);
    CpcaStats st;
    CompressCpca(X.data(), h, Options(h), nullptr, &st);
    // A uniform quantiser of step 2/(2^bits − 2) relative to each vector's largest term.
    EXPECT_LT(st.relative_error, 8.0 / ((1 << bits) - 2)) << bits;
    EXPECT_LT(st.relative_error, previous) << bits;
    previous = st.relative_error;
  }
}

TEST(Cpca, TruncatedBasisKeepsItsLargestTerms) {
  const std::vector<float> X = AffineClusters(2, 3, 200, 96, nullptr, 11);
  CompressedTransportHeader h = Header(2, 200, 2, 3);
  h.cubemap_n = 4;  // 96 coefficients
  h.keep_fraction = 0.25;
  CpcaStats st;
  const CpcaTransport t = CompressCpca(X.data(), h, Options(h), nullptr, &st);
  for (const CpcaCluster& c : t.clusters) {
    EXPECT_LE(c.mean.term_count(), 24u);
    for (const CpcaVector& v : c.basis) EXPECT_LE(v.term_count(), 24u);
  }
  EXPECT_NEAR(DecodedError(t, X), st.relative_error, 1e-6);
  EXPECT_GT(st.relative_error, 1e-3);  // truncation costs something on dense random rows
  EXPECT_LT(st.relative_error, 0.9);
}

TEST(Cpca, FewerRowsThanBasesDuplicateAndZeroRowsStayFinite) {
  // 12 rows: 4 zero rows, 4 copies of one row, 4 distinct; 5 clusters of S = 8 each.
  const std::size_t d = 24;
  std::vector<float> X(12 * d, 0.0f);
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<float> dup(d);
  for (float& x : dup) x = u(rng);
  for (std::size_t r = 4; r < 8; ++r)
    for (std::size_t j = 0; j < d; ++j) X[r * d + j] = dup[j];
  for (std::size_t r = 8; r < 12; ++r)
    for (std::size_t j = 0; j < d; ++j) X[r * d + j] = u(rng);
  const CompressedTransportHeader h = Header(2, 12, 5, 8);
  CpcaStats st;
  const CpcaTransport t = CompressCpca(X.data(), h, Options(h), nullptr, &st);
  EXPECT_TRUE(std::isfinite(st.relative_error));
  // 6 distinct rows (zero, the duplicate, 4 others) in 5 clusters of up to 8 bases: exact.
  EXPECT_LT(st.relative_error, 1e-4);
  EXPECT_NEAR(DecodedError(t, X), st.relative_error, 1e-6);
  std::vector<float> row(d);
  for (std::size_t r = 0; r < 4; ++r) {
    DecodeCpcaRow(t, r, row);
    for (float v : row) EXPECT_NEAR(v, 0.0f, 1e-5f);
  }
  const std::vector<uint8_t> bytes = EncodeCpcaTransport(t);
  const CpcaTransport back = DecodeCpcaTransport(bytes, "test");
  EXPECT_EQ(EncodeCpcaTransport(back), bytes);
}

TEST(Cpca, AllZeroRowsGiveAnAllZeroTransport) {
  const std::vector<float> X(50 * 24, 0.0f);
  const CompressedTransportHeader h = Header(2, 50, 4, 3);
  CpcaStats st;
  const CpcaTransport t = CompressCpca(X.data(), h, Options(h), nullptr, &st);
  EXPECT_EQ(st.relative_error, 0.0);
  EXPECT_EQ(t.term_count(), 0u);
  for (int32_t q : t.coefficients) EXPECT_EQ(q, 0);
}

TEST(Cpca, NonFiniteRowsAreRejected) {
  std::vector<float> X(10 * 24, 1.0f);
  X[5 * 24 + 3] = std::numeric_limits<float>::quiet_NaN();
  const CompressedTransportHeader h = Header(2, 10, 2, 1);
  EXPECT_THROW(CompressCpca(X.data(), h, Options(h)), NumericalError);
}

// P threads, each holding CpcaRowRange(R, p, P), reducing through shared memory.
struct Shared {
  explicit Shared(int p) : barrier(p) {}
  std::barrier<> barrier;
  std::mutex mutex;
  int arrived = 0;
  std::vector<int64_t> isum;
  std::vector<double> dmax;
};
class Reducer final : public CpcaReducer {
 public:
  explicit Reducer(Shared& s) : s_(s) {}
  void SumInt64(std::span<int64_t> v) override {
    Round([&] { s_.isum.assign(v.size(), 0); },
          [&] {
            for (std::size_t i = 0; i < v.size(); ++i) s_.isum[i] += v[i];
          },
          [&] { std::copy(s_.isum.begin(), s_.isum.end(), v.begin()); });
  }
  void MaxDouble(std::span<double> v) override {
    Round([&] { s_.dmax.assign(v.size(), -std::numeric_limits<double>::infinity()); },
          [&] {
            for (std::size_t i = 0; i < v.size(); ++i) s_.dmax[i] = std::max(s_.dmax[i], v[i]);
          },
          [&] { std::copy(s_.dmax.begin(), s_.dmax.end(), v.begin()); });
  }

 private:
  template <class A, class B, class C>
  void Round(A&& init, B&& add, C&& read) {
    {
      std::lock_guard<std::mutex> lock(s_.mutex);
      if (s_.arrived++ == 0) init();
      add();
    }
    s_.barrier.arrive_and_wait();  // every contribution is in
    read();
    s_.barrier.arrive_and_wait();  // every thread has read
    {
      std::lock_guard<std::mutex> lock(s_.mutex);
      --s_.arrived;
    }
    s_.barrier.arrive_and_wait();  // the next round starts from 0
  }
  Shared& s_;
};

CpcaTransport RunThreads(const std::vector<float>& X, const CompressedTransportHeader& h,
                         const CpcaOptions& o, int P, const CpcaSparseStructure* sparse) {
  const std::size_t d = h.column_count();
  std::vector<CpcaLocalResult> parts(static_cast<std::size_t>(P));
  Shared shared(P);
  std::vector<std::thread> threads;
  for (int p = 0; p < P; ++p)
    threads.emplace_back([&, p] {
      Reducer red(shared);
      const auto [lo, hi] = CpcaRowRange(h.sample_count, p, P);
      parts[static_cast<std::size_t>(p)] =
          ComputeCpca(h, o, X.data() + lo * d, lo, hi - lo, red, sparse);
    });
  for (auto& t : threads) t.join();
  CpcaTransport t;
  t.header = h;
  t.clusters = parts[0].clusters;
  for (const auto& part : parts) {
    t.cluster_of.insert(t.cluster_of.end(), part.cluster_of.begin(), part.cluster_of.end());
    t.coefficients.insert(t.coefficients.end(), part.coefficients.begin(), part.coefficients.end());
    // Every process holds the same clusters.
    EXPECT_EQ(part.clusters.size(), t.clusters.size());
    for (std::size_t c = 0; c < part.clusters.size(); ++c) {
      EXPECT_EQ(part.clusters[c].mean.q, t.clusters[c].mean.q);
      EXPECT_EQ(part.clusters[c].coefficient_scale, t.clusters[c].coefficient_scale);
    }
  }
  return t;
}

TEST(Cpca, RowRangesAreWholeUnitsCoveringEveryRow) {
  for (uint64_t rows : {1ull, 1023ull, 1024ull, 5000ull, 100000ull})
    for (int P = 1; P <= 9; ++P) {
      uint64_t next = 0;
      for (int p = 0; p < P; ++p) {
        const auto [lo, hi] = CpcaRowRange(rows, p, P);
        EXPECT_EQ(lo, next);
        EXPECT_LE(lo, hi);
        EXPECT_TRUE(lo % kCpcaUnitRows == 0 || lo == rows);
        next = hi;
      }
      EXPECT_EQ(next, rows);
    }
}

TEST(Cpca, BitIdenticalForAnyNumberOfProcesses) {
  // 3000 rows: three units, so two and three processes really split the rows.
  const std::vector<float> X = AffineClusters(5, 3, 3000, 24, nullptr, 9);
  CompressedTransportHeader h = Header(2, 3000, 6, 4);
  h.bits = 10;
  h.keep_fraction = 0.5;
  CpcaOptions o = CpcaOptionsFrom(h);
  o.candidates = 3;
  const CpcaTransport whole = CompressCpca(X.data(), h, o);
  const std::vector<uint8_t> bytes = EncodeCpcaTransport(whole);
  for (int P : {1, 2, 3, 4}) {
    CpcaTransport t = RunThreads(X, h, o, P, nullptr);
    t.header = whole.header;
    EXPECT_EQ(EncodeCpcaTransport(t), bytes) << P << " processes";
  }
}

// Sparse rows that are linear combinations of dense neighbours (Huang §5 Eq. 4): the dense pass
// plus re-clustering reaches about the standard error with far fewer distance evaluations.
TEST(Cpca, DensePassAndReclusteringMatchStandardCpca) {
  const std::size_t d = 24, R = 2000;
  std::vector<int> truth;
  std::vector<float> X = AffineClusters(4, 3, R, d, &truth, 21);
  std::vector<uint8_t> dense(R, 0);
  std::vector<std::vector<uint32_t>> nb(R);
  for (std::size_t r = 0; r < R; ++r) dense[r] = (r / 4) % 4 == 0;  // rows 16k … 16k + 3
  for (std::size_t r = 0; r < R; ++r) {
    if (dense[r]) continue;
    // Two dense rows of the same true cluster: rows ≡ r (mod 4) in the nearest dense blocks.
    const std::size_t base = r / 16 * 16 + r % 4;
    const std::size_t a = base, b = base + 16 < R ? base + 16 : base;
    nb[r] = {static_cast<uint32_t>(a), static_cast<uint32_t>(b)};
    for (std::size_t j = 0; j < d; ++j) X[r * d + j] = 0.3f * X[a * d + j] + 0.7f * X[b * d + j];
  }
  const CpcaSparseStructure sparse = CpcaSparseStructure::Of(dense, nb, 1);
  const CompressedTransportHeader h = Header(2, R, 4, 3);
  CpcaOptions o = CpcaOptionsFrom(h);
  o.candidates = 0;
  CpcaStats standard, huang;
  const CpcaTransport a = CompressCpca(X.data(), h, o, nullptr, &standard);
  const CpcaTransport b = CompressCpca(X.data(), h, o, &sparse, &huang);
  EXPECT_EQ(b.header.cpca_method, CpcaMethod::kDenseRecluster);
  // The dense pass finds the true clusters and every sparse row joins its own.
  for (std::size_t r = 0; r < R; ++r) EXPECT_EQ(b.cluster_of[r], b.cluster_of[r % 4]) << r;
  EXPECT_EQ(huang.rows_dense_pass, R / 4);
  EXPECT_LT(huang.relative_error, std::max(2e-4, 1.5 * standard.relative_error));
  EXPECT_LT(huang.distance_evaluations * 3, standard.distance_evaluations);
  EXPECT_NEAR(DecodedError(b, X), huang.relative_error, 1e-6);
  // Byte-identical across processes too.
  CpcaTransport t = RunThreads(X, h, o, 2, &sparse);
  t.header = b.header;
  EXPECT_EQ(EncodeCpcaTransport(t), EncodeCpcaTransport(b));
}

}  // namespace
}  // namespace prt
