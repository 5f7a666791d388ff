#include "worker/l1_solver.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace prt {
namespace {

struct Problem {
  int m = 0, k = 0;
  std::vector<double> A, b;  // column-major
};

// Independent reference: cyclic coordinate descent on the same objective, run to a tight
// tolerance (no shared code with the homotopy or ADMM paths).
std::vector<double> CoordinateDescent(const Problem& p, double lambda_abs) {
  std::vector<double> x(p.k, 0.0), r(p.b), colsq(p.k, 0.0);
  for (int j = 0; j < p.k; ++j)
    for (int i = 0; i < p.m; ++i) colsq[j] += p.A[i + p.m * j] * p.A[i + p.m * j];
  for (int sweep = 0; sweep < 20000; ++sweep) {
    double change = 0, scale = 1e-300;
    for (int j = 0; j < p.k; ++j) {
      if (colsq[j] == 0) continue;
      double rho = 0;
      for (int i = 0; i < p.m; ++i) rho += p.A[i + p.m * j] * r[i];
      rho += colsq[j] * x[j];
      const double nx =
          (rho > lambda_abs ? rho - lambda_abs : (rho < -lambda_abs ? rho + lambda_abs : 0)) /
          colsq[j];
      const double dx = nx - x[j];
      if (dx != 0)
        for (int i = 0; i < p.m; ++i) r[i] -= p.A[i + p.m * j] * dx;
      x[j] = nx;
      change = std::max(change, std::abs(dx) * std::sqrt(colsq[j]));
      scale = std::max(scale, std::abs(nx) * std::sqrt(colsq[j]));
    }
    if (change <= 1e-15 * scale) break;
  }
  return x;
}

double ObjectiveOf(const Problem& p, const std::vector<double>& x, double lambda_abs) {
  double f = 0;
  for (int i = 0; i < p.m; ++i) {
    double r = -p.b[i];
    for (int j = 0; j < p.k; ++j) r += p.A[i + p.m * j] * x[j];
    f += 0.5 * r * r;
  }
  for (double v : x) f += lambda_abs * std::abs(v);
  return f;
}

double LambdaAbs(const Problem& p, double lambda) {
  double cmax = 0;
  for (int j = 0; j < p.k; ++j) {
    double c = 0;
    for (int i = 0; i < p.m; ++i) c += p.A[i + p.m * j] * p.b[i];
    cmax = std::max(cmax, std::abs(c));
  }
  return lambda * cmax;
}

// Transport-like problems: columns are neighbours' visibility × cosine rows at the traced
// feature directions; b is a sparse combination of them plus noise.
Problem TransportLike(std::mt19937& rng, int m, int k, double dup_noise, int duplicates) {
  Problem p{m, k, std::vector<double>(static_cast<std::size_t>(m) * k), std::vector<double>(m, 0)};
  std::uniform_real_distribution<double> u(0, 1);
  for (int j = 0; j < k; ++j)
    for (int i = 0; i < m; ++i) p.A[i + m * j] = (u(rng) < 0.6 ? 1.0 : 0.0) * u(rng);
  for (int d = 0; d < duplicates && d + 1 < k; ++d)  // near-duplicate neighbours
    for (int i = 0; i < m; ++i) p.A[i + m * (d + 1)] = p.A[i + m * d] + dup_noise * (u(rng) - 0.5);
  for (int t = 0; t < 3; ++t) {
    const int j = static_cast<int>(u(rng) * k) % k;
    const double w = 0.2 + u(rng);
    for (int i = 0; i < m; ++i) p.b[i] += w * p.A[i + m * j];
  }
  for (int i = 0; i < m; ++i) p.b[i] += 0.01 * (u(rng) - 0.5);
  return p;
}

// Optimality certificate computed here from A and b directly (independent of the solver's own
// Gram-form check): the lasso KKT conditions Aᵀ(b − Aα) = λ·sign(α) on the support and
// |Aᵀ(b − Aα)| ≤ λ off it, relative to max|Aᵀb|.
double IndependentKkt(const Problem& p, const std::vector<double>& x, double lambda_abs) {
  std::vector<double> r(p.b);
  for (int j = 0; j < p.k; ++j)
    for (int i = 0; i < p.m; ++i) r[i] -= p.A[i + p.m * j] * x[j];
  double worst = 0;
  for (int j = 0; j < p.k; ++j) {
    double g = 0;
    for (int i = 0; i < p.m; ++i) g += p.A[i + p.m * j] * r[i];
    worst = std::max(worst, x[j] != 0 ? std::abs(g - std::copysign(lambda_abs, x[j]))
                                      : std::max(0.0, std::abs(g) - lambda_abs));
  }
  const double cmax = LambdaAbs(p, 1.0);  // max|Aᵀb|
  return cmax > 0 ? worst / cmax : worst;
}

// compare_objective: also run coordinate descent and compare objectives (only for problems
// where it converges in reasonable time: not for near-duplicate columns).
void ExpectOptimal(const Problem& p, const L1Result& r, double lambda, const char* what, int trial,
                   bool compare_objective) {
  ASSERT_NE(r.status, L1Status::kFailed) << what << " trial " << trial;
  for (double a : r.alpha) ASSERT_TRUE(std::isfinite(a));
  const double lam = LambdaAbs(p, lambda);
  EXPECT_LE(IndependentKkt(p, r.alpha, lam), 1e-6) << what << " trial " << trial;
  EXPECT_LE(r.kkt_violation, 1e-6) << what << " trial " << trial;
  if (compare_objective) {
    const std::vector<double> ref = CoordinateDescent(p, lam);
    const double f = ObjectiveOf(p, r.alpha, lam), fref = ObjectiveOf(p, ref, lam);
    EXPECT_LE(f, fref + 1e-9 * std::max(1.0, std::abs(fref)))
        << what << " trial " << trial << " status " << int(r.status);
  }
}

// Orthonormal design: the lasso solution is the soft-thresholded correlation, in closed form.
TEST(L1Solver, OrthonormalDesignIsSoftThreshold) {
  const int k = 5;
  std::vector<double> G(k * k, 0.0), c = {3.0, -0.5, 0.01, -2.0, 0.0};
  for (int i = 0; i < k; ++i) G[i * k + i] = 1.0;
  L1Options o;
  o.lambda = 0.25;  // λ_abs = 0.75
  L1Solver s(o);
  const L1Result r = s.SolveGram(G, c, 20.0, k);
  ASSERT_EQ(r.status, L1Status::kLars);
  const double expect[k] = {2.25, 0.0, 0.0, -1.25, 0.0};
  for (int i = 0; i < k; ++i) EXPECT_NEAR(r.alpha[i], expect[i], 1e-14) << i;
}

TEST(L1Solver, MatchesIndependentSolverOnRandomProblems) {
  std::mt19937 rng(42);
  L1Solver s;
  int lars = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    const int k = 10 + trial % 31, m = 100 + (trial * 7) % 260;
    const Problem p = TransportLike(rng, m, k, 0, 0);
    const L1Result r = s.Solve(p.A, p.b, m, k);
    lars += r.status == L1Status::kLars;
    ExpectOptimal(p, r, 1e-3, "random", trial, true);
    if (HasFatalFailure() || HasNonfatalFailure()) return;
  }
  EXPECT_GE(lars, 990);  // the homotopy itself solves nearly all of them exactly
}

