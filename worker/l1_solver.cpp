#include "worker/l1_solver.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>

namespace prt {

namespace {
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;
using CMap = Eigen::Map<const Mat>;
using CVecMap = Eigen::Map<const Vec>;

double SoftThreshold(double x, double t) {
  return x > t ? x - t : (x < -t ? x + t : 0.0);
}

double Objective(const Mat& G, const Vec& c, double bb, const Vec& a, double lambda) {
  // ½‖Aα − b‖² = ½αᵀGα − cᵀα + ½bᵀb
  return 0.5 * a.dot(G * a) - c.dot(a) + 0.5 * bb + lambda * a.lpNorm<1>();
}

double Kkt(const Mat& G, const Vec& c, const Vec& a, double lambda, double scale) {
  const Vec g = c - G * a;
  double worst = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    const double r = a[i] != 0 ? std::abs(g[i] - lambda * (a[i] > 0 ? 1.0 : -1.0))
                               : std::max(0.0, std::abs(g[i]) - lambda);
    worst = std::max(worst, r);
  }
  return scale > 0 ? worst / scale : worst;
}

// Exact optimum on a given support with given signs: G_SS α_S = c_S − λ s_S. Returns false
// when the system is singular or the signs come out inconsistent.
bool PolishOnSupport(const Mat& G, const Vec& c, double lambda, const std::vector<int>& support,
                     const std::vector<double>& signs, Vec& alpha) {
  const int s = static_cast<int>(support.size());
  alpha.setZero();
  if (s == 0) return true;
  Mat Gs(s, s);
  Vec rhs(s);
  for (int i = 0; i < s; ++i) {
    rhs[i] = c[support[i]] - lambda * signs[i];
    for (int j = 0; j < s; ++j) Gs(i, j) = G(support[i], support[j]);
  }
  Eigen::LDLT<Mat> ldlt(Gs);
  if (ldlt.info() != Eigen::Success) return false;
  const Vec d = ldlt.vectorD().cwiseAbs();
  if (d.minCoeff() <= 1e-13 * std::max(d.maxCoeff(), std::numeric_limits<double>::min()))
    return false;
  const Vec x = ldlt.solve(rhs);
  for (int i = 0; i < s; ++i) {
    if (!std::isfinite(x[i]) || x[i] * signs[i] < 0) return false;
    alpha[support[i]] = x[i];
  }
  return true;
}
}  // namespace

// Cholesky factor L (G_AA = L Lᵀ) of the Gram block of LARS's active set, in the order the
// variables entered.
class ActiveCholesky {
 public:
  void Reset(int k) {
    k_ = k;
    s_ = 0;
    max_pivot_ = 0;
    L_.assign(static_cast<std::size_t>(k) * static_cast<std::size_t>(k), 0.0);
  }
  // Appends variable j to the factor of `active` (the variables of its rows, in order). Returns
  // false and changes nothing when j's column is numerically dependent on them: its pivot (the
  // squared new diagonal, what an LDLᵀ factorisation would give) ≤ 1e-12 × the largest pivot.
  bool Append(const Mat& G, const std::vector<int>& active, int j) {
    double* row = &L_[static_cast<std::size_t>(s_) * k_];
    double pivot = G(j, j);
    for (int i = 0; i < s_; ++i) {
      const double* li = &L_[static_cast<std::size_t>(i) * k_];
      double v = G(active[static_cast<std::size_t>(i)], j);
      for (int q = 0; q < i; ++q) v -= li[q] * row[q];
      row[i] = v / li[i];
      pivot -= row[i] * row[i];
    }
    if (!(pivot > 1e-12 * std::max(max_pivot_, G(j, j))) || !std::isfinite(pivot)) return false;
    row[s_] = std::sqrt(pivot);
    max_pivot_ = std::max(max_pivot_, pivot);
    ++s_;
    return true;
  }
  // Factors `active` afresh (after a variable left): Append reads only the first s_ entries,
  // the prefix already factored.
  bool Refactor(const Mat& G, const std::vector<int>& active) {
    s_ = 0;
    max_pivot_ = 0;
    for (int j : active)
      if (!Append(G, active, j)) return false;
    return true;
  }
  // x = (L Lᵀ)⁻¹ b over the factor's s entries.
  void Solve(const double* b, double* x) const {
    for (int i = 0; i < s_; ++i) {
      const double* li = &L_[static_cast<std::size_t>(i) * k_];
      double v = b[i];
      for (int q = 0; q < i; ++q) v -= li[q] * x[q];
      x[i] = v / li[i];
    }
    for (int i = s_ - 1; i >= 0; --i) {
      double v = x[i];
      for (int r = i + 1; r < s_; ++r) v -= L_[static_cast<std::size_t>(r) * k_ + i] * x[r];
      x[i] = v / L_[static_cast<std::size_t>(i) * k_ + i];
    }
  }

 private:
  int k_ = 0, s_ = 0;
  double max_pivot_ = 0;
  std::vector<double> L_;  // row-major k×k; row i holds L's row i in columns 0..i
};

