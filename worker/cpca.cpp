// Clustered PCA (Sloan et al. 2003) with Huang & Ramamoorthi 2010 §6's dense pass and
// re-clustering pass; see worker/cpca.h and docs/cpca.md.
#include "worker/cpca.h"

#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"

namespace prt {

using MatF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MatD = Eigen::MatrixXd;

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

uint64_t SplitMix(uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

// A deterministic value in [−1, 1) for (seed, a, b, c): subspace starts.
float Noise(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
  const uint64_t h = SplitMix(SplitMix(SplitMix(seed ^ 0x5eedcca) ^ a) ^ (b << 20 ^ c));
  return static_cast<float>(static_cast<double>(h >> 11) * 0x1.0p-52 - 1.0);
}

// Sums that travel between processes as 64-bit integers: value·scale rounded once per unit and
// cluster, scale = 2^62 / bound with `bound` at least the largest possible |sum|.
struct Fixed {
  double scale = 1;
  explicit Fixed(double bound) {
    scale = bound > 0 && std::isfinite(bound) ? std::ldexp(1.0, 62) / bound : 1.0;
  }
  // Rounds half away from zero; a plain truncating conversion (one instruction, no libm call).
  int64_t To(double v) const {
    const double x = v * scale;
    return static_cast<int64_t>(x >= 0 ? x + 0.5 : x - 0.5);
  }
  double From(int64_t v) const { return static_cast<double>(v) / scale; }
};

int MaxQ(int bits) {
  return (1 << (bits - 1)) - 1;
}

// The basis dimensions of the LBG stages: 0, 1, 2, 4, … S.
std::vector<uint32_t> StageDims(uint32_t S) {
  std::vector<uint32_t> dims{0};
  for (uint32_t s = 1; s < S; s *= 2) dims.push_back(s);
  if (S > 0) dims.push_back(S);
  return dims;
}

// Everything one process knows while clustering.
class Clustering {
 public:
  Clustering(const CompressedTransportHeader& h, const CpcaOptions& o, const float* rows,
             uint64_t first, uint64_t count, CpcaReducer& reducer)
      : o_(o),
        X_(rows),
        first_(first),
        count_(count),
        R_(h.sample_count),
        d_(h.column_count()),
        K_(o.clusters),
        red_(reducer) {
    cluster_.assign(count_, 0);
    active_.assign(count_, 1);
    mean_ = MatF::Zero(K_, d_);
    mean_norm_.assign(K_, 0.0f);
    basis_.assign(K_, MatF());
    members_.assign(K_, 0);
    // Global bounds: the largest |x| (and a finiteness check).
    double xmax = 0;
    for (uint64_t i = 0; i < count_ * d_; ++i) {
      const float v = X_[i];
      if (!std::isfinite(v))
        throw NumericalError("CPCA: row " + std::to_string(first_ + i / d_) + " has a NaN/Inf");
      xmax = std::max(xmax, static_cast<double>(std::fabs(v)));
    }
    double m[1] = {xmax};
    red_.MaxDouble(m);
    xmax_ = m[0];
  }

  uint64_t distance_evaluations() const { return distances_; }
  const std::vector<uint32_t>& cluster() const { return cluster_; }
  std::vector<uint32_t>& cluster() { return cluster_; }
  std::vector<uint8_t>& active() { return active_; }
  const MatF& mean() const { return mean_; }
  const std::vector<MatF>& basis() const { return basis_; }
  const std::vector<uint64_t>& members() const { return members_; }
  double xmax() const { return xmax_; }
  uint32_t dim() const { return dim_; }
  const std::vector<double>& variance() const { return variance_; }
  const std::vector<double>& scatter() const { return scatter_; }

  // Seeds (k-means++, Arthur & Vassilvitskii 2007, made deterministic): the first mean is a
  // row of `pool` (the participating rows, global indices) drawn by the seed, each next one a
  // row drawn with probability ∝ its squared distance to the nearest mean so far. The draw is
  // over fixed-point per-row weights summed per unit, so every process picks the same row.
  // Clusters left without a seed (every row equals a seed) start empty.
  void Seed(const std::vector<uint64_t>& pool) {
    std::vector<double> dmin(count_, -1.0);
    for (uint64_t r = 0; r < count_; ++r)
      if (active_[r]) dmin[r] = std::numeric_limits<double>::infinity();
    const uint64_t units = (R_ + kCpcaUnitRows - 1) / kCpcaUnitRows;
    uint64_t row = pool[SplitMix(o_.seed) % pool.size()];
    std::fill(members_.begin(), members_.end(), 0);
    for (uint32_t c = 0; c < K_; ++c) {
      SetMeanToRow(c, row);
      members_[c] = 1;
      if (c + 1 == K_) break;
      // Squared distances to the nearest mean, then a draw.
      double mx[1] = {0.0};
      tbb::parallel_for(uint64_t{0}, count_, [&](uint64_t r) {
        if (dmin[r] < 0) return;
        Eigen::Map<const Eigen::Matrix<float, 1, Eigen::Dynamic>> xv(X_ + r * d_, d_);
        dmin[r] = std::min(dmin[r], static_cast<double>((xv - mean_.row(c)).squaredNorm()));
      });
      for (uint64_t r = 0; r < count_; ++r) mx[0] = std::max(mx[0], dmin[r]);
      red_.MaxDouble(mx);
      if (!(mx[0] > 0)) break;  // every row is one of the seeds
      const Fixed fx(mx[0] * static_cast<double>(kCpcaUnitRows) * static_cast<double>(units));
      std::vector<int64_t> unit_sum(units, 0);
      for (uint64_t r = 0; r < count_; ++r)
        if (dmin[r] > 0) unit_sum[(first_ + r) / kCpcaUnitRows] += fx.To(dmin[r]);
      red_.SumInt64(unit_sum);
      int64_t total = 0;
      for (int64_t v : unit_sum) total += v;
      if (total <= 0) break;
      int64_t target =
          static_cast<int64_t>(SplitMix(o_.seed * 31 + c + 1) % static_cast<uint64_t>(total));
      uint64_t unit = 0;
      while (target >= unit_sum[unit]) target -= unit_sum[unit++];
      std::vector<int64_t> pick(1, 0);
      const uint64_t lo = unit * kCpcaUnitRows;
      if (lo >= first_ && lo < first_ + count_) {
        for (uint64_t r = lo - first_; r < std::min(count_, lo - first_ + kCpcaUnitRows); ++r) {
          const int64_t w = dmin[r] > 0 ? fx.To(dmin[r]) : 0;
          if (target < w) {
            pick[0] = static_cast<int64_t>(first_ + r) + 1;
            break;
          }
          target -= w;
        }
      }
      red_.SumInt64(pick);
      if (pick[0] <= 0) break;
      row = static_cast<uint64_t>(pick[0] - 1);
    }
    RefreshMeanNorms();
  }

  // mean_ row c = row `row` (global), from the process that holds it.
  void SetMeanToRow(uint32_t c, uint64_t row) {
    std::vector<int64_t> bits(d_, 0);
    if (row >= first_ && row < first_ + count_) {
      const float* x = X_ + (row - first_) * d_;
      for (uint32_t j = 0; j < d_; ++j) {
        uint32_t u;
        std::memcpy(&u, &x[j], 4);
        bits[j] = u;
      }
    }
    red_.SumInt64(bits);  // one process contributes each value, the others 0: exact
    for (uint32_t j = 0; j < d_; ++j) {
      const uint32_t u = static_cast<uint32_t>(bits[j]);
      float v;
      std::memcpy(&v, &u, 4);
      mean_(c, j) = v;
    }
    mean_norm_[c] = mean_.row(c).squaredNorm();
  }

  // Grows the basis to `dim` vectors per cluster: the new ones start as deterministic noise,
  // orthonormalised against the old.
  void GrowBasis(uint32_t dim) {
    for (uint32_t c = 0; c < K_; ++c) {
      MatF& U = basis_[c];
      const uint32_t old = static_cast<uint32_t>(U.cols());
      MatD Q(d_, dim);
      for (uint32_t i = 0; i < dim; ++i)
        for (uint32_t j = 0; j < d_; ++j)
          Q(j, i) = i < old ? static_cast<double>(U(j, i)) : Noise(o_.seed, c, i, j);
      U = Orthonormal(Q).cast<float>();
    }
    dim_ = dim;
    variance_.assign(static_cast<std::size_t>(K_) * dim_, 0.0);
  }

  // Assignment: every active row to the cluster of least projection distance
  //   ‖x − μ_c‖² − ‖U_cᵀ(x − μ_c)‖²
  // among the candidates: the `candidates` clusters of nearest mean and its own (or, with
  // `restricted`, its own and those restricted(row) lists). Ties go to the lower cluster id.
  template <class Restricted>
  void Assign(const Restricted& restricted, bool use_restricted) {
    const uint32_t s = dim_;
    // U_cᵀ μ_c per cluster.
    MatF Umu(K_, std::max<uint32_t>(s, 1));
    for (uint32_t c = 0; c < K_; ++c)
      if (s > 0) Umu.row(c) = mean_.row(c) * basis_[c];
    const uint32_t C = o_.candidates == 0 ? K_ : std::min(o_.candidates, K_);
    constexpr uint64_t kBlock = 256;
    const uint64_t blocks = (count_ + kBlock - 1) / kBlock;
    std::vector<uint64_t> evaluations(blocks, 0);
    tbb::parallel_for(uint64_t{0}, blocks, [&](uint64_t b) {
      const uint64_t lo = b * kBlock, hi = std::min(count_, lo + kBlock);
      Eigen::Map<const MatF> Xb(X_ + lo * d_, static_cast<Eigen::Index>(hi - lo), d_);
      // x·μ_c for the block's active rows (not with restricted candidates): D row slot[r − lo].
      MatF D;
      std::vector<uint32_t> slot(hi - lo, 0);
      if (!use_restricted) {
        uint32_t m = 0;
        for (uint64_t r = lo; r < hi; ++r)
          if (active_[r]) slot[r - lo] = m++;
        if (m == hi - lo) {
          D = Xb * mean_.transpose();
        } else if (m > 0) {
          MatF A(static_cast<Eigen::Index>(m), d_);
          for (uint64_t r = lo; r < hi; ++r)
            if (active_[r]) A.row(slot[r - lo]) = Xb.row(static_cast<Eigen::Index>(r - lo));
          D = A * mean_.transpose();
        }
      }
      // Per row its candidates (mean distance, cluster); then the projections grouped by
      // cluster, one GEMM of the block's rows that have it as a candidate; then the choice.
      std::vector<std::vector<std::pair<float, uint32_t>>> cands(hi - lo);
      for (uint64_t r = lo; r < hi; ++r) {
        if (!active_[r]) continue;
        auto& cand = cands[r - lo];
        const float* x = X_ + r * d_;
        Eigen::Map<const Eigen::Matrix<float, 1, Eigen::Dynamic>> xv(x, d_);
        const float xx = xv.squaredNorm();
        if (use_restricted) {
          cand.emplace_back(0.0f, cluster_[r]);
          for (uint32_t c : restricted(r))
            if (c != cluster_[r]) cand.emplace_back(0.0f, c);
          std::sort(cand.begin() + 1, cand.end(),
                    [](const auto& a, const auto& b2) { return a.second < b2.second; });
          cand.erase(
              std::unique(cand.begin() + 1, cand.end(),
                          [](const auto& a, const auto& b2) { return a.second == b2.second; }),
              cand.end());
          for (auto& [dist, c] : cand) dist = xx - 2 * xv.dot(mean_.row(c)) + mean_norm_[c];
        } else {
          for (uint32_t c = 0; c < K_; ++c)
            if (members_[c] > 0) cand.emplace_back(xx - 2 * D(slot[r - lo], c) + mean_norm_[c], c);
          if (cand.empty()) cand.emplace_back(0.0f, 0);
          if (s > 0 && cand.size() > C) {
            const auto less = [](const auto& a, const auto& b2) {
              return a.first < b2.first || (a.first == b2.first && a.second < b2.second);
            };
            std::nth_element(cand.begin(), cand.begin() + C, cand.end(), less);
            const bool own = std::any_of(cand.begin(), cand.begin() + C,
                                         [&](const auto& p) { return p.second == cluster_[r]; });
            cand.resize(C);
            if (!own && members_[cluster_[r]] > 0)
              cand.emplace_back(xx - 2 * D(slot[r - lo], cluster_[r]) + mean_norm_[cluster_[r]],
                                cluster_[r]);
          }
        }
      }
      if (s > 0) {
        std::vector<std::vector<std::pair<uint32_t, uint32_t>>> by_cluster(K_);  // (row, slot)
        for (uint64_t r = lo; r < hi; ++r)
          for (uint32_t k = 0; k < cands[r - lo].size(); ++k)
            by_cluster[cands[r - lo][k].second].push_back({static_cast<uint32_t>(r - lo), k});
        MatF G, Z;
        for (uint32_t c = 0; c < K_; ++c) {
          const auto& list = by_cluster[c];
          if (list.empty()) continue;
          G.resize(static_cast<Eigen::Index>(list.size()), d_);
          for (std::size_t k = 0; k < list.size(); ++k)
            G.row(static_cast<Eigen::Index>(k)) = Xb.row(list[k].first);
          Z.noalias() = G * basis_[c];
          for (std::size_t k = 0; k < list.size(); ++k)
            cands[list[k].first][list[k].second].first -=
                (Z.row(static_cast<Eigen::Index>(k)) - Umu.row(c)).squaredNorm();
          evaluations[b] += list.size();
        }
      }
      for (uint64_t r = lo; r < hi; ++r) {
        if (!active_[r]) continue;
        float best = std::numeric_limits<float>::infinity();
        uint32_t best_c = cluster_[r];
        for (const auto& [e, c] : cands[r - lo])
          if (e < best || (e == best && c < best_c)) {
            best = e;
            best_c = c;
          }
        cluster_[r] = best_c;
      }
    });
    for (uint64_t e : evaluations) distances_ += e;
  }

  // Update: every cluster's mean, then `power` subspace iterations on its scatter matrix, from
  // the active rows. Sums are per unit and cluster, in fixed point, summed over processes.
  void Update(int power) {
    BuildMemberLists();
    // Member counts (exact) and means.
    std::vector<int64_t> counts(K_, 0);
    for (uint32_t c = 0; c < K_; ++c) counts[c] = static_cast<int64_t>(Members(c));
    red_.SumInt64(counts);
    const Fixed fm(xmax_ * static_cast<double>(R_) * 2 + 1e-300);
    std::vector<int64_t> sums(static_cast<std::size_t>(K_) * d_, 0);
    tbb::parallel_for(uint32_t{0}, K_, [&](uint32_t c) {
      std::vector<double> part(d_);
      ForEachUnitRun(c, [&](const uint32_t* rows, std::size_t m) {
        std::fill(part.begin(), part.end(), 0.0);
        for (std::size_t k = 0; k < m; ++k) {
          const float* x = X_ + static_cast<std::size_t>(rows[k]) * d_;
          for (uint32_t j = 0; j < d_; ++j) part[j] += x[j];
        }
        int64_t* acc = sums.data() + static_cast<std::size_t>(c) * d_;
        for (uint32_t j = 0; j < d_; ++j) acc[j] += fm.To(part[j]);
      });
    });
    red_.SumInt64(sums);
    for (uint32_t c = 0; c < K_; ++c) {
      members_[c] = static_cast<uint64_t>(counts[c]);
      if (counts[c] == 0) continue;  // an empty cluster keeps its mean (Reseed may move it)
      for (uint32_t j = 0; j < d_; ++j)
        mean_(c, j) = static_cast<float>(fm.From(sums[static_cast<std::size_t>(c) * d_ + j]) /
                                         static_cast<double>(counts[c]));
    }
    RefreshMeanNorms();
    for (int it = 0; it < power; ++it) SubspaceIteration(it + 1 == power);
  }

  // An empty cluster takes the row of largest projection distance to its own cluster (ties: the
  // lowest row index), as long as some row has a positive distance.
  void Reseed() {
    std::vector<uint32_t> empty;
    for (uint32_t c = 0; c < K_; ++c)
      if (members_[c] == 0) empty.push_back(c);
    if (empty.empty()) return;
    std::vector<float> err(count_, -1.0f);
    tbb::parallel_for(uint64_t{0}, count_, [&](uint64_t r) {
      if (!active_[r]) return;
      err[r] = Distance(r, cluster_[r]);
    });
    for (uint32_t c : empty) {
      double best[2] = {0.0, -static_cast<double>(R_)};  // distance, −row
      for (uint64_t r = 0; r < count_; ++r)
        if (err[r] > best[0]) best[0] = err[r];
      red_.MaxDouble(std::span<double>(best, 1));
      if (!(best[0] > 0)) return;
      for (uint64_t r = 0; r < count_; ++r)
        if (err[r] == best[0]) {
          best[1] = -static_cast<double>(first_ + r);
          break;
        }
      red_.MaxDouble(std::span<double>(best + 1, 1));
      const uint64_t row = static_cast<uint64_t>(-best[1]);
      if (row >= first_ && row < first_ + count_) {
        err[row - first_] = -1.0f;
        cluster_[row - first_] = c;
      }
      SetMeanToRow(c, row);
      members_[c] = 1;
    }
  }

  float Distance(uint64_t r, uint32_t c) const {
    Eigen::Map<const Eigen::Matrix<float, 1, Eigen::Dynamic>> xv(X_ + r * d_, d_);
    const Eigen::Matrix<float, 1, Eigen::Dynamic> y = xv - mean_.row(c);
    float e = y.squaredNorm();
    if (dim_ > 0) e -= (y * basis_[c]).squaredNorm();
    return std::max(e, 0.0f);
  }

 private:
  static MatD Orthonormal(const MatD& Q) {
    if (Q.cols() == 0) return Q;
    Eigen::HouseholderQR<MatD> qr(Q);
    return qr.householderQ() * MatD::Identity(Q.rows(), Q.cols());
  }

  uint64_t Members(uint32_t c) const { return member_begin_[c + 1] - member_begin_[c]; }

  // Local active rows grouped by cluster, each group in row order.
  void BuildMemberLists() {
    member_begin_.assign(K_ + 1, 0);
    for (uint64_t r = 0; r < count_; ++r)
      if (active_[r]) ++member_begin_[cluster_[r] + 1];
    for (uint32_t c = 0; c < K_; ++c) member_begin_[c + 1] += member_begin_[c];
    member_rows_.assign(member_begin_[K_], 0);
    std::vector<uint64_t> at(member_begin_.begin(), member_begin_.end() - 1);
    for (uint64_t r = 0; r < count_; ++r)
      if (active_[r]) member_rows_[at[cluster_[r]]++] = static_cast<uint32_t>(r);
  }

  // Calls f(rows, m) for each run of cluster c's local members inside one unit.
  template <class F>
  void ForEachUnitRun(uint32_t c, F&& f) const {
    const uint32_t* rows = member_rows_.data() + member_begin_[c];
    const std::size_t n = member_begin_[c + 1] - member_begin_[c];
    std::size_t k = 0;
    while (k < n) {
      const uint64_t unit = (first_ + rows[k]) / kCpcaUnitRows;
      std::size_t e = k + 1;
      while (e < n && (first_ + rows[e]) / kCpcaUnitRows == unit) ++e;
      f(rows + k, e - k);
      k = e;
    }
  }

  void RefreshMeanNorms() {
    for (uint32_t c = 0; c < K_; ++c) mean_norm_[c] = mean_.row(c).squaredNorm();
  }

  // Y_c = Σ (x − μ_c)(x − μ_c)ᵀ U_c, then U_c = orthonormal(Y_c). `last` also records the
  // variance ‖Y_c e_i‖ = ‖C_c u_i‖ captured by each vector.
  void SubspaceIteration(bool last) {
    const uint32_t s = dim_;
    if (s == 0) return;
    // |(x − μ)_j| ≤ 2·xmax and |z_i| ≤ ‖x − μ‖ ≤ 2·xmax·√d per row.
    const Fixed fy(
        4 * xmax_ * xmax_ * std::sqrt(static_cast<double>(d_)) * static_cast<double>(R_) + 1e-300);
    std::vector<int64_t> Y(static_cast<std::size_t>(K_) * d_ * s, 0);
    tbb::parallel_for(uint32_t{0}, K_, [&](uint32_t c) {
      int64_t* acc = Y.data() + static_cast<std::size_t>(c) * d_ * s;
      MatF Xc, Z, P;
      ForEachUnitRun(c, [&](const uint32_t* rows, std::size_t m) {
        Xc.resize(static_cast<Eigen::Index>(m), d_);
        for (std::size_t k = 0; k < m; ++k)
          Xc.row(static_cast<Eigen::Index>(k)) =
              Eigen::Map<const Eigen::Matrix<float, 1, Eigen::Dynamic>>(
                  X_ + static_cast<std::size_t>(rows[k]) * d_, d_) -
              mean_.row(c);
        Z.noalias() = Xc * basis_[c];
        P.noalias() = Xc.transpose() * Z;  // d × s, row-major
        const float* p = P.data();
        for (std::size_t k = 0; k < static_cast<std::size_t>(d_) * s; ++k) acc[k] += fy.To(p[k]);
      });
    });
    red_.SumInt64(Y);
    if (last) variance_.assign(static_cast<std::size_t>(K_) * s, 0.0);
    for (uint32_t c = 0; c < K_; ++c) {
      if (members_[c] == 0) continue;
      MatD Yc(d_, s);
      const int64_t* acc = Y.data() + static_cast<std::size_t>(c) * d_ * s;
      for (uint32_t j = 0; j < d_; ++j)
        for (uint32_t i = 0; i < s; ++i)
          Yc(j, i) = fy.From(acc[static_cast<std::size_t>(j) * s + i]);
      if (last)
        for (uint32_t i = 0; i < s; ++i)
          variance_[static_cast<std::size_t>(c) * s + i] = Yc.col(i).norm();
      // A direction without variance (a cluster of fewer rows than S + 1, duplicate rows) keeps
      // deterministic noise so that the QR stays full rank; it is dropped when stored.
      const double tiny = 1e-300 + 1e-12 * Yc.norm();
      for (uint32_t i = 0; i < s; ++i)
        if (Yc.col(i).norm() <= tiny)
          for (uint32_t j = 0; j < d_; ++j) Yc(j, i) = 1e-20 * Noise(o_.seed, c, i + 1000, j);
      basis_[c] = Orthonormal(Yc).cast<float>();
    }
  }

 public:
  // The scatter trace Σ ‖x − μ_c‖² of every cluster (for the stored basis's variance test).
  void ComputeScatter() {
    BuildMemberLists();
    const Fixed ft(4 * xmax_ * xmax_ * static_cast<double>(d_) * static_cast<double>(R_) + 1e-300);
    std::vector<int64_t> tr(K_, 0);
    tbb::parallel_for(uint32_t{0}, K_, [&](uint32_t c) {
      ForEachUnitRun(c, [&](const uint32_t* rows, std::size_t m) {
        double part = 0;
        for (std::size_t k = 0; k < m; ++k) {
          const float* x = X_ + static_cast<std::size_t>(rows[k]) * d_;
          for (uint32_t j = 0; j < d_; ++j) {
            const double v = static_cast<double>(x[j]) - mean_(c, j);
            part += v * v;
          }
        }
        tr[c] += ft.To(part);
      });
    });
    red_.SumInt64(tr);
    scatter_.assign(K_, 0.0);
    for (uint32_t c = 0; c < K_; ++c) scatter_[c] = ft.From(tr[c]);
  }

 private:
  const CpcaOptions& o_;
  const float* X_;
  uint64_t first_, count_, R_;
  uint32_t d_, K_;
  CpcaReducer& red_;
  double xmax_ = 0;
  uint32_t dim_ = 0;
  std::vector<uint32_t> cluster_;  // per local row
  std::vector<uint8_t> active_;    // per local row: takes part in the current pass
  MatF mean_;                      // K × d
  std::vector<float> mean_norm_;
  std::vector<MatF> basis_;        // per cluster d × dim, orthonormal columns
  std::vector<uint64_t> members_;  // global member counts
  std::vector<double> variance_;   // K × dim: ‖C_c u_i‖ after the last update
  std::vector<double> scatter_;    // per cluster Σ ‖x − μ‖²
  std::vector<uint64_t> member_begin_;
  std::vector<uint32_t> member_rows_;
  uint64_t distances_ = 0;
};

// Keeps the `keep` largest |v_j| (ties: lower index), quantised with `bits`.
CpcaVector QuantiseVector(const double* v, uint32_t d, uint32_t keep, int bits) {
  CpcaVector out;
  std::vector<uint32_t> idx;
  for (uint32_t j = 0; j < d; ++j)
    if (v[j] != 0 && std::isfinite(v[j])) idx.push_back(j);
  if (idx.empty()) return out;
  if (idx.size() > keep) {
    std::nth_element(idx.begin(), idx.begin() + keep, idx.end(), [&](uint32_t a, uint32_t b) {
      const double fa = std::fabs(v[a]), fb = std::fabs(v[b]);
      return fa > fb || (fa == fb && a < b);
    });
    idx.resize(keep);
  }
  std::sort(idx.begin(), idx.end());
  double scale = 0;
  for (uint32_t j : idx) scale = std::max(scale, std::fabs(v[j]));
  const float fscale = static_cast<float>(scale);
  if (!(fscale > 0) || !std::isfinite(fscale)) return out;
  const int A = MaxQ(bits);
  for (uint32_t j : idx) {
    const long q = std::lround(v[j] / static_cast<double>(fscale) * A);
    if (q == 0) continue;
    out.index.push_back(j);
    out.q.push_back(static_cast<int32_t>(std::clamp<long>(q, -A, A)));
  }
  out.scale = out.index.empty() ? 0.0f : fscale;
  return out;
}

void Dequantise(const CpcaVector& v, int bits, double* out) {
  const double f = static_cast<double>(v.scale) / MaxQ(bits);
  for (std::size_t k = 0; k < v.index.size(); ++k) out[v.index[k]] += v.q[k] * f;
}

}  // namespace

std::pair<uint64_t, uint64_t> CpcaRowRange(uint64_t rows, int p, int P) {
  if (P <= 0 || p < 0 || p >= P) throw std::invalid_argument("CpcaRowRange: bad process");
  const uint64_t units = (rows + kCpcaUnitRows - 1) / kCpcaUnitRows;
  const uint64_t u0 = units * static_cast<uint64_t>(p) / static_cast<uint64_t>(P);
  const uint64_t u1 = units * static_cast<uint64_t>(p + 1) / static_cast<uint64_t>(P);
  return {std::min(rows, u0 * kCpcaUnitRows), std::min(rows, u1 * kCpcaUnitRows)};
}

CpcaOptions CpcaOptionsFrom(const CompressedTransportHeader& h) {
  CpcaOptions o;
  o.clusters = h.cpca_clusters;
  o.bases = h.cpca_bases;
  o.bits = h.bits;
  o.keep_fraction = h.keep_fraction;
  o.coefficient_bits = h.cpca_coefficient_bits;
  o.seed = h.dither_seed;
  return o;
}

CpcaSparseStructure CpcaSparseStructure::Of(
    std::span<const uint8_t> sample_is_dense,
    std::span<const std::vector<uint32_t>> sample_neighbours, uint32_t channels) {
  const std::size_t V = sample_is_dense.size();
  if (sample_neighbours.size() != V)
    throw std::invalid_argument("CpcaSparseStructure::Of: neighbour lists for every sample");
  CpcaSparseStructure s;
  s.is_dense.resize(V * channels);
  s.neighbours.resize(V * channels);
  for (uint32_t c = 0; c < channels; ++c)
    for (std::size_t v = 0; v < V; ++v) {
      s.is_dense[c * V + v] = sample_is_dense[v] ? 1 : 0;
      if (sample_is_dense[v]) continue;
      for (uint32_t u : sample_neighbours[v]) {
        if (u >= V) throw std::invalid_argument("CpcaSparseStructure::Of: neighbour out of range");
        if (sample_is_dense[u]) s.neighbours[c * V + v].push_back(static_cast<uint32_t>(c * V + u));
      }
    }
  return s;
}

CpcaLocalResult ComputeCpca(const CompressedTransportHeader& h, const CpcaOptions& o,
                            const float* rows, uint64_t first, uint64_t count, CpcaReducer& reducer,
                            const CpcaSparseStructure* sparse,
                            const std::function<void(int, int)>& progress) {
  const double t0 = Now();
  const uint64_t R = h.sample_count;
  const uint32_t d = h.column_count();
  if (o.clusters == 0 || o.clusters > R)
    throw std::invalid_argument("ComputeCpca: clusters must be in [1, rows]");
  if (o.bases > d || o.bases > kMaxCpcaBases)
    throw std::invalid_argument("ComputeCpca: too many bases");
  if (o.bits < 2 || o.bits > 24 || o.coefficient_bits < 2 || o.coefficient_bits > 24)
    throw std::invalid_argument("ComputeCpca: quantiser bits not in [2, 24]");
  if (!(o.keep_fraction > 0) || o.keep_fraction > 1)
    throw std::invalid_argument("ComputeCpca: keep fraction not in (0, 1]");
  if (first % kCpcaUnitRows != 0 || (first + count != R && (first + count) % kCpcaUnitRows != 0) ||
      first + count > R)
    throw std::invalid_argument("ComputeCpca: rows not on unit boundaries");
  if (sparse && (sparse->is_dense.size() != R || sparse->neighbours.size() != R))
    throw std::invalid_argument("ComputeCpca: sparse structure of the wrong size");
  // Eigen picks its GEMM blocking from the cache sizes it detects; fixed sizes make every
  // product, hence every byte, the same on any machine.
  Eigen::setCpuCacheSizes(32 * 1024, 1024 * 1024, 8 * 1024 * 1024);

  const uint32_t K = o.clusters, S = o.bases;
  Clustering cl(h, o, rows, first, count, reducer);
  CpcaLocalResult out;
  CpcaStats& st = out.stats;

  // The rows the LBG stages run on: all (standard) or the dense ones (Huang's dense pass).
  std::vector<uint64_t> pool;
  for (uint64_t r = 0; r < R; ++r)
    if (!sparse || sparse->is_dense[r]) pool.push_back(r);
  if (pool.empty())
    for (uint64_t r = 0; r < R; ++r) pool.push_back(r);  // no dense row: standard
  const bool two_pass = sparse && pool.size() < R;
  for (uint64_t r = 0; r < count; ++r) cl.active()[r] = two_pass ? sparse->is_dense[first + r] : 1;
  st.rows_dense_pass = pool.size();

  const std::vector<uint32_t> dims = StageDims(S);
  const int total_iterations = static_cast<int>(dims.size()) * std::max(1, o.iterations_per_stage) +
                               (two_pass ? std::max(0, o.recluster_iterations) + 1 : 0);
  int done = 0;
  const auto step = [&] {
    ++done;
    ++st.lbg_iterations;
    if (progress) progress(done, total_iterations);
  };
  const auto none = [](uint64_t) { return std::span<const uint32_t>(); };

  // LBG: assign, update; an empty cluster is re-seeded before the next assignment, so that
  // the last step of every pass is an update (means and bases of the final members).
  const int power = std::max(1, o.power_iterations);
  cl.Seed(pool);
  bool first_iteration = true;
  for (uint32_t dim : dims) {
    cl.GrowBasis(dim);
    for (int it = 0; it < std::max(1, o.iterations_per_stage); ++it) {
      if (!first_iteration) cl.Reseed();
      first_iteration = false;
      cl.Assign(none, false);
      cl.Update(dim == 0 ? 0 : power);
      step();
    }
  }
  st.seconds_dense = Now() - t0;

  if (two_pass) {
    const double t1 = Now();
    // The dense rows' clusters, known to every process.
    std::vector<int64_t> dense_cluster(R, 0);
    for (uint64_t r = 0; r < count; ++r)
      if (sparse->is_dense[first + r]) dense_cluster[first + r] = cl.cluster()[r] + 1;
    reducer.SumInt64(dense_cluster);
    // Each sparse row joins its first dense neighbour's cluster (a row without one: the
    // nearest by projection distance, from every cluster), then LBG iterations on all rows.
    std::vector<std::vector<uint32_t>> choices(count);
    std::vector<uint8_t> orphan(count, 0);
    for (uint64_t r = 0; r < count; ++r) {
      cl.active()[r] = 1;
      if (sparse->is_dense[first + r]) continue;
      for (uint32_t u : sparse->neighbours[first + r])
        if (dense_cluster[u] > 0) choices[r].push_back(static_cast<uint32_t>(dense_cluster[u] - 1));
      if (choices[r].empty())
        orphan[r] = 1;
      else
        cl.cluster()[r] = choices[r][0];
    }
    // Orphans (sparse rows none of whose neighbours is dense): a full search once.
    {
      std::vector<uint8_t> keep = cl.active();
      for (uint64_t r = 0; r < count; ++r) cl.active()[r] = orphan[r];
      cl.Assign(none, false);
      cl.active() = keep;
    }
    for (int it = 0; it < std::max(0, o.recluster_iterations); ++it) {
      cl.Update(power);
      cl.Assign([&](uint64_t r) { return std::span<const uint32_t>(choices[r]); }, true);
      step();
    }
    cl.Update(power);
    step();
    st.seconds_recluster = Now() - t1;
  }

  // Store: each cluster's mean and basis truncated to their largest terms and quantised, then
  // every row's least-squares coefficients against the stored basis, quantised per cluster and
  // vector with the largest magnitude over its members.
  const uint32_t keep =
      static_cast<uint32_t>(std::clamp(std::lround(o.keep_fraction * d), 1l, static_cast<long>(d)));
  out.clusters.resize(K);
  std::vector<MatF> Ut(K);               // S × d dequantised basis (transposed)
  std::vector<std::vector<float>> m(K);  // dequantised means
  std::vector<MatD> pinv(K);             // (ŨᵀŨ)⁺
  const uint32_t s_now = cl.dim();
  if (S > 0) cl.ComputeScatter();
  tbb::parallel_for(uint32_t{0}, K, [&](uint32_t c) {
    CpcaCluster& k = out.clusters[c];
    k.basis.resize(S);
    k.coefficient_scale.assign(S, 0.0f);
    std::vector<double> v(d);
    for (uint32_t j = 0; j < d; ++j) v[j] = cl.mean()(c, j);
    if (cl.members()[c] > 0) k.mean = QuantiseVector(v.data(), d, keep, o.bits);
    std::vector<double> dq(d, 0.0);
    Dequantise(k.mean, o.bits, dq.data());
    m[c].assign(dq.begin(), dq.end());
    Ut[c] = MatF::Zero(S, d);
    const double scatter = cl.scatter().empty() ? 0.0 : cl.scatter()[c];
    for (uint32_t i = 0; i < S && i < s_now; ++i) {
      // A vector that captures (next to) nothing of the cluster's scatter is not stored.
      const double var = cl.variance()[static_cast<std::size_t>(c) * s_now + i];
      if (cl.members()[c] < 2 || !(var > 1e-9 * scatter) || !(scatter > 0)) continue;
      for (uint32_t j = 0; j < d; ++j) v[j] = cl.basis()[c](j, i);
      k.basis[i] = QuantiseVector(v.data(), d, keep, o.bits);
      std::fill(dq.begin(), dq.end(), 0.0);
      Dequantise(k.basis[i], o.bits, dq.data());
      for (uint32_t j = 0; j < d; ++j) Ut[c](i, j) = static_cast<float>(dq[j]);
    }
    if (S > 0) {
      const MatD G = (Ut[c].cast<double>() * Ut[c].cast<double>().transpose());
      pinv[c] = G.completeOrthogonalDecomposition().pseudoInverse();
    }
  });

  // Coefficients in double, then the per-cluster, per-vector scales over all processes.
  std::vector<double> w(count * S, 0.0);
  tbb::parallel_for(uint64_t{0}, count, [&](uint64_t r) {
    if (S == 0) return;
    const uint32_t c = cl.cluster()[r];
    Eigen::VectorXf y(d);
    for (uint32_t j = 0; j < d; ++j) y(j) = rows[r * d + j] - m[c][j];
    const Eigen::VectorXd b = (Ut[c] * y).cast<double>();
    const Eigen::VectorXd x = pinv[c] * b;
    for (uint32_t i = 0; i < S; ++i) w[r * S + i] = std::isfinite(x(i)) ? x(i) : 0.0;
  });
  std::vector<double> wmax(static_cast<std::size_t>(K) * S, 0.0);
  for (uint64_t r = 0; r < count; ++r)
    for (uint32_t i = 0; i < S; ++i) {
      double& mx = wmax[static_cast<std::size_t>(cl.cluster()[r]) * S + i];
      mx = std::max(mx, std::fabs(w[r * S + i]));
    }
  reducer.MaxDouble(wmax);
  const int A = MaxQ(o.coefficient_bits);
  for (uint32_t c = 0; c < K; ++c)
    for (uint32_t i = 0; i < S; ++i) {
      const float sc = static_cast<float>(wmax[static_cast<std::size_t>(c) * S + i]);
      out.clusters[c].coefficient_scale[i] = std::isfinite(sc) && sc > 0 ? sc : 0.0f;
    }
  out.cluster_of = cl.cluster();
  out.coefficients.assign(count * S, 0);
  std::vector<double> row_error(count, 0.0), row_energy(count, 0.0);
  tbb::parallel_for(uint64_t{0}, count, [&](uint64_t r) {
    const uint32_t c = cl.cluster()[r];
    std::vector<double> rec(m[c].begin(), m[c].end());
    for (uint32_t i = 0; i < S; ++i) {
      const float sc = out.clusters[c].coefficient_scale[i];
      if (sc == 0) continue;
      const long q = std::clamp<long>(std::lround(w[r * S + i] / sc * A), -A, A);
      out.coefficients[r * S + i] = static_cast<int32_t>(q);
      const double wq = static_cast<double>(q) * sc / A;
      if (wq != 0)
        for (uint32_t j = 0; j < d; ++j) rec[j] += wq * Ut[c](i, j);
    }
    double e = 0, en = 0;
    for (uint32_t j = 0; j < d; ++j) {
      const double x = rows[r * d + j];
      e += (x - rec[j]) * (x - rec[j]);
      en += x * x;
    }
    row_error[r] = e;
    row_energy[r] = en;
  });
  // ‖T̂ − T̃‖² and ‖T̂‖² as fixed-point sums (one rounding per unit): the same on any number of
  // processes.
  double bounds[2] = {0, 0};
  for (uint64_t r = 0; r < count; ++r) {
    bounds[0] = std::max(bounds[0], row_error[r]);
    bounds[1] = std::max(bounds[1], row_energy[r]);
  }
  reducer.MaxDouble(bounds);
  const Fixed fe(bounds[0] * static_cast<double>(R) * 2 + 1e-300);
  const Fixed fn(bounds[1] * static_cast<double>(R) * 2 + 1e-300);
  int64_t sums[2] = {0, 0};
  for (uint64_t u = 0; u < count; u += kCpcaUnitRows) {
    double pe = 0, pn = 0;
    for (uint64_t r = u; r < std::min(count, u + kCpcaUnitRows); ++r) {
      pe += row_error[r];
      pn += row_energy[r];
    }
    sums[0] += fe.To(pe);
    sums[1] += fn.To(pn);
  }
  reducer.SumInt64(sums);
  const double err = fe.From(sums[0]), energy = fn.From(sums[1]);
  st.energy = energy;
  st.relative_error = energy > 0 ? std::sqrt(std::max(0.0, err) / energy) : 0.0;
  st.distance_evaluations = cl.distance_evaluations();
  for (uint32_t c = 0; c < K; ++c) st.empty_clusters += cl.members()[c] == 0 ? 1 : 0;
  st.seconds = Now() - t0;
  return out;
}

CpcaTransport CompressCpca(const float* rows_hat, const CompressedTransportHeader& h,
                           const CpcaOptions& o, const CpcaSparseStructure* sparse,
                           CpcaStats* stats) {
  LocalCpcaReducer local;
  CpcaLocalResult r = ComputeCpca(h, o, rows_hat, 0, h.sample_count, local, sparse);
  CpcaTransport t;
  t.header = h;
  t.header.scheme = CompressionScheme::kCpca;
  t.header.cpca_clusters = o.clusters;
  t.header.cpca_bases = o.bases;
  t.header.cpca_coefficient_bits = static_cast<uint8_t>(o.coefficient_bits);
  t.header.bits = static_cast<uint8_t>(o.bits);
  t.header.keep_fraction = o.keep_fraction;
  t.header.dither_seed = o.seed;
  t.header.terms_per_column = 0;
  t.header.cpca_method = sparse && r.stats.rows_dense_pass < h.sample_count
                             ? CpcaMethod::kDenseRecluster
                             : CpcaMethod::kStandard;
  t.cluster_of = std::move(r.cluster_of);
  t.clusters = std::move(r.clusters);
  t.coefficients = std::move(r.coefficients);
  if (stats) *stats = r.stats;
  ValidateCpcaTransport(t, "CompressCpca");
  return t;
}

}  // namespace prt
