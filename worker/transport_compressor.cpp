// The compression pipeline of Cheslack-Postava et al. 2008 §4.4 (steps 2–5), in memory.
#include "worker/transport_compressor.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include "formats/column_coding.h"
#include "vocabulary/errors.h"
#include "worker/adaptive_column_transform.h"
#include "worker/quantisation.h"
#include "worker/row_transform.h"

namespace prt {

CompressionOptions CompressionOptionsFrom(const CompressionSettings& s, const std::string& file) {
  CompressionOptions o;
  o.row_wavelet = ParseRowWavelet(s.row_wavelet, file);
  o.column_wavelet = ParseColumnWavelet(s.column_wavelet, file);
  o.scheme = ParseCompressionScheme(s.scheme, file);
  if (s.bits < 2 || s.bits > 24) throw InputError(file, "compression.bits must be in [2, 24]");
  o.bits = s.bits;
  if (!(s.keep_fraction > 0) || s.keep_fraction > 1)
    throw InputError(file, "compression.keep_fraction must be in (0, 1]");
  o.keep_fraction = s.keep_fraction;
  o.budget = ParseCompressionBudget(s.budget, file);
  if (s.light_weight < 0 || s.light_weight > 16)
    throw InputError(file, "compression.light_weight must be in [0, 16]");
  o.light_weight = s.light_weight;
  o.cpca_clusters = static_cast<uint32_t>(std::max(1, s.clusters));
  o.cpca_bases = static_cast<uint32_t>(std::max(0, s.bases));
  o.cpca_coefficient_bits = s.coefficient_bits;
  return o;
}

uint32_t ColumnTermBudget(const CompressionOptions& o, std::size_t sample_count) {
  if (o.terms_per_column > 0)
    return static_cast<uint32_t>(std::min<std::size_t>(o.terms_per_column, sample_count));
  const double k = std::round(o.keep_fraction * static_cast<double>(sample_count));
  return static_cast<uint32_t>(std::clamp(k, 1.0, static_cast<double>(sample_count)));
}

uint32_t RowTermBudget(const CompressionOptions& o, std::size_t column_count) {
  const double k = std::round(o.keep_fraction * static_cast<double>(column_count));
  return static_cast<uint32_t>(std::clamp(k, 1.0, static_cast<double>(column_count)));
}

CompressedTransportHeader MakeCompressedHeader(const CompressionOptions& o, int cubemap_n,
                                               const SpatialDomain& domain, uint32_t channels) {
  CompressedTransportHeader h;
  h.cubemap_n = static_cast<uint32_t>(cubemap_n);
  h.sample_count = static_cast<uint32_t>(domain.sample_count());
  h.channels = channels;
  h.row_wavelet = o.row_wavelet;
  h.column_wavelet = o.column_wavelet;
  h.scheme = o.scheme;
  h.bits = static_cast<uint8_t>(o.bits);
  h.keep_fraction = o.keep_fraction;
  h.terms_per_column = o.scheme == CompressionScheme::k2D || o.scheme == CompressionScheme::kCpca
                           ? 0
                           : ColumnTermBudget(o, h.sample_count);
  h.dither_seed = o.dither_seed;
  h.budget = o.budget;
  h.light_weight =
      o.budget == CompressionBudget::kGlobal ? static_cast<uint8_t>(o.light_weight) : 0;
  h.domain = domain;
  if (o.scheme == CompressionScheme::kCpca) {
    // More clusters than rows would leave clusters that can never have a member.
    h.cpca_clusters = std::min<uint32_t>(o.cpca_clusters, h.sample_count);
    h.cpca_bases = std::min<uint32_t>(o.cpca_bases, h.column_count());
    h.cpca_coefficient_bits = static_cast<uint8_t>(o.cpca_coefficient_bits);
    h.cpca_method = o.cpca_method;
  }
  ValidateHeader(h, "compression options");
  return h;
}

void PrepareRows(const CompressedTransportHeader& h, const CompressionOptions& o, float* rows,
                 std::size_t count) {
  const int n = static_cast<int>(h.cubemap_n);
  const std::size_t M = h.column_count();
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t r) {
    ForwardRowTransform(h.row_wavelet, n, rows + r * M, 1);
    if (h.scheme == CompressionScheme::k2D && h.budget == CompressionBudget::kColumn)
      KeepLargestPerRow(rows + r * M, 1, M, RowTermBudget(o, M));
  });
}

