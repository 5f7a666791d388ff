// Scaling and dithered scalar quantisation of a column (Cheslack-Postava et al. 2008 §4.3).
// The kept coefficients (chosen by the non-linear approximation on the ORIGINAL coefficients) are
// scaled by f = 2^(l·d/2), l their column-transform level (wavelets.h: 0 = scaling … finest) and d
// their segment's dimension (1 mesh, 2 grid; the paper's 2^l for 2D images), normalised by
// the column's largest scaled magnitude m, and quantised to `bits` bits with subtractive dither:
//   u = f·c / m ∈ [−1, 1],  A = 2^(bits−1) − 1,  r = DitherOffset(seed, column, index) ∈ [−½, ½)
//   q = ⌊u·A + r + ½⌋ ∈ [−A, A],   û = (q − r) / A.
// The error û − u is uniform in (−Δ/2, Δ/2] with Δ = 1/A, independent of u (RMS Δ/√12). Terms
// with q = 0 are dropped (they decode to 0, error |u| < Δ).
#pragma once

#include <cstdint>
#include <span>

#include "formats/compressed_transport.h"

namespace prt {

// One normalised value u ∈ [−1, 1] with dither r ∈ [−½, ½).
int32_t QuantiseDithered(double u, double dither, int bits);
double DequantiseDithered(int32_t q, double dither, int bits);

// Compressed column from its coefficients (coefficient layout at `depth`), the sorted positions
// kept by the non-linear approximation, and the level map at that depth. Returns a column with
// no terms when every kept term quantises to zero.
CompressedColumn QuantiseColumn(uint32_t column, int depth, const float* coefficients,
                                std::span<const uint32_t> kept, const uint8_t* scale_map, int bits,
                                uint64_t dither_seed);

}  // namespace prt
