#include "bench/sparse_variant.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace prt::bench {

SparseVariant ParseSparseVariant(const std::string& spec, const SparsePlan& base) {
  SparseVariant v{spec, base, 0, -1, 0};
  std::stringstream ss(spec);
  for (std::string kv; std::getline(ss, kv, ';');) {
    if (kv.empty()) continue;
    const std::size_t eq = kv.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("--variant: expected key=value: " + kv);
    const std::string key = kv.substr(0, eq), val = kv.substr(eq + 1);
    const double x = (val == "visibility" || val == "transport" || val == "l1" || val == "ls")
                         ? 0.0
                         : std::stod(val);
    if (key == "budget") {
      v.plan.dense_budget = x;
    } else if (key == "initial") {
      v.plan.initial_fraction = x;
    } else if (key == "iterations") {
      v.plan.iterations = static_cast<int>(x);
    } else if (key == "radius") {
      v.plan.radius = base.radius * x;
    } else if (key == "features") {
      v.plan.sparse.features = static_cast<int>(std::lround(x));
    } else if (key == "min_features") {
      v.plan.sparse.min_features =
          static_cast<int>(std::lround(x < 1 ? x * v.plan.sparse.features : x));
    } else if (key == "grid_step") {
      v.plan.angular.grid_step = static_cast<int>(x);
    } else if (key == "window") {
      v.plan.angular.window = static_cast<int>(x);
    } else if (key == "lambda") {
      v.plan.sparse.lambda = x;
    } else if (key == "normal_cos") {
      v.plan.sparse.min_normal_cos = x;
    } else if (key == "unity") {
      v.plan.sparse.unity_weight = x;
    } else if (key == "max_residual") {
      v.plan.sparse.max_residual = x;
    } else if (key == "empty_weight") {
      v.plan.empty_weight = static_cast<int>(x);
    } else if (key == "rank_floor") {
      v.plan.rank_floor = static_cast<int>(x);
    } else if (key == "feature_paths") {
      v.feature_paths = static_cast<int>(x);
    } else if (key == "direct_weights") {
      v.direct_weights = static_cast<int>(x);
    } else if (key == "ind_features") {
      v.indirect_features = static_cast<int>(x);
    } else if (key == "mode") {
      v.plan.sparse.mode =
          val == "transport" ? InterpolationMode::kTransport : InterpolationMode::kVisibility;
    } else if (key == "solver") {
      v.plan.sparse.solver = val == "ls" ? SolverKind::kLeastSquares : SolverKind::kL1;
    } else {
      throw std::invalid_argument("--variant: unknown key " + key);
    }
  }
  return v;
}

}  // namespace prt::bench