struct L1Solver::Impl {
  Mat G;
  Vec c;
  ActiveCholesky chol;
};

L1Solver::L1Solver(L1Options options) : impl_(new Impl), options_(options) {}
L1Solver::~L1Solver() {
  delete impl_;
}

double L1Solver::KktViolation(std::span<const double> G, std::span<const double> c,
                              std::span<const double> alpha, double lambda_abs) {
  const int k = static_cast<int>(c.size());
  const Mat Gm = CMap(G.data(), k, k);
  const Vec cv = CVecMap(c.data(), k);
  const Vec av = CVecMap(alpha.data(), k);
  return Kkt(Gm, cv, av, lambda_abs, cv.cwiseAbs().maxCoeff());
}

std::vector<double> L1Solver::LeastSquares(std::span<const double> A, std::span<const double> b,
                                           int m, int k) {
  const Mat Am = CMap(A.data(), m, k);
  const Vec bv = CVecMap(b.data(), m);
  Eigen::CompleteOrthogonalDecomposition<Mat> cod(Am);
  const Vec x = cod.solve(bv);
  std::vector<double> out(static_cast<std::size_t>(k));
  for (int i = 0; i < k; ++i) out[static_cast<std::size_t>(i)] = std::isfinite(x[i]) ? x[i] : 0.0;
  return out;
}

L1Result L1Solver::Solve(std::span<const double> A, std::span<const double> b, int m, int k) {
  const Mat Am = CMap(A.data(), m, k);
  const Vec bv = CVecMap(b.data(), m);
  // AᵀA through its lower triangle (half the work of the full product), mirrored.
  impl_->G.setZero(k, k);
  impl_->G.selfadjointView<Eigen::Lower>().rankUpdate(Am.transpose());
  impl_->G.triangularView<Eigen::StrictlyUpper>() = impl_->G.transpose();
  impl_->c.noalias() = Am.transpose() * bv;
  return SolveGram({impl_->G.data(), static_cast<std::size_t>(k) * k},
                   {impl_->c.data(), static_cast<std::size_t>(k)}, bv.squaredNorm(), k);
}

