// L1-regularised least squares for sparse-vertex reconstruction (Huang & Ramamoorthi 2010, §5.1,
// Eq. 5 solved with an L1 penalty as the paper advocates after Kim et al. 2007):
//
//   minimise  f(α) = ½‖Aα − b‖² + λ‖α‖₁
//
// A is m×k (m constraints = traced feature directions of the sparse vertex, k unknowns = its
// dense neighbours, 10–40), b the traced values. Both solvers work on the Gram form
// G = AᵀA, c = Aᵀb, so the m×k system is touched once.
//
// Primary solver: LARS/homotopy (Osborne et al. 2000; Efron et al. 2004, lasso modification) in
// double precision: follows the piecewise-linear solution path α(λ') from λ' = max|c| down to λ,
// adding the variable whose correlation reaches the active level and dropping a variable whose
// coefficient crosses zero. A variable dropped at one step may not re-enter at the next step
// (the guard against the cycling that returns wrong optima in near-degenerate problems), and a
// variable whose column is linearly dependent on the active set is never added.
// Fallback: ADMM (Boyd et al. 2011, §6.4) with one Cholesky factorisation of G + ρI.
// Every result is checked against the KKT conditions; a result that fails them is reported
// as failed, never returned as an optimum.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

namespace prt {

enum class L1Status : uint8_t {
  kLars = 0,        // homotopy converged and passed the KKT check
  kAdmm = 1,        // homotopy failed the check; ADMM converged and passed it
  kZeroSystem = 2,  // b or A is all zero (α = 0 is optimal, reported separately)
  kFailed = 3,      // neither converged: the caller must not use α
};

struct L1Result {
  std::vector<double> alpha;
  L1Status status = L1Status::kFailed;
  int iterations = 0;        // homotopy steps or ADMM iterations
  double kkt_violation = 0;  // max over i of the KKT residual, relative to max|c|
  double objective = 0;
};

struct L1Options {
  double lambda = 1e-3;    // relative: the penalty is lambda · max|Aᵀb| (scale-free)
  int max_lars_steps = 0;  // 0 = 8·k
  int max_admm_iterations = 20000;
  double kkt_tolerance = 1e-6;  // relative to max|c|
};

// Reusable solver; holds scratch so that millions of solves allocate nothing after warm-up.
class L1Solver {
 public:
  explicit L1Solver(L1Options options = {});
  ~L1Solver();
  L1Solver(const L1Solver&) = delete;
  L1Solver& operator=(const L1Solver&) = delete;

  // A is column-major m×k (A[i + m·j] = row i, column j), b has m entries.
  L1Result Solve(std::span<const double> A, std::span<const double> b, int m, int k);

  // The same problem given as its Gram form (G k×k column-major symmetric, c = Aᵀb,
  // bb = bᵀb for the objective).
  L1Result SolveGram(std::span<const double> G, std::span<const double> c, double bb, int k);

  // Plain least squares (minimum-norm, via complete orthogonal decomposition), the baseline
  // the paper compares against (Fig. 6).
  static std::vector<double> LeastSquares(std::span<const double> A, std::span<const double> b,
                                          int m, int k);

  // KKT residual of α for the Gram problem, relative to max|c| (0 at the exact optimum).
  static double KktViolation(std::span<const double> G, std::span<const double> c,
                             std::span<const double> alpha, double lambda_abs);

 private:
  struct Impl;
  Impl* impl_;
  L1Options options_;
};

}  // namespace prt