namespace {

// §4.2: one column, sample order in, coefficient layout out; returns its depth.
int TransformOneColumn(const CompressedTransportHeader& h, float* c) {
  const std::size_t S = h.sample_count;
  int depth = 0;
  switch (h.scheme) {
    case CompressionScheme::k2D: {
      thread_local std::vector<float> tmp;
      tmp.assign(c, c + S);
      SamplesToCoefficientOrder(h.domain, tmp.data(), c);
      break;
    }
    case CompressionScheme::k4D:
      depth = MaxColumnDepth(h.domain);
      ForwardColumnTransform(h.domain, h.column_wavelet, depth, c);
      break;
    case CompressionScheme::kAdaptive4D:
      depth = TransformColumnAdaptive(h.domain, h.column_wavelet, h.terms_per_column, c);
      break;
    case CompressionScheme::kCpca:
      throw std::invalid_argument("the column stage does not apply to scheme cpca (worker/cpca.h)");
  }
  for (std::size_t i = 0; i < S; ++i)
    if (!std::isfinite(c[i])) throw NumericalError("CompressColumnBlock: non-finite coefficient");
  return depth;
}

// Non-linear approximation and §4.3 quantisation of one transformed column: the column's
// per-column budget, or every |c| ≥ threshold when threshold > 0 (global budget).
CompressedColumn QuantiseOneColumn(const CompressedTransportHeader& h, uint32_t column, int depth,
                                   const float* c, float threshold, ColumnStats& st) {
  const std::size_t S = h.sample_count;
  // 2D with a per-row budget: the rows were truncated already, keep every surviving term.
  const std::size_t budget = h.scheme == CompressionScheme::k2D ? S : h.terms_per_column;
  std::vector<uint32_t> kept;
  ApproximationEnergy e;
  if (threshold > 0) {
    const float w = ColumnWeight(h, column);
    for (std::size_t i = 0; i < S; ++i) {
      const double v = static_cast<double>(c[i]) * c[i];
      e.total += v;
      if (c[i] != 0.0f && std::fabs(c[i]) * w >= threshold) {
        kept.push_back(static_cast<uint32_t>(i));
        e.kept += v;
      }
    }
  } else {
    e = MeasureApproximation(c, S, budget);
    kept = LargestTerms(c, S, budget);
  }
  thread_local std::vector<uint8_t> scale;
  scale.resize(S);
  ColumnScaleMap(h.domain, depth, scale.data());
  CompressedColumn out =
      QuantiseColumn(column, depth, c, kept, scale.data(), h.bits, h.dither_seed);
  st = ColumnStats{};
  st.column = column;
  st.depth = static_cast<uint8_t>(depth);
  st.kept_terms = static_cast<uint32_t>(kept.size());
  st.stored_terms = static_cast<uint32_t>(out.index.size());
  st.kept_energy = e.kept;
  st.total_energy = e.total;
  return out;
}

}  // namespace

void TransformColumnBlock(const CompressedTransportHeader& h, uint32_t count, float* columns,
                          uint8_t* depths) {
  const std::size_t S = h.sample_count;
  tbb::parallel_for(uint32_t{0}, count, [&](uint32_t k) {
    depths[k] =
        static_cast<uint8_t>(TransformOneColumn(h, columns + static_cast<std::size_t>(k) * S));
  });
}

