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
// The phase (AddCompressionPhase, in the list farm/phase_list.cpp) reads the scene and geometry the
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

// memcpy bandwidth over a `bytes` buffer (best of a few passes), MB/s (10^6 bytes/s).
double MeasureMemoryBandwidth(std::size_t bytes);
// Writes `bytes` into a temporary file in `dir`, fsyncs it, removes it: MB/s.
double MeasureDiskWriteBandwidth(const std::string& dir, std::size_t bytes);

}  // namespace prt
