// Column transform over the spatial domain and dequantisation (Cheslack-Postava et al. 2008 §4.2,
// §4.3). docs/compression.md.
#include "formats/column_coding.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

WaveletFilter ToWaveletFilter(RowWavelet w) {
  return w == RowWavelet::kHaar ? WaveletFilter::kHaar : WaveletFilter::kDaubechies4;
}
WaveletFilter ToWaveletFilter(ColumnWavelet w) {
  return w == ColumnWavelet::kLeGall53 ? WaveletFilter::kLeGall53 : WaveletFilter::kCdf97;
}

void SamplesToCoefficientOrder(const SpatialDomain& domain, const float* samples, float* out) {
  std::size_t off = 0;
  for (const auto& s : domain.segments) {
    if (s.kind == SpatialSegment::Kind::kMesh1D && !s.order.empty()) {
      for (uint32_t k = 0; k < s.count; ++k) out[off + k] = samples[off + s.order[k]];
    } else {
      std::copy(samples + off, samples + off + s.count, out + off);
    }
    off += s.count;
  }
}

void CoefficientOrderToSamples(const SpatialDomain& domain, const float* coefficients, float* out) {
  std::size_t off = 0;
  for (const auto& s : domain.segments) {
    if (s.kind == SpatialSegment::Kind::kMesh1D && !s.order.empty()) {
      for (uint32_t k = 0; k < s.count; ++k) out[off + s.order[k]] = coefficients[off + k];
    } else {
      std::copy(coefficients + off, coefficients + off + s.count, out + off);
    }
    off += s.count;
  }
}

// §4.2: each segment is transformed separately to min(depth, its maximum depth).
void ForwardColumnTransform(const SpatialDomain& domain, ColumnWavelet wavelet, int depth,
                            float* column) {
  const std::size_t n = domain.sample_count();
  std::vector<float> tmp(n);
  SamplesToCoefficientOrder(domain, column, tmp.data());
  std::copy(tmp.begin(), tmp.end(), column);
  std::size_t off = 0;
  const WaveletFilter f = ToWaveletFilter(wavelet);
  for (const auto& s : domain.segments) {
    int w, h;
    SegmentShape(s, w, h);
    const int d = std::min(depth, MaxSegmentDepth(s));
    if (d > 0) ForwardWavelet2D(f, column + off, w, h, d);
    off += s.count;
  }
}

void InverseColumnTransform(const SpatialDomain& domain, ColumnWavelet wavelet, int depth,
                            float* column) {
  std::size_t off = 0;
  const WaveletFilter f = ToWaveletFilter(wavelet);
  for (const auto& s : domain.segments) {
    int w, h;
    SegmentShape(s, w, h);
    const int d = std::min(depth, MaxSegmentDepth(s));
    if (d > 0) InverseWavelet2D(f, column + off, w, h, d);
    off += s.count;
  }
  const std::size_t n = domain.sample_count();
  std::vector<float> tmp(column, column + n);
  CoefficientOrderToSamples(domain, tmp.data(), column);
}

void InverseColumnTransformStep(const SpatialDomain& domain, ColumnWavelet wavelet, int step,
                                float* coefficients) {
  std::size_t off = 0;
  const WaveletFilter f = ToWaveletFilter(wavelet);
  for (const auto& s : domain.segments) {
    int w, h;
    SegmentShape(s, w, h);
    if (step <= MaxSegmentDepth(s)) InverseWavelet2DStep(f, coefficients + off, w, h, step);
    off += s.count;
  }
}

void ColumnLevelMap(const SpatialDomain& domain, int depth, uint8_t* levels) {
  std::size_t off = 0;
  for (const auto& s : domain.segments) {
    int w, h;
    SegmentShape(s, w, h);
    const int d = std::min(depth, MaxSegmentDepth(s));
    CoefficientLevelMap2D(w, h, d, levels + off);
    off += s.count;
  }
}

void ColumnScaleMap(const SpatialDomain& domain, int depth, uint8_t* scale) {
  ColumnLevelMap(domain, depth, scale);
  std::size_t off = 0;
  for (const auto& s : domain.segments) {
    const int dim = s.kind == SpatialSegment::Kind::kGrid2D ? 2 : 1;
    for (uint32_t i = 0; i < s.count; ++i)
      scale[off + i] = static_cast<uint8_t>(scale[off + i] * dim);
    off += s.count;
  }
}

double DitherOffset(uint64_t seed, uint32_t column, uint32_t index) {
  const uint64_t h = SplitMix64(SplitMix64(seed ^ 0x5851f42d4c957f2dull) ^
                                ((static_cast<uint64_t>(column) << 32) | index));
  return static_cast<double>(h >> 11) * 0x1.0p-53 - 0.5;
}

void DequantiseColumn(const CompressedTransportHeader& h, const CompressedColumn& c,
                      const uint8_t* scale_map, float* coefficients) {
  std::fill(coefficients, coefficients + h.sample_count, 0.0f);
  for (std::size_t k = 0; k < c.index.size(); ++k) {
    const uint32_t i = c.index[k];
    coefficients[i] = static_cast<float>(DequantiseTerm(
        c.q[k], DitherOffset(h.dither_seed, c.column, i), c.scale, h.bits, scale_map[i]));
  }
}

std::vector<float> DecompressToRowWaveletBasis(const CompressedTransport& t) {
  const auto& h = t.header;
  const std::size_t S = h.sample_count, M = h.column_count();
  std::vector<float> dense(S * M, 0.0f);
  std::vector<float> col(S);
  std::vector<uint8_t> levels(S);
  int levels_depth = -1;
  for (const auto& c : t.columns) {
    if (c.depth != levels_depth) {
      ColumnScaleMap(h.domain, c.depth, levels.data());
      levels_depth = c.depth;
    }
    DequantiseColumn(h, c, levels.data(), col.data());
    InverseColumnTransform(h.domain, h.column_wavelet, c.depth, col.data());
    for (std::size_t s = 0; s < S; ++s) dense[s * M + c.column] = col[s];
  }
  return dense;
}

std::vector<float> DecompressTransport(const CompressedTransport& t) {
  std::vector<float> dense = DecompressToRowWaveletBasis(t);
  const int n = static_cast<int>(t.header.cubemap_n);
  const int depth = WaveletMaxDepth(WaveletFilter::kHaar, n);
  const std::size_t M = t.header.column_count();
  for (std::size_t s = 0; s < t.header.sample_count; ++s)
    InverseWaveletCubemap(ToWaveletFilter(t.header.row_wavelet), dense.data() + s * M, n, depth);
  return dense;
}

std::vector<float> LightingToRowWaveletBasis(RowWavelet wavelet, int cubemap_n,
                                             std::span<const float> lighting, int channels) {
  const std::size_t M = static_cast<std::size_t>(6) * cubemap_n * cubemap_n;
  if (channels < 1 || lighting.size() != M * static_cast<std::size_t>(channels))
    throw std::invalid_argument("LightingToRowWaveletBasis: lighting size != channels·6n²");
  std::vector<float> out(lighting.begin(), lighting.end());
  const int depth = WaveletMaxDepth(WaveletFilter::kHaar, cubemap_n);
  for (int c = 0; c < channels; ++c)
    ForwardWaveletCubemap(ToWaveletFilter(wavelet), out.data() + c * M, cubemap_n, depth);
  return out;
}

}  // namespace prt
