// The column coding both ends of compressed transport share (formats/compressed_transport.h): the
// column transform over the spatial domain and its coefficient layout, the dither sequence and
// dequantisation (Cheslack-Postava et al. 2008 §4.2–4.3), and decompression to a dense T. The
// farm's compressor (worker/) encodes with it; the viewer's relighter (runtime/compressed_relight.h,
// §4.5 Eq. 8) decodes with it.
//
// Coefficient layout of a column (docs/compression.md): the column is a vector over the spatial
// samples in global order. Segment by segment (at its offset in the global order):
//   mesh (kMesh1D)  values are first permuted into Hilbert order (position k holds vertex
//                   order[k]), then transformed as a w = count, h = 1 region;
//   grid (kGrid2D)  transformed as the w×h region in place (row-major, x fastest).
// The transform is vocabulary/wavelets.h's 2D non-standard decomposition in Mallat layout, to
// depth min(d, segment's maximum depth). At depth 0 the layout is the permuted samples.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "formats/compressed_transport.h"
#include "vocabulary/wavelets.h"

namespace prt {

WaveletFilter ToWaveletFilter(RowWavelet w);
WaveletFilter ToWaveletFilter(ColumnWavelet w);

// Column in global sample order ↔ coefficient layout at `depth` (in place, `column` has
// domain.sample_count() floats). Depth 0 only applies the Hilbert permutation.
void ForwardColumnTransform(const SpatialDomain& domain, ColumnWavelet wavelet, int depth,
                            float* column);
void InverseColumnTransform(const SpatialDomain& domain, ColumnWavelet wavelet, int depth,
                            float* column);
// Single inverse step t (depth t → t − 1) of every segment whose maximum depth is ≥ t; the
// S'_{l→l+1} of Eq. 5–8. Acts on the coefficient layout (no permutation).
void InverseColumnTransformStep(const SpatialDomain& domain, ColumnWavelet wavelet, int step,
                                float* coefficients);
// Permutation between global sample order and depth-0 layout.
void SamplesToCoefficientOrder(const SpatialDomain& domain, const float* samples, float* out);
void CoefficientOrderToSamples(const SpatialDomain& domain, const float* coefficients, float* out);

// levels[i] = wavelets.h level (0 = scaling … depth = finest) of coefficient i at `depth`
// (domain.sample_count() entries).
void ColumnLevelMap(const SpatialDomain& domain, int depth, uint8_t* levels);
// §4.3 non-linear scaling, as a power of √2 per coefficient: scale[i] = level · dim, dim the
// dimension of the coefficient's segment (1 mesh, 2 grid), so that the coefficient is multiplied
// by ScaleFactor(scale[i]) = 2^(level·dim/2). With √2-normalised filters a level-l coefficient of
// a smooth dim-dimensional signal is ∝ 2^(−l·dim/2) (its basis function has 2^(dim·(L−l))
// samples of amplitude 2^(−dim·(L−l)/2)); for a 2D image this is the paper's 2^l.
void ColumnScaleMap(const SpatialDomain& domain, int depth, uint8_t* scale);
inline double ScaleFactor(int half_octaves) {
  const double f = static_cast<double>(uint64_t{1} << (half_octaves / 2));
  return (half_octaves & 1) ? f * 1.4142135623730951 : f;
}

// Subtractive dither offset r ∈ [−1/2, 1/2) for term `index` of column `column`: a pure hash
// of (seed, column, index), the same in encoder and decoder.
double DitherOffset(uint64_t seed, uint32_t column, uint32_t index);
// Largest quantised magnitude for `bits`: A = 2^(bits−1) − 1.
inline int QuantiserMax(int bits) {
  return (1 << (bits - 1)) - 1;
}
// Value of one quantised term, undoing dither, normalisation and the §4.3 scaling:
//   c = (q − r) · scale / A / ScaleFactor(half_octaves).
inline double DequantiseTerm(int32_t q, double dither, double scale, int bits, int half_octaves) {
  return (static_cast<double>(q) - dither) * scale / QuantiserMax(bits) / ScaleFactor(half_octaves);
}
// Column coefficients (coefficient layout at c.depth, sample_count floats) from a compressed
// column. `scale_map` is ColumnScaleMap at c.depth.
void DequantiseColumn(const CompressedTransportHeader& h, const CompressedColumn& c,
                      const uint8_t* scale_map, float* coefficients);

// Dense T̂ (rows = samples, columns = row-wavelet coefficients, sample_count × column_count),
// and dense T in the cubemap texel basis (inverse row transform of every row of T̂).
std::vector<float> DecompressToRowWaveletBasis(const CompressedTransport& t);
std::vector<float> DecompressTransport(const CompressedTransport& t);

// Lighting in the row-wavelet basis: each of `channels` cubemap vectors (6n² floats each,
// channel-major) transformed per face to full depth by the header's row wavelet. With the
// orthonormal row filters, T·L = T̂·L̂.
std::vector<float> LightingToRowWaveletBasis(RowWavelet wavelet, int cubemap_n,
                                             std::span<const float> lighting, int channels);

}  // namespace prt
