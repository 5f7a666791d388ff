// What the viewer needs to use compressed transport (compressed_transport.h) without the worker:
// the column transform over the spatial domain and its coefficient layout, the dither sequence
// and dequantisation (Cheslack-Postava et al. 2008 §4.3), decompression to a dense T for tests,
// and relighting B = T·L straight from the compressed columns (§4.5, Eq. 8).
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
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "vocabulary/compressed_transport.h"
#include "vocabulary/wavelets.h"

namespace prt {

WaveletFilter ToWaveletFilter(RowWavelet w);
WaveletFilter ToWaveletFilter(ColumnWavelet w);

// Largest depth of one segment / of the whole domain (the maximum over segments).
int MaxSegmentDepth(const SpatialSegment& s);
int MaxColumnDepth(const SpatialDomain& d);

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

// Where a relight's per-sample outputs go. kSamples: global sample order (meshes in order, each
// mesh's vertices in its file's order). kCoefficients: the depth-0 coefficient layout, i.e. each
// mesh segment's vertices along its Hilbert order (position k of a segment holds its vertex
// order[k]) and each grid in row-major order: the order the inverse steps leave X in, so that the
// way back is a sequential copy instead of a gather through the permutation. A renderer that
// remaps its vertex buffers once at load (CompressedRelighter::coefficient_of_sample()) then
// takes the relit radiance as it comes (docs/viewer.md, "Relighting speed").
enum class SampleOrder : uint8_t { kSamples, kCoefficients };

// Relighting from adaptively compressed columns (§4.5, Eq. 8). Construction dequantises every
// term once and groups columns by depth; Relight then computes, per channel,
//   B = Σ_l S'_{l→l−1}( Σ_{j∈N(l)} L̂_j · C_j )
// by adding the lights of depth-l columns into one column-wavelet-domain buffer per channel
// (float) and running one single-step inverse per level from the deepest level down (one full
// inverse transform in all, whatever the number of lights); the terms no earlier inverse step
// touches are added in one pass before the first step (RelightLights). Parallel inside (TBB: the
// scatter over tiles of coefficients, from 2^15 terms; the inverse steps and, below 4 MB of X,
// the gather back to sample order run on the calling thread, where X is cached). Thread-compatible
// (const methods are safe to call from several threads with separate outputs).
class CompressedRelighter {
 public:
  explicit CompressedRelighter(const CompressedTransport& t);

  const CompressedTransportHeader& header() const { return header_; }
  std::size_t sample_count() const { return header_.sample_count; }
  std::size_t column_count() const { return header_.column_count(); }
  // Depth chosen for a column (0 for absent/all-zero columns); -1 when absent.
  int ColumnDepth(uint32_t column) const;
  // Stored terms of a column (0 for absent columns).
  std::size_t ColumnTermCount(uint32_t column) const;

  // Sample (global order) → its position in the depth-0 coefficient layout, the position its
  // radiance takes in SampleOrder::kCoefficients outputs.
  std::span<const uint32_t> coefficient_of_sample() const { return coefficient_of_sample_; }

  // Dense lighting in the row-wavelet basis: lighting_hat = channels × column_count floats,
  // radiance = channels × sample_count floats (channel-major, samples in `order`), B = T̂·L̂ per
  // channel.
  void Relight(std::span<const float> lighting_hat, int channels, std::span<float> radiance,
               SampleOrder order = SampleOrder::kSamples) const;
  // Sparse lighting (a non-linear lighting approximation): terms (columns[k], weights[k·channels
  // + c]); columns need not be sorted; duplicates add.
  void RelightSparse(std::span<const uint32_t> columns, std::span<const float> weights,
                     int channels, std::span<float> radiance,
                     SampleOrder order = SampleOrder::kSamples) const;
  // The same, into one double array of sample_count() values per channel (out[c]), with no
  // intermediate float image: what the viewer's TransportOperator accumulates into. Added to
  // out[c]'s values, or with `assign` written over them (out[c] need not be initialised).
  void RelightSparseAdd(std::span<const uint32_t> columns, std::span<const float> weights,
                        int channels, std::span<double* const> out,
                        SampleOrder order = SampleOrder::kSamples, bool assign = false) const;

 private:
  // A column's terms in two parts (see RelightLights): those no inverse step deeper than the
  // column's depth touches, in terms_ (every term of a depth-0 column), and the rest, the
  // low-band coefficients of segments transformed below their maximum depth, in late_terms_.
  struct Column {
    uint8_t depth;
    uint32_t begin, end;            // range in terms_
    uint32_t late_begin, late_end;  // range in late_terms_
  };
  struct Light;
  // Where a frame's radiance goes: channel-major floats, or added into per-channel doubles.
  struct Output {
    float* radiance = nullptr;
    double* const* add = nullptr;
    SampleOrder order = SampleOrder::kSamples;
    bool assign = false;  // with `add`: write instead of adding
  };
  void RelightLights(std::vector<Light>& lights, int channels, Output out) const;
  template <class Index>
  static void Copy(std::size_t lo, std::size_t hi, const float* base, const Index& index,
                   std::size_t C, std::size_t K, std::size_t S, const Output& out);
  std::vector<Light> LightsOf(std::span<const uint32_t> columns, std::span<const float> weights,
                              int channels) const;

  CompressedTransportHeader header_;
  int max_depth_ = 0;
  std::vector<int32_t> slot_;  // column → index into columns_, or −1
  // Sample (global order) → its coefficient in the depth-0 layout (the Hilbert order's inverse).
  std::vector<uint32_t> coefficient_of_sample_;
  std::vector<Column> columns_;
  // Each segment of the domain as the relighter uses it, derived once from the header: its
  // coefficient range [lo, hi) in the global order, its w×h shape (a mesh is count×1) and its
  // maximum depth.
  struct Segment {
    std::size_t lo, hi;
    int w, h, max_depth;
  };
  std::vector<Segment> segments_;
  // A stored term: coefficient index and dequantised value side by side, so that a column is
  // one sequential stream of 8-byte terms.
  struct Term {
    uint32_t index;
    float value;
  };
  std::vector<Term> terms_;
  std::vector<Term> late_terms_;
  // X is scattered tile by tile: tile_ consecutive coefficients (4096, 64 KB of X with three
  // channels, so that every term's read-modify-write stays within L1/L2 of the core that owns
  // the tile), all of a depth's lights per tile.
  // tile_offsets_[slot·(tiles_ + 1) + t] is the first term of column `slot` whose index is at
  // least t·tile_ (its last entry is the column's end).
  std::size_t tile_ = 0, tiles_ = 0;
  std::vector<uint32_t> tile_offsets_;
  // Per-frame buffers (X and the inverse steps' scratch), kept between frames: a fresh
  // allocation of this size is mmap'ed and page-faulted in every frame. A pool, not one pair,
  // since concurrent Relight calls (and a thread that runs another relight while it waits in a
  // parallel loop) each need their own.
  struct FrameBuffers {
    std::vector<float> x, scratch;
    std::vector<bool> low_in_scratch;  // per segment: its low band lives in `scratch`
  };
  std::unique_ptr<FrameBuffers> TakeBuffers() const;
  void ReturnBuffers(std::unique_ptr<FrameBuffers> b) const;
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<FrameBuffers>> pool_;
};

}  // namespace prt
