// The full transport of a run with interreflection (see composed_transport.h).
#include "worker/composed_transport.h"

#include <tbb/parallel_for.h>

#include <algorithm>

#include "vocabulary/errors.h"
#include "worker/bounce_gather.h"

namespace prt {

void AddCoarsenedRows(const TransportFileReader& reader, const CubemapLayout& coarse, float* out) {
  const CubemapLayout grid(static_cast<int>(reader.info().cubemap_n));
  const std::size_t cols = coarse.texel_count();
  std::vector<float> block;
  for (uint64_t b = 0; b < reader.info().block_count(); ++b) {
    block.resize(static_cast<std::size_t>(reader.info().RowsInBlock(b) * grid.texel_count()));
    reader.ReadBlock(b, block);
    const uint64_t first = reader.info().FirstRowOfBlock(b);
    tbb::parallel_for(uint64_t{0}, reader.info().RowsInBlock(b), [&](uint64_t r) {
      thread_local std::vector<float> row;
      row.resize(cols);
      CoarsenRow(grid, coarse, block.data() + r * grid.texel_count(), row.data());
      float* dst = out + (first + r) * cols;
      for (std::size_t J = 0; J < cols; ++J) dst[J] += row[J];
    });
  }
}

ComposedTransport::ComposedTransport(const std::string& direct,
                                     const std::vector<std::string>& bounces, int channels)
    : direct_(std::make_unique<TransportFileReader>(direct)), channels_(channels) {
  vertices_ = direct_->info().rows;
  fine_ = CubemapLayout(static_cast<int>(direct_->info().cubemap_n));
  for (const std::string& path : bounces) {
    const TransportFileReader r(path);
    if (r.info().rows != uint64_t(channels) * vertices_ ||
        r.info().cubemap_n > direct_->info().cubemap_n ||
        direct_->info().cubemap_n % r.info().cubemap_n != 0)
      throw InputError(path, std::to_string(r.info().rows) +
                                 " rows at n = " + std::to_string(r.info().cubemap_n) +
                                 " do not fit " + std::to_string(channels) + " channel(s) of " +
                                 std::to_string(vertices_) +
                                 " samples at n = " + std::to_string(direct_->info().cubemap_n));
    if (indirect_.empty()) {
      coarse_ = CubemapLayout(static_cast<int>(r.info().cubemap_n));
      indirect_.assign(static_cast<std::size_t>(r.info().rows * coarse_.texel_count()), 0.0f);
    } else if (coarse_.n() != int(r.info().cubemap_n)) {
      throw InputError(path, "bounce rows on another grid than the first bounce's");
    }
    AddCoarsenedRows(r, coarse_, indirect_.data());
  }
}

void ComposedTransport::ReadRows(uint64_t first, uint64_t count, float* out) const {
  const std::size_t cols = fine_.texel_count();
  // The direct rows: one run of samples per channel the range touches.
  for (uint64_t r = first; r < first + count;) {
    const uint64_t v = r % vertices_;
    const uint64_t run = std::min(first + count - r, vertices_ - v);
    direct_->ReadRows(v, run, out + (r - first) * cols);
    r += run;
  }
  if (indirect_.empty()) return;
  const std::size_t m_cols = coarse_.texel_count();
  tbb::parallel_for(uint64_t{0}, count, [&](uint64_t i) {
    AddRefinedRow(coarse_, fine_, indirect_.data() + (first + i) * m_cols, out + i * cols);
  });
}

}  // namespace prt
