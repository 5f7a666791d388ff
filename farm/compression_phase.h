// prt-farm's last phase: the compressed transport run/transport.prtc (docs/farm-compression.md),
// computed by all ranks from the finished run/transport.prtt, following Cheslack-Postava et al.
// 2008 §4.4 steps 2–5:
//   rows     rank 0 reads T in chunks of whole file blocks (TransportFileReader, checksums
//            verified) and scatters each chunk's rows over the ranks; every rank applies the row
//            transform (§4.1, PrepareRows) to its share
//   transpose (step 3, farm/distributed_transpose.h) every rank owns a contiguous range of
//            columns and receives them as column blocks
//   columns  every rank compresses its column blocks (§4.2–4.3, CompressColumnBlock) and sends
//            them to rank 0 as one encoded column block; rank 0 writes EncodeCompressedTransport
//            durably. Columns are independent, so the bytes equal the in-process
//            CompressTransport on the same rows for any number of ranks and any budget.
// The phase is MakeCompressionPhase() (farm/farm_context.h); it reads the scene and geometry the
// setup phase holds, and only the rows from disk. Its figures go to report.json "compression"
// (CompressionFarmReport, farm/farm_report.h).
#pragma once

#include <cstddef>
#include <string>

#include "farm/farm_options.h"
#include "formats/compressed_transport.h"
#include "vocabulary/scene.h"
#include "worker/transport_compressor.h"

namespace prt {

// What the compression phase will use for this scene, geometry and command line: the options
// (the scene's [compression], --compression-scheme over it) and the header transport.prtc gets.
// Throws InputError naming the scene file on bad settings.
struct CompressionPlan {
  CompressionOptions options;
  CompressedTransportHeader header;
};
CompressionPlan PlanCompression(const SceneDescription& scene, const SceneGeometry& geometry,
                                int cubemap_n, const FarmOptions& options);
// "scheme adaptive4d -> 2d, bits 9 -> 12, …" for what makes `now` differ from the header a
// finished transport.prtc was written with (`was`); "" when a run would write the same header.
std::string CompressedHeaderDifferences(const CompressedTransportHeader& was,
                                        const CompressedTransportHeader& now);

// memcpy bandwidth over a `bytes` buffer (best of a few passes), MB/s (10^6 bytes/s).
double MeasureMemoryBandwidth(std::size_t bytes);
// Writes `bytes` into a temporary file in `dir`, fsyncs it, removes it: MB/s.
double MeasureDiskWriteBandwidth(const std::string& dir, std::size_t bytes);

}  // namespace prt