std::vector<CompressedColumn> QuantiseColumnBlock(const CompressedTransportHeader& h,
                                                  uint32_t first_column, uint32_t count,
                                                  const float* transformed, const uint8_t* depths,
                                                  float threshold,
                                                  std::vector<ColumnStats>* stats) {
  const std::size_t S = h.sample_count;
  std::vector<CompressedColumn> all(count);
  std::vector<ColumnStats> st(count);
  tbb::parallel_for(uint32_t{0}, count, [&](uint32_t k) {
    all[k] = QuantiseOneColumn(h, first_column + k, depths[k],
                               transformed + static_cast<std::size_t>(k) * S, threshold, st[k]);
  });
  std::vector<CompressedColumn> out;
  for (auto& c : all)
    if (!c.index.empty()) out.push_back(std::move(c));
  if (stats) stats->insert(stats->end(), st.begin(), st.end());
  return out;
}

std::vector<CompressedColumn> CompressColumnBlock(const CompressedTransportHeader& h,
                                                  uint32_t first_column, uint32_t count,
                                                  const float* columns,
                                                  std::vector<ColumnStats>* stats) {
  std::vector<float> c(columns, columns + static_cast<std::size_t>(count) * h.sample_count);
  std::vector<uint8_t> depths(count);
  TransformColumnBlock(h, count, c.data(), depths.data());
  return QuantiseColumnBlock(h, first_column, count, c.data(), depths.data(), 0.0f, stats);
}

double ColumnBlockError(const CompressedTransportHeader& h, uint32_t first_column, uint32_t count,
                        const float* columns, const uint8_t* depths,
                        std::span<const CompressedColumn> compressed) {
  const std::size_t S = h.sample_count;
  std::vector<const CompressedColumn*> of(count, nullptr);
  for (const CompressedColumn& c : compressed) {
    if (c.column < first_column || c.column >= first_column + count)
      throw std::invalid_argument("ColumnBlockError: compressed column outside the block");
    of[c.column - first_column] = &c;
  }
  return tbb::parallel_reduce(
      tbb::blocked_range<uint32_t>(0, count), 0.0,
      [&](const tbb::blocked_range<uint32_t>& r, double acc) {
        std::vector<float> y(S);
        std::vector<uint8_t> scale(S);
        for (uint32_t k = r.begin(); k != r.end(); ++k) {
          const float* x = columns + static_cast<std::size_t>(k) * S;
          const CompressedColumn* c = of[k];
          std::fill(y.begin(), y.end(), 0.0f);
          if (c != nullptr) {
            ColumnScaleMap(h.domain, c->depth, scale.data());
            DequantiseColumn(h, *c, scale.data(), y.data());
          }
          if (depths != nullptr) {
            // The transform is linear: x − x̃ = W⁻¹(c − ĉ), one inverse transform per column.
            if (c != nullptr && c->depth != depths[k])
              throw std::logic_error("ColumnBlockError: compressed at another depth");
            for (std::size_t i = 0; i < S; ++i) y[i] = x[i] - y[i];
            InverseColumnTransform(h.domain, h.column_wavelet, depths[k], y.data());
            for (std::size_t i = 0; i < S; ++i) acc += double(y[i]) * y[i];
          } else {
            if (c != nullptr)
              InverseColumnTransform(h.domain, h.column_wavelet, c->depth, y.data());
            for (std::size_t i = 0; i < S; ++i) {
              const double d = double(x[i]) - y[i];
              acc += d * d;
            }
          }
        }
        return acc;
      },
      [](double a, double b) { return a + b; });
}

float GlobalThreshold(const float* coefficients, std::size_t n, std::size_t keep) {
  std::vector<float> mag;
  mag.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    if (coefficients[i] != 0.0f) mag.push_back(std::fabs(coefficients[i]));
  if (mag.empty()) return 0.0f;
  if (keep == 0) return std::numeric_limits<float>::infinity();
  if (keep >= mag.size()) return *std::min_element(mag.begin(), mag.end());
  std::nth_element(mag.begin(), mag.begin() + (keep - 1), mag.end(), std::greater<float>());
  return mag[keep - 1];
}

