// In-memory compression of the transport matrix T into adaptive 4D wavelet form
// (Cheslack-Postava et al. 2008 §4): rows → row transform (§4.1) → columns → adaptive column
// transform (§4.2) → non-linear approximation → 2^(l·d/2) scaling, normalisation, dithered
// quantisation (§4.3) → compressed columns (formats/compressed_transport.h). The 2D baseline
// (Ng et al. 2003) and full non-adaptive 4D run through the same code. The stages are exposed
// separately so that the farm can run them on row blocks and column blocks (worker/block_spill.h)
// without ever holding T. Inverse: formats/column_coding.h (DecompressTransport).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "formats/compressed_transport.h"
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
  // kColumn: the paper's N terms per column (2D: per row). kGlobal (not in the paper): keep
  // about round(f·samples·columns) coefficients of the whole transformed matrix, those at or above
  // a magnitude threshold (MagnitudeHistogram, ThresholdFromHistogram); the per-column budget
  // still decides each column's depth. docs/compression.md.
  CompressionBudget budget = CompressionBudget::kColumn;
  // Global budget only: rank magnitudes of row level l by |c|·2^(−light_weight·l/2), favouring
  // the coarse row-wavelet columns that carry most of the relit radiance under natural lighting.
  int light_weight = 0;
  uint64_t dither_seed = 1;
  // scheme kCpca (worker/cpca.h): clusters, bases per cluster, coefficient bits, method.
  uint32_t cpca_clusters = 64;
  uint32_t cpca_bases = 16;
  int cpca_coefficient_bits = 16;
  CpcaMethod cpca_method = CpcaMethod::kStandard;
};

// From the scene file's [compression] table; throws InputError(file, ...) on bad names/values.
CompressionOptions CompressionOptionsFrom(const CompressionSettings& s, const std::string& file);

// Header for T with domain.sample_count() rows over `domain` and cubemap size n (validated).
// `channels` (1 or 3): colour channels of T, whose rows are then channel-major (row c·V + v) and
// whose domain must be `channels` copies of the spatial one (SpatialDomainOf(…, channels),
// PerChannelDomain); throws InputError otherwise.
CompressedTransportHeader MakeCompressedHeader(const CompressionOptions& o, int cubemap_n,
                                               const SpatialDomain& domain, uint32_t channels = 1);
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
// The exact squared error of the column stage on a block of columns, in the T̂ basis (which
// the orthonormal row transform of Cheslack-Postava et al. 2008 §4.1 makes the error in the
// texel basis): Σ ‖x − x̃‖², with x each column entering the column stage (sample order) and x̃
// what its compressed column decodes to (formats/column_coding.h: dequantised (§4.3),
// inverse-transformed (§4.2); 0 for a column not in `compressed`). With `depths`, `columns`
// holds the transformed columns c (TransformColumnBlock's output) and the error is ‖W⁻¹(c − ĉ)‖²
// by linearity. Parallel over columns (TBB).
double ColumnBlockError(const CompressedTransportHeader& h, uint32_t first_column, uint32_t count,
                        const float* columns, const uint8_t* depths,
                        std::span<const CompressedColumn> compressed);

// The keep-th largest non-zero |c| of n coefficients (exact; tests and diagnostics).
float GlobalThreshold(const float* coefficients, std::size_t n, std::size_t keep);

// Global budget, the same on any number of ranks and any block order: non-zero magnitudes are
// counted in kMagnitudeBins bins by the top 16 bits of their float32 pattern (bins 2^-7 wide
// relative to the value); histograms of column blocks add. The threshold is the lower edge of
// the bin where the count from the largest bin down first reaches `keep`, so that every |c| in
// that bin and above is kept: at least `keep` terms (all non-zeros when there are fewer), at most
// one bin more.
inline constexpr std::size_t kMagnitudeBins = std::size_t{1} << 15;
void AddMagnitudeHistogram(const float* coefficients, std::size_t n, uint64_t* histogram);
// The same for `count` transformed columns first_column… (column-major), each column's
// magnitudes weighted by ColumnWeight (what QuantiseColumnBlock compares with the threshold).
void AddColumnBlockHistogram(const CompressedTransportHeader& h, uint32_t first_column,
                             uint32_t count, const float* transformed, uint64_t* histogram);
// 2^(−light_weight·l/2) for the row level l of `column`.
float ColumnWeight(const CompressedTransportHeader& h, uint32_t column);
float ThresholdFromHistogram(const uint64_t* histogram, uint64_t keep);
// Terms the global budget aims at: round(f·samples·columns), at least 1.
uint64_t GlobalTermBudget(const CompressedTransportHeader& h);

// The whole pipeline in memory: T is samples × 6n², row-major, in the cubemap texel basis.
CompressedTransport CompressTransport(const float* T, int cubemap_n, const SpatialDomain& domain,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats = nullptr);
// The same for the header `h` (MakeCompressedHeader with `o`; e.g. a 3-channel T:
// h.sample_count = 3·V rows, channel-major).
CompressedTransport CompressTransport(const float* T, const CompressedTransportHeader& h,
                                      const CompressionOptions& o,
                                      std::vector<ColumnStats>* stats = nullptr);

}  // namespace prt