TEST(L1Solver, NearDegenerateAndDuplicatedNeighbours) {
  std::mt19937 rng(7);
  L1Solver s;
  for (int trial = 0; trial < 1000; ++trial) {
    const int k = 10 + trial % 31, m = 350;
    const double noise = trial % 3 == 0 ? 0.0 : (trial % 3 == 1 ? 1e-9 : 1e-5);
    const Problem p = TransportLike(rng, m, k, noise, 1 + trial % 5);
    const L1Result r = s.Solve(p.A, p.b, m, k);
    ExpectOptimal(p, r, 1e-3, "near-degenerate", trial, false);
    if (HasFatalFailure() || HasNonfatalFailure()) return;
  }
}

TEST(L1Solver, RankDeficientAndUnderdetermined) {
  std::mt19937 rng(3);
  L1Options o;
  o.lambda = 1e-2;
  L1Solver s(o);
  for (int trial = 0; trial < 200; ++trial) {
    const int k = 40, m = 8 + trial % 30;  // fewer equations than unknowns
    const Problem p = TransportLike(rng, m, k, 0, 0);
    ExpectOptimal(p, s.Solve(p.A, p.b, m, k), 1e-2, "underdetermined", trial, trial < 20);
    if (HasFatalFailure() || HasNonfatalFailure()) return;
  }
}

