// The full transport T = T⁰ + T¹ + … + Tᴷ of a run with interreflection (docs/
// interreflection.md), read as rows: the direct rows of transport.prtt plus every bounce's rows
// (indirect/bounce-<k>.prtt, on the coarse indirect grid) refined to the direct grid by
// AddRefinedRow (worker/bounce_gather.h). With `channels` 3 the result has 3·V rows,
// channel-major (row c·V + v: channel c of sample v); with 1, V rows. What the compression phase
// compresses; no MPI here.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "formats/transport_file.h"
#include "vocabulary/cubemap.h"

namespace prt {

// Adds every row of `reader` (a transport file at n, a multiple of coarse.n()), coarsened to
// `coarse` by CoarsenRow, into out (rows × coarse.texel_count() floats), block by block in
// parallel over rows (TBB). What the bounces read of T⁰ and of each other.
void AddCoarsenedRows(const TransportFileReader& reader, const CubemapLayout& coarse, float* out);

class ComposedTransport {
 public:
  // `direct`: transport.prtt (V rows at n); `bounces`: the bounce files in order (each
  // channels·V rows at the indirect n). Sums the bounces into memory (channels·V·6m² floats).
  // Throws InputError naming a file whose sizes do not fit.
  ComposedTransport(const std::string& direct, const std::vector<std::string>& bounces,
                    int channels);
  uint64_t rows() const { return uint64_t(channels_) * vertices_; }
  uint64_t vertices() const { return vertices_; }
  int channels() const { return channels_; }
  const TransportFileInfo& direct_info() const { return direct_->info(); }
  // Rows [first, first + count) of T (count · 6n² floats).
  void ReadRows(uint64_t first, uint64_t count, float* out) const;

 private:
  std::unique_ptr<TransportFileReader> direct_;
  int channels_ = 1;
  uint64_t vertices_ = 0;
  CubemapLayout fine_{1}, coarse_{1};
  std::vector<float> indirect_;  // Σ_k Tᵏ, channels·V rows at the coarse grid
};

}  // namespace prt
