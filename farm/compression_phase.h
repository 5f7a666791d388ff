// prt-farm's last phase: the compressed transport run/transport.prtc (docs/farm-compression.md),
// computed by all ranks from the finished run/transport.prtt, following Cheslack-Postava et al.
// 2008 §4.4 steps 2–5:
//   rows     rank 0 reads T in chunks of whole file blocks (TransportFileReader, checksums
//            verified) and scatters each chunk's rows over the ranks; every rank applies the row
//            transform (§4.1, PrepareRows) to its share
//   transpose (step 3) every rank owns a contiguous range of columns; the row-transformed rows
//            move between ranks with MPI_Alltoallv (rank i sends rank j the slab rows_i ×
//            columns_j) and enter the rank's BlockTransposer (worker/block_spill.h), which
//            spills sorted runs to disk beyond the memory budget and merges them into column
//            blocks
//   columns  every rank compresses its column blocks (§4.2–4.3, CompressColumnBlock) and sends
//            them to rank 0 as one encoded column block; rank 0 writes EncodeCompressedTransport
//            durably. Columns are independent, so the bytes equal the in-process
//            CompressTransport on the same rows for any number of ranks and any budget.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "farm/farm_options.h"
#include "worker/block_spill.h"

namespace prt {

class Progress;

// Same name as packager/run_folder_pack.h's kCompressedTransportFileName (farm may not include
// the packager).
inline constexpr const char* kCompressedTransportFile = "transport.prtc";

// Columns [first, end) owned by `rank` of `ranks`: contiguous, sizes differ by at most 1.
std::pair<uint32_t, uint32_t> OwnedColumns(uint32_t cols, int rank, int ranks);
// Rows of a chunk [first, first + count) that `rank` of `ranks` row-transforms.
std::pair<uint64_t, uint64_t> ChunkShare(uint64_t first, uint64_t count, int rank, int ranks);
// Rows per streamed chunk: whole file blocks (never re-read a block), about a quarter of the
// memory budget, at most 64 MiB (MPI counts stay far below 2^31), at least one file block.
uint64_t ChunkRows(uint64_t row_bytes, uint32_t rows_per_block, uint64_t memory_budget,
                   uint64_t rows);

// What the distributed transpose did on one rank (seconds are this rank's).
struct TransposeStats {
  uint64_t bytes_sent = 0;     // row data this rank sent to other ranks (scatter + all-to-all)
  uint64_t bytes_spilled = 0;  // written to spill runs by this rank's BlockTransposer
  uint64_t runs_spilled = 0;
  double read_seconds = 0;           // rank 0: reading and verifying transport.prtt
  double row_transform_seconds = 0;  // PrepareRows (§4.1)
  double exchange_seconds = 0;       // MPI scatter + all-to-all
  // BlockTransposer: its construction (allocation; with the owned data inside the budget, the
  // first touch of all of it) and AddRows (buffering, spilling).
  double buffer_seconds = 0;
  double merge_seconds = 0;  // BlockTransposer::NextColumnBlock (merging runs)
  double sink_seconds = 0;   // the column-block consumer (compression)
};

// Reads rows [first, first + count) of T into out (count × cols floats); called on rank 0 only.
using RowReader = std::function<void(uint64_t first, uint64_t count, float* out)>;
// Transforms rows in place (count × cols floats); called on every rank for its chunk shares.
using RowPreparer = std::function<void(uint64_t first, uint64_t count, float* rows)>;
// Receives the owned column blocks in order, column-major (columns[k·rows + r]).
using ColumnBlockSink =
    std::function<void(uint32_t first_column, uint32_t count, std::vector<float>& columns)>;

// The distributed, out-of-core blocked transpose (§4.4 step 3). Collective over `comm`: every
// rank calls it with the same rows, cols and chunk_rows. `spill.memory_budget_bytes` bounds each
// rank's buffered rows; `spill.spill_dir` must be a folder this rank may write. The column blocks
// a rank's sink receives are bit-for-bit the same for any budget and any number of ranks owning
// the same columns. `progress` (rank 0, may be null) advances by the rows streamed. Throws on
// MPI errors (with MPI_ERRORS_RETURN) and spill failures; a failed read on rank 0 is broadcast
// so that every rank throws.
TransposeStats DistributedTranspose(MPI_Comm comm, uint64_t rows, uint32_t cols,
                                    uint64_t chunk_rows, const RowReader& read,
                                    const RowPreparer& prepare, const BlockSpillOptions& spill,
                                    const ColumnBlockSink& sink, Progress* progress = nullptr);

// The phase's figures, as written to report.json "compression" (docs/farm-compression.md).
struct CompressionPhaseReport {
  double wall_seconds = 0;
  int ranks = 1;
  std::string scheme, row_wavelet, column_wavelet;
  int bits = 0;
  double keep_fraction = 0;
  uint64_t memory_budget_bytes = 0;
  uint64_t raw_bytes = 0;    // rows × cols × 4
  uint64_t bytes_moved = 0;  // between ranks, all ranks
  uint64_t spill_bytes = 0;  // all ranks
  uint64_t spill_runs = 0;
  double transpose_seconds = 0;  // max over ranks of exchange + buffer + merge
  double read_seconds = 0, row_transform_seconds = 0, exchange_seconds = 0, buffer_seconds = 0,
         merge_seconds = 0, compress_seconds = 0, write_seconds = 0;  // max over ranks
  uint64_t compressed_bytes = 0;                                      // transport.prtc
  uint64_t terms = 0;
  uint64_t columns_stored = 0;
  bool raw_kept = true;
  // --measure-bandwidth (0 when not measured): memcpy and write+fsync in the run folder, MB/s.
  double memory_bandwidth_mb_s = 0;
  double disk_write_bandwidth_mb_s = 0;

  double TransposeMbPerSecond() const;  // raw_bytes / transpose_seconds
  double PhaseMbPerSecond() const;      // raw_bytes / wall_seconds
  double Ratio() const;                 // compressed_bytes / raw_bytes
};

// report.json text with "compression" set, a "compress" entry appended to "phases" and the
// phase's time added to "wall_seconds". Throws InputError(name) when the text is not JSON.
std::string MergeCompressionReport(const std::string& report_json, const CompressionPhaseReport& r,
                                   const std::string& name);

// memcpy bandwidth over a `bytes` buffer (best of a few passes), MB/s (10^6 bytes/s).
double MeasureMemoryBandwidth(std::size_t bytes);
// Writes `bytes` into a temporary file in `dir`, fsyncs it, removes it: MB/s.
double MeasureDiskWriteBandwidth(const std::string& dir, std::size_t bytes);

// Collective, after RunFarm returned kExitOk on every rank: the compression phase. Returns the
// exit code (the same on every rank; a failure in the middle aborts the job with MPI_Abort).
// Does nothing with --no-compress.
int RunCompressionPhase(const FarmOptions& options);

}  // namespace prt
