// The uncompressed transport T of a benchmark scene and the column schemes' stages on it, shared
// by compression_bench and prt-cpca-bench: T traced here (or read from a cache file an earlier
// run wrote, or from a farm run folder), the per-sample albedo, and 2D / 4D / adaptive 4D
// compression of rows that are already in the row-wavelet basis, split so that what does not
// depend on the keep fraction is done once (the same functions and the same bytes as
// worker/transport_compressor.h CompressTransport).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "formats/compressed_transport.h"
#include "vocabulary/scene.h"
#include "worker/transport_compressor.h"

namespace prt::bench {

struct BenchTransport {
  std::string name;
  std::vector<float> T;  // S rows of 6n² floats, texel basis
  int n = 32;
  std::size_t S = 0;
  SpatialDomain domain;
  std::vector<float> albedo;  // 3 per sample
  std::string source;
  double order_normal_weight = 0;  // of the mesh column order
};

// The meshes' albedo per vertex, 3 floats per sample in the scene's sample order.
std::vector<float> AlbedoPerSample(const SceneGeometry& g);

// T of a benchmark scene (bench_scene.h) at n, `rays` rays per texel (seed 1): from `cache`
// (<scene>_n<n>_r<rays>.f32) when present, else traced (and written there; `cache` empty: no
// cache).
BenchTransport SceneTransport(const std::string& name, int n, int rays, const std::string& cache,
                              double order_normal_weight);

// T of a farm run folder (run/transport.prtt, kept with --keep-raw), its geometry and albedo; an
// image run (run/image.prti) gets the image domain and per-pixel albedo.
BenchTransport ReadRunTransport(const std::string& dir, double order_normal_weight);

// rows (S × M, row-major) → columns (M × S, column-major), in 64 × 64 tiles.
std::vector<float> TransposeRows(const std::vector<float>& rows, std::size_t S, std::size_t M);

// The column transforms of 2D and full 4D, which do not depend on the keep fraction: computed by
// the first CompressPreparedColumns call of a scheme and reused by the next ones (one per
// scheme and column wavelet; start a fresh one when either changes).
struct FixedColumns {
  std::vector<float> columns;
  std::vector<uint8_t> depths;
};

// The column stage of CompressTransport for header h (MakeCompressedHeader(o, …)) on T̂:
// rows_hat are the rows after PrepareRows with the global budget (no per-row truncation) and
// cols_hat their transpose (TransposeRows). 2D with the per-column budget truncates a copy of
// the rows here (each row's RowTermBudget largest terms). stats (optional): one entry per
// column. squared_error (optional): ‖T̂ − T̃‖²_F of the result (worker ColumnBlockError; for 2D
// with the per-column budget only the column stage's part, not the rows' truncation).
CompressedTransport CompressPreparedColumns(const CompressedTransportHeader& h,
                                            const CompressionOptions& o,
                                            const std::vector<float>& rows_hat,
                                            const std::vector<float>& cols_hat, FixedColumns& fixed,
                                            std::vector<ColumnStats>* stats = nullptr,
                                            double* squared_error = nullptr);

}  // namespace prt::bench
