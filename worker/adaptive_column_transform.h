// Adaptive-depth column transform (Cheslack-Postava et al. 2008 §4.2 and §4.4 step 4).
// A column of T̂ (one row-wavelet coefficient for every spatial sample) is transformed over the
// spatial domain (formats/column_coding.h) to every depth 0 … max in turn; at each depth
// the column's `budget`-term non-linear approximation is measured on the original (unscaled)
// coefficients. The chosen depth keeps the largest fraction of the column's energy; when several
// depths keep all of it (at most `budget` non-zeros) the one with the fewest terms wins. Every
// depth is examined, since sparsity can fluctuate with depth (§4.4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "formats/compressed_transport.h"

namespace prt {

// The `budget`-term non-linear approximation of one coefficient vector.
struct ApproximationEnergy {
  double kept = 0;         // sum of the `budget` largest squares
  double total = 0;        // sum of all squares
  uint32_t terms = 0;      // min(budget, non-zeros)
  bool keeps_all = false;  // non-zeros ≤ budget
  double kept_fraction() const { return total > 0 ? kept / total : 1.0; }
};
ApproximationEnergy MeasureApproximation(const float* c, std::size_t n, std::size_t budget);

// Positions of the `budget` largest |c[i]| among the non-zeros (ties: lower index first),
// sorted ascending.
std::vector<uint32_t> LargestTerms(const float* c, std::size_t n, std::size_t budget);

// The §4.2 rule on measurements at depths 0 … per_depth.size() − 1.
int PickDepth(std::span<const ApproximationEnergy> per_depth);

// Transforms `column` (sample order in, coefficient layout out) to the depth PickDepth chooses
// and returns it; per_depth (optional) receives the measurements at every depth.
int TransformColumnAdaptive(const SpatialDomain& domain, ColumnWavelet wavelet, std::size_t budget,
                            float* column, std::vector<ApproximationEnergy>* per_depth = nullptr);

}  // namespace prt
