// In-memory compression of the transport matrix T into adaptive 4D wavelet form
// (Cheslack-Postava et al. 2008 §4): rows → row transform (§4.1) → columns → adaptive column
// transform (§4.2) → non-linear approximation → 2^(l·d/2) scaling, normalisation, dithered
// quantisation (§4.3) → compressed columns (vocabulary/compressed_transport.h). The 2D baseline
// (Ng et al. 2003) and full non-adaptive 4D run through the same code. The stages are exposed
// separately so that the farm can run them on row blocks and column blocks (worker/block_spill.h)
// without ever holding T. Inverse: vocabulary/compressed_relight.h (DecompressTransport).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/compressed_transport.h"
#include "vocabulary/scene.h"

namespace prt {

struct CompressionOptions {
  RowWavelet row_wavelet = RowWavelet::kHaar;
  ColumnWavelet column_wavelet = ColumnWavelet::kLeGall53;
  CompressionScheme scheme = CompressionScheme::kAdaptive4D;
  int bits = 9;
  // Non-linear approximation budget as a fraction of T: each column keeps round(f·samples)
  // terms (2D: each row keeps round(f·columns)), at least 1. The paper's user-specified N-term
  // approximation per column (§4.4).
  double keep_fraction = 0.05;
  uint32_t terms_per_column = 0;  // when > 0, overrides keep_fraction for the column budget
  // Not in the paper: keep the round(f·samples·columns) largest coefficients of the whole
  // transformed matrix instead of N per column (2D: instead of per row). The per-column budget
  // still decides each column's depth. In memory only (the farm would need a global threshold).
  bool global_budget = false;
  uint64_t dither_seed = 1;
};

// From the scene file's [compression] table; throws InputError(file, ...) on bad names/values.
CompressionOptions CompressionOptionsFrom(const CompressionSettings& s, const std::string& file);

// Header for T with `sample_count` rows over `domain` and cubemap size n (validated).
CompressedTransportHeader MakeCompressedHeader(const CompressionOptions& o, int cubemap_n,
                                               const SpatialDomain& domain);
// Per-column and per-row budgets in terms.
uint32_t ColumnTermBudget(const CompressionOptions& o, std::size_t sample_count);
uint32_t RowTermBudget(const CompressionOptions& o, std::size_t column_count);

// Row stage (§4.1): `count` rows of 6n² texels in place → T̂ rows; for the 2D scheme also the
// per-row non-linear approximation.
void PrepareRows(const CompressedTransportHeader& h, const CompressionOptions& o, float* rows,
                 std::size_t count);

// What the column stage decided for one column.
struct ColumnStats {
  uint32_t column = 0;
  uint8_t depth = 0;
  uint32_t kept_terms = 0;    // by the non-linear approximation
  uint32_t stored_terms = 0;  // after dropping q = 0
  double kept_energy = 0;     // in the coefficient domain at `depth`
  double total_energy = 0;
};

// Column stage (§4.2–4.3) on `count` columns first_column… of T̂, column-major
// (columns[k·samples + s]). Returns the non-empty compressed columns in column order; stats
// (optional) gets one entry per column. Parallel over columns (TBB), deterministic.
std::vector<CompressedColumn> CompressColumnBlock(const CompressedTransportHeader& h,
                                                  uint32_t first_column, uint32_t count,
                                                  const float* columns,
                                                  std::vector<ColumnStats>* stats = nullptr);
// The same in two halves: column transforms to each column's depth (in place, §4.2), then
// non-linear approximation and quantisation (§4.3) with the per-column budget (threshold 0) or
// keeping every |c| ≥ threshold (global budget).
void TransformColumnBlock(const CompressedTransportHeader& h, uint32_t count, float* columns,
                          uint8_t* depths);
std::vector<CompressedColumn> QuantiseColumnBlock(const CompressedTransportHeader& h,
                                                  uint32_t first_column, uint32_t count,
                                                  const float* transformed, const uint8_t* depths,
                                                  float threshold,
                                                  std::vector<ColumnStats>* stats = nullptr);
// The keep-th largest non-zero |c| of n coefficients (the global budget's threshold).
float GlobalThreshold(const float* coefficients, std::size_t n, std::size_t keep);

// The whole pipeline in memory: T is samples × 6n², row-major, in the cubemap texel basis.
CompressedTransport CompressTransport(const float* T, int cubemap_n, const SpatialDomain& domain,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats = nullptr);

}  // namespace prt
