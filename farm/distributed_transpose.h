// The distributed, out-of-core blocked transpose of prt-farm's compression phase
// (Cheslack-Postava et al. 2008 §4.4 step 3; docs/farm-compression.md): every rank owns a
// contiguous range of columns; the row-transformed rows move between ranks with MPI_Alltoallv
// (rank i sends rank j the slab rows_i × columns_j) and enter the rank's BlockTransposer
// (worker/block_spill.h), which spills sorted runs to disk beyond the memory budget and merges
// them into column blocks.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <functional>
#include <utility>
#include <vector>

#include "worker/block_spill.h"

namespace prt {

class Progress;

// Columns [first, end) owned by `rank` of `ranks`: contiguous, sizes differ by at most 1.
std::pair<uint32_t, uint32_t> OwnedColumns(uint32_t cols, int rank, int ranks);
// Rows of a chunk [first, first + count) that `rank` of `ranks` row-transforms: contiguous, in
// whole units of `align` rows (the file's blocks, so that no two ranks read the same block) but
// for the chunk's last unit.
std::pair<uint64_t, uint64_t> ChunkShare(uint64_t first, uint64_t count, int rank, int ranks,
                                         uint64_t align = 1);
// Rows per streamed chunk: whole file blocks (never re-read a block), about a quarter of the
// memory budget, at most 64 MiB (MPI counts stay far below 2^31), at least one file block.
uint64_t ChunkRows(uint64_t row_bytes, uint32_t rows_per_block, uint64_t memory_budget,
                   uint64_t rows);

// What the distributed transpose did on one rank (seconds are this rank's).
struct TransposeStats {
  uint64_t bytes_sent = 0;     // row data this rank sent to other ranks (scatter + all-to-all)
  uint64_t bytes_spilled = 0;  // written to spill runs by this rank's BlockTransposer
  uint64_t runs_spilled = 0;
  uint64_t bytes_read = 0;           // rows this rank read from the file (float32 bytes)
  double read_seconds = 0;           // reading and verifying transport.prtt
  double row_transform_seconds = 0;  // PrepareRows (§4.1)
  double exchange_seconds = 0;       // MPI scatter + all-to-all
  // BlockTransposer: its construction (allocation; with the owned data inside the budget, the
  // first touch of all of it) and AddRows (buffering, spilling).
  double buffer_seconds = 0;
  double merge_seconds = 0;  // BlockTransposer::NextColumnBlock (merging runs)
  double sink_seconds = 0;   // the column-block consumer (compression)
};

// Reads rows [first, first + count) of T into out (count × cols floats): on rank 0 only, which
// scatters them, or with TransposeReading::every_rank_reads on every rank for its own share.
using RowReader = std::function<void(uint64_t first, uint64_t count, float* out)>;
// Transforms rows in place (count × cols floats); called on every rank for its chunk shares.
using RowPreparer = std::function<void(uint64_t first, uint64_t count, float* rows)>;
// Receives the owned column blocks in order, column-major (columns[k·rows + r]).
using ColumnBlockSink =
    std::function<void(uint32_t first_column, uint32_t count, std::vector<float>& columns)>;

// Who reads the rows (docs/farm.md, "Where the rows go").
struct TransposeReading {
  // false: rank 0 reads each chunk and scatters the shares; true: every rank reads its own share
  // (the file is on a folder every rank sees), and no row passes through rank 0.
  bool every_rank_reads = false;
  uint64_t align = 1;  // ChunkShare's unit: the file's rows per block
};

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
                                    const ColumnBlockSink& sink, Progress* progress = nullptr,
                                    const TransposeReading& reading = {});

}  // namespace prt