L1Result L1Solver::SolveGram(std::span<const double> Gs, std::span<const double> cs, double bb,
                             int k) {
  L1Result result;
  result.alpha.assign(static_cast<std::size_t>(k), 0.0);
  const Mat G = CMap(Gs.data(), k, k);
  const Vec c = CVecMap(cs.data(), k);
  const double cmax = k > 0 ? c.cwiseAbs().maxCoeff() : 0.0;
  if (k == 0 || !(cmax > 0) || !std::isfinite(cmax) || !G.allFinite()) {
    result.status =
        (k > 0 && std::isfinite(cmax) && G.allFinite()) ? L1Status::kZeroSystem : L1Status::kFailed;
    result.objective = 0.5 * bb;
    return result;
  }
  const double lambda = options_.lambda * cmax;
  const double tiny = 1e-14 * cmax;
  Vec alpha = Vec::Zero(k);

  // ---- LARS / homotopy ----
  // The active set's Gram block is held as its Cholesky factor, extended by one row when a
  // variable enters (O(s²)) and refactored when one leaves (rare), instead of a fresh
  // factorisation of G_AA at every step (O(s³) per step, ~40 steps).
  std::vector<int> active;
  std::vector<double> sign;
  std::vector<char> in_active(static_cast<std::size_t>(k), 0),
      dependent(static_cast<std::size_t>(k), 0);
  ActiveCholesky& chol = impl_->chol;
  chol.Reset(k);
  int last_dropped = -1;
  bool lars_ok = false;
  {
    Vec g = c;
    Vec a(k);
    std::vector<double> d(static_cast<std::size_t>(k));
    Eigen::Index first;
    double lam = g.cwiseAbs().maxCoeff(&first);
    if (lam <= lambda) {
      lars_ok = true;  // α = 0 is optimal
    } else if (chol.Append(G, active, static_cast<int>(first))) {
      active.push_back(static_cast<int>(first));
      sign.push_back(g[first] > 0 ? 1.0 : -1.0);
      in_active[static_cast<std::size_t>(first)] = 1;
      const int max_steps = options_.max_lars_steps > 0 ? options_.max_lars_steps : 8 * k + 8;
      int step = 0;
      for (; step < max_steps; ++step) {
        const int s = static_cast<int>(active.size());
        chol.Solve(sign.data(), d.data());  // d = G_AA⁻¹ s_A
        a.setZero();
        for (int i = 0; i < s; ++i)
          a += G.col(active[static_cast<std::size_t>(i)]) * d[static_cast<std::size_t>(i)];
        g.noalias() = c - G * alpha;
        double gamma = lam - lambda;  // default: reach the target λ
        int event = -1;
        bool drop = false;
        for (int j = 0; j < k; ++j) {
          if (in_active[static_cast<std::size_t>(j)] || dependent[static_cast<std::size_t>(j)] ||
              j == last_dropped)
            continue;
          const double den1 = 1.0 - a[j], den2 = 1.0 + a[j];
          if (den1 > 1e-12) {
            const double t = (lam - g[j]) / den1;
            if (t > tiny && t < gamma) {
              gamma = t;
              event = j;
              drop = false;
            }
          }
          if (den2 > 1e-12) {
            const double t = (lam + g[j]) / den2;
            if (t > tiny && t < gamma) {
              gamma = t;
              event = j;
              drop = false;
            }
          }
        }
        for (int i = 0; i < s; ++i) {
          const int j = active[static_cast<std::size_t>(i)];
          const double di = d[static_cast<std::size_t>(i)];
          if (di == 0) continue;
          const double t = -alpha[j] / di;
          if (t > tiny && t < gamma) {
            gamma = t;
            event = i;
            drop = true;
          }
        }
        for (int i = 0; i < s; ++i)
          alpha[active[static_cast<std::size_t>(i)]] += gamma * d[static_cast<std::size_t>(i)];
        lam -= gamma;
        if (event < 0) {
          lars_ok = true;
          break;
        }
        if (drop) {
          const int j = active[static_cast<std::size_t>(event)];
          alpha[j] = 0;
          in_active[static_cast<std::size_t>(j)] = 0;
          active.erase(active.begin() + event);
          sign.erase(sign.begin() + event);
          last_dropped = j;
          // A principal block of a positive definite block: refactoring cannot fail but for
          // rounding; if it does, the homotopy gives up and ADMM takes over.
          if (!chol.Refactor(G, active)) break;
          if (active.empty()) {
            // Path restarts from α = 0 at the current λ.
            g.noalias() = c - G * alpha;
            Eigen::Index nxt;
            g.cwiseAbs().maxCoeff(&nxt);
            if (std::abs(g[nxt]) <= lambda) {
              lars_ok = true;
              break;
            }
          }
        } else if (chol.Append(G, active, event)) {
          g.noalias() = c - G * alpha;
          active.push_back(event);
          sign.push_back(g[event] > 0 ? 1.0 : -1.0);
          in_active[static_cast<std::size_t>(event)] = 1;
          last_dropped = -1;
        } else {
          // The variable is (numerically) dependent on the active set: never add it, and go on
          // from the same point of the path.
          dependent[static_cast<std::size_t>(event)] = 1;
        }
      }
      result.iterations = step + 1;
    }
    if (lars_ok && !active.empty()) {
      // Recompute the final coefficients exactly on the active set (removes accumulated drift).
      Vec polished(k);
      if (PolishOnSupport(G, c, lambda, active, sign, polished)) alpha = polished;
    }
  }
  double kkt = Kkt(G, c, alpha, lambda, cmax);
  if (lars_ok && alpha.allFinite() && kkt <= options_.kkt_tolerance) {
    result.status = L1Status::kLars;
  } else {
    // ---- ADMM fallback (Boyd et al. 2011, §6.4) ----
    const double rho = std::max(G.diagonal().mean(), 1e-300);
    Mat M = G;
    M.diagonal().array() += rho;
    Eigen::LLT<Mat> llt(M);
    Vec x = Vec::Zero(k), z = Vec::Zero(k), u = Vec::Zero(k), zold(k);
    int it = 0;
    bool converged = false;
    for (; it < options_.max_admm_iterations; ++it) {
      x = llt.solve(c + rho * (z - u));
      zold = z;
      for (int i = 0; i < k; ++i) z[i] = SoftThreshold(x[i] + u[i], lambda / rho);
      u += x - z;
      const double pri = (x - z).norm(), dual = rho * (z - zold).norm();
      const double eps = 1e-10 * std::max({x.norm(), z.norm(), 1e-300});
      if (pri <= eps && dual <= eps * rho) {
        converged = true;
        break;
      }
      if ((it & 63) == 63 && Kkt(G, c, z, lambda, cmax) <= 0.1 * options_.kkt_tolerance) {
        converged = true;
        break;
      }
    }
    result.iterations = it + 1;
    // Polish on ADMM's support: exact when ADMM found the right support and signs.
    std::vector<int> supp;
    std::vector<double> sg;
    for (int i = 0; i < k; ++i)
      if (z[i] != 0) {
        supp.push_back(i);
        sg.push_back(z[i] > 0 ? 1.0 : -1.0);
      }
    Vec polished(k);
    if (PolishOnSupport(G, c, lambda, supp, sg, polished) &&
        Kkt(G, c, polished, lambda, cmax) < Kkt(G, c, z, lambda, cmax))
      z = polished;
    kkt = Kkt(G, c, z, lambda, cmax);
    (void)converged;
    if (z.allFinite() && kkt <= options_.kkt_tolerance) {
      alpha = z;
      result.status = L1Status::kAdmm;
    } else {
      result.status = L1Status::kFailed;
      alpha.setZero();
    }
  }
  result.kkt_violation = kkt;
  result.objective = Objective(G, c, bb, alpha, lambda);
  for (int i = 0; i < k; ++i) result.alpha[static_cast<std::size_t>(i)] = alpha[i];
  return result;
}

}  // namespace prt
