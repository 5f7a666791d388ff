// Row transform of T (Cheslack-Postava et al. 2008 §4.1) and the per-row non-linear
// approximation of the 2D baseline (Ng et al. 2003). Transforms come from vocabulary/wavelets.h.
#include "worker/row_transform.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "formats/column_coding.h"
#include "vocabulary/wavelets.h"

namespace prt {

int RowTransformDepth(int cubemap_n) {
  return WaveletMaxDepth(WaveletFilter::kHaar, cubemap_n);
}

void ForwardRowTransform(RowWavelet wavelet, int cubemap_n, float* rows, std::size_t count) {
  const std::size_t M = static_cast<std::size_t>(6) * cubemap_n * cubemap_n;
  const int depth = RowTransformDepth(cubemap_n);
  for (std::size_t r = 0; r < count; ++r)
    ForwardWaveletCubemap(ToWaveletFilter(wavelet), rows + r * M, cubemap_n, depth);
}

void InverseRowTransform(RowWavelet wavelet, int cubemap_n, float* rows, std::size_t count) {
  const std::size_t M = static_cast<std::size_t>(6) * cubemap_n * cubemap_n;
  const int depth = RowTransformDepth(cubemap_n);
  for (std::size_t r = 0; r < count; ++r)
    InverseWaveletCubemap(ToWaveletFilter(wavelet), rows + r * M, cubemap_n, depth);
}

std::vector<uint8_t> RowCoefficientLevels(int cubemap_n) {
  const std::size_t F = static_cast<std::size_t>(cubemap_n) * cubemap_n;
  std::vector<uint8_t> levels(6 * F);
  CoefficientLevelMap2D(cubemap_n, cubemap_n, RowTransformDepth(cubemap_n), levels.data());
  for (int f = 1; f < 6; ++f) std::copy(levels.begin(), levels.begin() + F, levels.begin() + f * F);
  return levels;
}

void KeepLargestPerRow(float* rows, std::size_t count, std::size_t cols, std::size_t keep) {
  if (keep >= cols) return;
  std::vector<uint32_t> idx(cols);
  for (std::size_t r = 0; r < count; ++r) {
    float* row = rows + r * cols;
    std::iota(idx.begin(), idx.end(), 0u);
    auto larger = [row](uint32_t a, uint32_t b) {
      const float fa = std::fabs(row[a]), fb = std::fabs(row[b]);
      return fa > fb || (fa == fb && a < b);
    };
    std::nth_element(idx.begin(), idx.begin() + keep, idx.end(), larger);
    for (std::size_t k = keep; k < cols; ++k) row[idx[k]] = 0.0f;
  }
}

}  // namespace prt