// Values from 1e-8 to 1e8: the penalty is relative, so the solution scales exactly.
TEST(L1Solver, ScaleInvariantFrom1em8To1e8) {
  std::mt19937 rng(11);
  const Problem base = TransportLike(rng, 200, 20, 0, 0);
  L1Solver s;
  const L1Result r0 = s.Solve(base.A, base.b, base.m, base.k);
  ASSERT_EQ(r0.status, L1Status::kLars);
  for (double scale : {1e-8, 1e-4, 1e4, 1e8}) {
    Problem p = base;
    for (double& v : p.b) v *= scale;  // α scales with b
    const L1Result r = s.Solve(p.A, p.b, p.m, p.k);
    ASSERT_NE(r.status, L1Status::kFailed) << scale;
    for (int j = 0; j < p.k; ++j) EXPECT_NEAR(r.alpha[j] / scale, r0.alpha[j], 1e-9) << scale;
    Problem q = base;
    for (double& v : q.A) v *= scale;  // α scales with 1/A
    const L1Result rq = s.Solve(q.A, q.b, q.m, q.k);
    ASSERT_NE(rq.status, L1Status::kFailed) << scale;
    for (int j = 0; j < q.k; ++j) EXPECT_NEAR(rq.alpha[j] * scale, r0.alpha[j], 1e-9) << scale;
  }
}

TEST(L1Solver, AllZeroSystemsGiveZero) {
  L1Solver s;
  std::vector<double> A(350 * 20, 0.0), b(350, 0.0);
  L1Result r = s.Solve(A, b, 350, 20);
  EXPECT_EQ(r.status, L1Status::kZeroSystem);
  for (double a : r.alpha) EXPECT_EQ(a, 0.0);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  for (double& v : A) v = u(rng);  // b = 0 with a real A: α = 0 is optimal
  r = s.Solve(A, b, 350, 20);
  EXPECT_EQ(r.status, L1Status::kZeroSystem);
  for (double a : r.alpha) EXPECT_EQ(a, 0.0);
}

TEST(L1Solver, NonFiniteInputIsRejected) {
  L1Solver s;
  std::vector<double> A(10 * 3, 1.0), b(10, 1.0);
  A[4] = std::nan("");
  EXPECT_EQ(s.Solve(A, b, 10, 3).status, L1Status::kFailed);
}

// L1 keeps the weights sparse where least squares over-fits (the paper's §5.1 observation):
// with few constraints, LS spreads weight over every neighbour.
TEST(L1Solver, SparserThanLeastSquares) {
  std::mt19937 rng(5);
  const Problem p = TransportLike(rng, 30, 30, 0, 0);
  L1Options o;
  o.lambda = 1e-2;
  L1Solver s(o);
  const L1Result r = s.Solve(p.A, p.b, p.m, p.k);
  const std::vector<double> ls = L1Solver::LeastSquares(p.A, p.b, p.m, p.k);
  auto nnz = [](const std::vector<double>& v) {
    return std::count_if(v.begin(), v.end(), [](double x) { return std::abs(x) > 1e-9; });
  };
  EXPECT_LT(nnz(r.alpha), nnz(ls) / 2);
}

}  // namespace
}  // namespace prt
