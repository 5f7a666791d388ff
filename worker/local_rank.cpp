#include "worker/local_rank.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "vocabulary/hash.h"

namespace prt {

double HashUniform(uint64_t seed, uint64_t a, uint64_t b) {
  const uint64_t h = SplitMix64(SplitMix64(SplitMix64(seed) ^ a) ^ (b * 0xD6E8FEB86659FD93ull));
  return static_cast<double>(h >> 11) * 0x1.0p-53;
}

int LocalRank(std::span<const float* const> rows, std::size_t dim, double rel_threshold) {
  const Eigen::Index k = static_cast<Eigen::Index>(rows.size());
  if (k == 0 || dim == 0) return 0;
  // Gram matrix of the rows (float products, vectorised by Eigen; the rows are averages of
  // values in [0, 1/π], far from float's limits), then σ_i² as its eigenvalues in double.
  Eigen::MatrixXf M(k, static_cast<Eigen::Index>(dim));
  for (Eigen::Index i = 0; i < k; ++i)
    M.row(i) = Eigen::Map<const Eigen::RowVectorXf>(rows[static_cast<std::size_t>(i)],
                                                    static_cast<Eigen::Index>(dim));
  const Eigen::MatrixXd G = (M * M.transpose()).cast<double>();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(G, Eigen::EigenvaluesOnly);
  const Eigen::VectorXd ev = es.eigenvalues().cwiseMax(0.0);  // σ² ascending
  const double smax2 = ev.maxCoeff();
  if (!(smax2 > 0)) return 0;
  const double thr2 = rel_threshold * rel_threshold * smax2;
  int rank = 0;
  for (Eigen::Index i = 0; i < ev.size(); ++i) rank += ev[i] > thr2;
  return rank;
}

void DownsampleRow(const float* row, int n, int m, float* out) {
  const int f = n / m;
  const double inv = 1.0 / (static_cast<double>(f) * f);
  for (int face = 0; face < 6; ++face) {
    for (int y = 0; y < m; ++y) {
      for (int x = 0; x < m; ++x) {
        double s = 0;
        for (int dy = 0; dy < f; ++dy) {
          const float* r = row + (static_cast<std::size_t>(face) * n + (y * f + dy)) * n + x * f;
          for (int dx = 0; dx < f; ++dx) s += r[dx];
        }
        out[(static_cast<std::size_t>(face) * m + y) * m + x] = static_cast<float>(s * inv);
      }
    }
  }
}

std::vector<uint32_t> WeightedSampleWithoutReplacement(std::span<const uint32_t> ids,
                                                       std::span<const double> weights,
                                                       std::size_t count, uint64_t seed) {
  const std::size_t n = ids.size();
  count = std::min(count, n);
  // key = log(u)/w (monotone in u^(1/w)); non-positive weights get −∞ − rank so they come last
  // in a deterministic order.
  std::vector<std::pair<double, uint32_t>> keyed(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double u = std::max(HashUniform(seed, ids[i]), 1e-300);
    const double w = weights[i];
    keyed[i] = {w > 0 ? std::log(u) / w : -1e300 * (1 + u), ids[i]};
  }
  std::partial_sort(keyed.begin(), keyed.begin() + static_cast<std::ptrdiff_t>(count), keyed.end(),
                    [](const auto& a, const auto& b) {
                      return a.first != b.first ? a.first > b.first : a.second < b.second;
                    });
  std::vector<uint32_t> out(count);
  for (std::size_t i = 0; i < count; ++i) out[i] = keyed[i].second;
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace prt