void AddMagnitudeHistogram(const float* coefficients, std::size_t n, uint64_t* histogram) {
  for (std::size_t i = 0; i < n; ++i) {
    uint32_t u;
    std::memcpy(&u, &coefficients[i], 4);
    u &= 0x7fffffffu;
    if (u != 0) ++histogram[u >> 16];
  }
}

float ColumnWeight(const CompressedTransportHeader& h, uint32_t column) {
  if (h.light_weight == 0) return 1.0f;
  thread_local std::vector<uint8_t> levels;
  thread_local uint32_t levels_n = 0;
  if (levels_n != h.cubemap_n) {
    levels = RowCoefficientLevels(static_cast<int>(h.cubemap_n));
    levels_n = h.cubemap_n;
  }
  return static_cast<float>(1.0 / ScaleFactor(h.light_weight * levels[column]));
}

void AddColumnBlockHistogram(const CompressedTransportHeader& h, uint32_t first_column,
                             uint32_t count, const float* transformed, uint64_t* histogram) {
  const std::size_t S = h.sample_count;
  std::vector<float> v(S);
  for (uint32_t k = 0; k < count; ++k) {
    const float w = ColumnWeight(h, first_column + k);
    const float* c = transformed + static_cast<std::size_t>(k) * S;
    for (std::size_t i = 0; i < S; ++i) v[i] = std::fabs(c[i]) * w;
    AddMagnitudeHistogram(v.data(), S, histogram);
  }
}

float ThresholdFromHistogram(const uint64_t* histogram, uint64_t keep) {
  uint64_t count = 0;
  std::size_t bin = kMagnitudeBins;
  while (bin > 0) {
    --bin;
    count += histogram[bin];
    if (count >= keep && histogram[bin] > 0) break;
  }
  // Lower edge of the bin (at least the smallest positive float: zeros are never kept).
  const uint32_t u = std::max<uint32_t>(static_cast<uint32_t>(bin) << 16, 1u);
  float t;
  std::memcpy(&t, &u, 4);
  return t;
}

uint64_t GlobalTermBudget(const CompressedTransportHeader& h) {
  const double k = std::round(h.keep_fraction * static_cast<double>(h.sample_count) *
                              static_cast<double>(h.column_count()));
  return static_cast<uint64_t>(std::max(1.0, k));
}

CompressedTransport CompressTransport(const float* T, int cubemap_n, const SpatialDomain& domain,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats) {
  return CompressTransport(T, MakeCompressedHeader(o, cubemap_n, domain), o, stats);
}

CompressedTransport CompressTransport(const float* T, const CompressedTransportHeader& h,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats) {
  ValidateHeader(h, "CompressTransport");
  CompressedTransport out;
  out.header = h;
  const std::size_t S = out.header.sample_count, M = out.header.column_count();
  std::vector<float> rows(T, T + S * M);
  PrepareRows(out.header, o, rows.data(), S);
  // Transpose (block_spill.h does the same out of core) and transform every column.
  std::vector<float> cols(S * M);
  for (std::size_t s = 0; s < S; ++s)
    for (std::size_t j = 0; j < M; ++j) cols[j * S + s] = rows[s * M + j];
  rows = std::vector<float>();
  std::vector<uint8_t> depths(M);
  TransformColumnBlock(out.header, static_cast<uint32_t>(M), cols.data(), depths.data());
  float threshold = 0.0f;
  if (o.budget == CompressionBudget::kGlobal) {
    std::vector<uint64_t> hist(kMagnitudeBins, 0);
    AddColumnBlockHistogram(out.header, 0, static_cast<uint32_t>(M), cols.data(), hist.data());
    threshold = ThresholdFromHistogram(hist.data(), GlobalTermBudget(out.header));
  }
  out.columns = QuantiseColumnBlock(out.header, 0, static_cast<uint32_t>(M), cols.data(),
                                    depths.data(), threshold, stats);
  return out;
}

}  // namespace prt
