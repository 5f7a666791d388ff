// The compression pipeline of Cheslack-Postava et al. 2008 §4.4 (steps 2–5), in memory.
#include "worker/transport_compressor.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "vocabulary/compressed_relight.h"
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
                                               const SpatialDomain& domain) {
  CompressedTransportHeader h;
  h.cubemap_n = static_cast<uint32_t>(cubemap_n);
  h.sample_count = static_cast<uint32_t>(domain.sample_count());
  h.row_wavelet = o.row_wavelet;
  h.column_wavelet = o.column_wavelet;
  h.scheme = o.scheme;
  h.bits = static_cast<uint8_t>(o.bits);
  h.keep_fraction = o.keep_fraction;
  h.terms_per_column = o.scheme == CompressionScheme::k2D ? 0 : ColumnTermBudget(o, h.sample_count);
  h.dither_seed = o.dither_seed;
  h.domain = domain;
  ValidateHeader(h, "compression options");
  return h;
}

void PrepareRows(const CompressedTransportHeader& h, const CompressionOptions& o, float* rows,
                 std::size_t count) {
  const int n = static_cast<int>(h.cubemap_n);
  const std::size_t M = h.column_count();
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t r) {
    ForwardRowTransform(h.row_wavelet, n, rows + r * M, 1);
    if (h.scheme == CompressionScheme::k2D)
      KeepLargestPerRow(rows + r * M, 1, M, RowTermBudget(o, M));
  });
}

namespace {

// One column through §4.2–4.3.
CompressedColumn CompressOneColumn(const CompressedTransportHeader& h, uint32_t column,
                                   const float* samples, ColumnStats& st) {
  const std::size_t S = h.sample_count;
  thread_local std::vector<float> c;
  thread_local std::vector<uint8_t> levels;
  c.assign(samples, samples + S);
  st = ColumnStats{};
  st.column = column;
  int depth = 0;
  std::size_t budget = h.terms_per_column;
  switch (h.scheme) {
    case CompressionScheme::k2D: {
      // Rows were already truncated (Ng et al. 2003): keep every surviving term.
      budget = S;
      float* p = c.data();
      std::vector<float> tmp(p, p + S);
      SamplesToCoefficientOrder(h.domain, tmp.data(), p);
      break;
    }
    case CompressionScheme::k4D:
      depth = MaxColumnDepth(h.domain);
      ForwardColumnTransform(h.domain, h.column_wavelet, depth, c.data());
      break;
    case CompressionScheme::kAdaptive4D:
      depth = TransformColumnAdaptive(h.domain, h.column_wavelet, budget, c.data());
      break;
  }
  for (float& v : c)
    if (!std::isfinite(v)) throw NumericalError("CompressColumnBlock: non-finite coefficient");
  const ApproximationEnergy e = MeasureApproximation(c.data(), S, budget);
  const std::vector<uint32_t> kept = LargestTerms(c.data(), S, budget);
  levels.resize(S);
  ColumnScaleMap(h.domain, depth, levels.data());
  CompressedColumn out =
      QuantiseColumn(column, depth, c.data(), kept, levels.data(), h.bits, h.dither_seed);
  st.depth = static_cast<uint8_t>(depth);
  st.kept_terms = static_cast<uint32_t>(kept.size());
  st.stored_terms = static_cast<uint32_t>(out.index.size());
  st.kept_energy = e.kept;
  st.total_energy = e.total;
  return out;
}

}  // namespace

std::vector<CompressedColumn> CompressColumnBlock(const CompressedTransportHeader& h,
                                                  uint32_t first_column, uint32_t count,
                                                  const float* columns,
                                                  std::vector<ColumnStats>* stats) {
  const std::size_t S = h.sample_count;
  std::vector<CompressedColumn> all(count);
  std::vector<ColumnStats> st(count);
  tbb::parallel_for(uint32_t{0}, count, [&](uint32_t k) {
    all[k] =
        CompressOneColumn(h, first_column + k, columns + static_cast<std::size_t>(k) * S, st[k]);
  });
  std::vector<CompressedColumn> out;
  for (auto& c : all)
    if (!c.index.empty()) out.push_back(std::move(c));
  if (stats) stats->insert(stats->end(), st.begin(), st.end());
  return out;
}

CompressedTransport CompressTransport(const float* T, int cubemap_n, const SpatialDomain& domain,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats) {
  CompressedTransport out;
  out.header = MakeCompressedHeader(o, cubemap_n, domain);
  const std::size_t S = out.header.sample_count, M = out.header.column_count();
  std::vector<float> rows(T, T + S * M);
  PrepareRows(out.header, o, rows.data(), S);
  // Transpose in column blocks (block_spill.h does the same out of core).
  const uint32_t block = 256;
  std::vector<float> cols;
  for (uint32_t first = 0; first < M; first += block) {
    const uint32_t count = std::min<uint32_t>(block, static_cast<uint32_t>(M - first));
    cols.resize(static_cast<std::size_t>(count) * S);
    for (std::size_t s = 0; s < S; ++s)
      for (uint32_t k = 0; k < count; ++k) cols[k * S + s] = rows[s * M + first + k];
    std::vector<CompressedColumn> c =
        CompressColumnBlock(out.header, first, count, cols.data(), stats);
    for (auto& x : c) out.columns.push_back(std::move(x));
  }
  return out;
}

}  // namespace prt
