// A sparse-precomputation plan variant from the command line, shared by prt-sparse-bench and
// prt-sparse-gi-bench: "key=value;key=value" applied to the scene's plan.
#pragma once

#include <string>

#include "worker/sparse_precomputation.h"

namespace prt::bench {

struct SparseVariant {
  std::string name;
  SparsePlan plan;
  int indirect_features = 0;  // 0: IndirectFeatures() of the plan's direct features
  int direct_weights = -1;    // -1: the estimator's default; 0 / 1 (SparseIndirectOptions)
  int feature_paths = 0;      // gathering: directions of the sparse vertices' features (0: all)
};

// Keys: budget, initial, iterations, radius (× the scene's), features, min_features (× features
// when < 1), window, lambda, normal_cos, empty_weight, mode (visibility|transport), solver
// (l1|ls), unity (unity_weight), max_residual, rank_floor, ind_features, direct_weights (0|1),
// grid_step. Throws std::invalid_argument on an unknown key or a malformed pair.
SparseVariant ParseSparseVariant(const std::string& spec, const SparsePlan& base);

}  // namespace prt::bench
