// Row transform of the transport matrix (Cheslack-Postava et al. 2008 §4.1, step 2 of §4.4):
// every row of T is a cubemap vector (6·n² texels, cubemap.h layout) and is transformed per face
// by a 2D non-standard wavelet decomposition to full depth (orthonormal Haar by default, or
// Daubechies-4), in the layout of vocabulary/wavelets.h. Because both filters are orthonormal,
// T·L = T̂·L̂ with L̂ the lighting transformed the same way.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "formats/compressed_transport.h"

namespace prt {

// Full depth of the row transform for cubemap size n (log2 n).
int RowTransformDepth(int cubemap_n);

// `count` rows of 6·n² floats each, in place.
void ForwardRowTransform(RowWavelet wavelet, int cubemap_n, float* rows, std::size_t count);
void InverseRowTransform(RowWavelet wavelet, int cubemap_n, float* rows, std::size_t count);

// levels[j] = row-wavelet level of column j of T̂ (0 = scaling, 1 = coarsest … log2 n = finest),
// 6·n² entries. There are 3·4^(l−1) columns per face at level l ≥ 1 (the paper's "4^l columns").
std::vector<uint8_t> RowCoefficientLevels(int cubemap_n);

// The 2D baseline's non-linear approximation (Ng et al. 2003): in each of `count` rows of `cols`
// floats keep the `keep` coefficients of largest magnitude (ties: lower index first) and set the
// others to zero.
void KeepLargestPerRow(float* rows, std::size_t count, std::size_t cols, std::size_t keep);

}  // namespace prt
