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

struct L1Solver::Impl {
  Mat G;
  Vec c;
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
  impl_->G.noalias() = Am.transpose() * Am;
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
  std::vector<int> active;
  std::vector<double> sign;
  std::vector<char> in_active(static_cast<std::size_t>(k), 0),
      dependent(static_cast<std::size_t>(k), 0);
  int last_dropped = -1;
  bool lars_ok = false;
  {
    Vec g = c;
    Eigen::Index first;
    double lam = g.cwiseAbs().maxCoeff(&first);
    if (lam <= lambda) {
      lars_ok = true;  // α = 0 is optimal
    } else {
      active.push_back(static_cast<int>(first));
      sign.push_back(g[first] > 0 ? 1.0 : -1.0);
      in_active[static_cast<std::size_t>(first)] = 1;
      const int max_steps = options_.max_lars_steps > 0 ? options_.max_lars_steps : 8 * k + 8;
      int step = 0;
      for (; step < max_steps; ++step) {
        const int s = static_cast<int>(active.size());
        Mat Gaa(s, s);
        Vec sa(s);
        for (int i = 0; i < s; ++i) {
          sa[i] = sign[static_cast<std::size_t>(i)];
          for (int j = 0; j < s; ++j)
            Gaa(i, j) = G(active[static_cast<std::size_t>(i)], active[static_cast<std::size_t>(j)]);
        }
        Eigen::LDLT<Mat> ldlt(Gaa);
        const Vec piv = ldlt.vectorD().cwiseAbs();
        if (ldlt.info() != Eigen::Success || piv.minCoeff() <= 1e-12 * piv.maxCoeff()) {
          // The variable just added is (numerically) dependent on the active set: drop it for
          // good and continue from the same point of the path.
          const int j = active.back();
          active.pop_back();
          sign.pop_back();
          in_active[static_cast<std::size_t>(j)] = 0;
          dependent[static_cast<std::size_t>(j)] = 1;
          if (active.empty()) break;
          continue;
        }
        const Vec d = ldlt.solve(sa);
        Vec a = Vec::Zero(k);
        for (int i = 0; i < s; ++i) a += G.col(active[static_cast<std::size_t>(i)]) * d[i];
        g = c - G * alpha;
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
          if (d[i] == 0) continue;
          const double t = -alpha[j] / d[i];
          if (t > tiny && t < gamma) {
            gamma = t;
            event = i;
            drop = true;
          }
        }
        for (int i = 0; i < s; ++i) alpha[active[static_cast<std::size_t>(i)]] += gamma * d[i];
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
          if (active.empty()) {
            // Path restarts from α = 0 at the current λ.
            const Vec g2 = c - G * alpha;
            Eigen::Index nxt;
            g2.cwiseAbs().maxCoeff(&nxt);
            if (std::abs(g2[nxt]) <= lambda) {
              lars_ok = true;
              break;
            }
          }
        } else {
          const Vec g2 = c - G * alpha;
          active.push_back(event);
          sign.push_back(g2[event] > 0 ? 1.0 : -1.0);
          in_active[static_cast<std::size_t>(event)] = 1;
          last_dropped = -1;
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
