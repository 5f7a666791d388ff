// Out-of-core half of the blocked transpose of T (Cheslack-Postava et al. 2008 §4.4, step 3):
// rows of T̂ arrive in row blocks, in any order; columns leave in column blocks, in order. Rows
// are buffered in memory up to a budget; beyond it the buffer is sorted by (column block, row)
// and spilled to disk as a sorted run; at the end every run and the buffer are merged one column
// block at a time. No MPI here: the farm's all-to-all (farm/) delivers each rank the slabs of
// rows for the column range it owns and feeds them to AddRows.
//
// When all the owned columns of all rows fit the budget, rows are written straight into their
// column blocks as they arrive (no buffer, no merge; the blocks are handed out as they are).
// Otherwise the row buffer never exceeds max(budget, one row slab's size), plus one output column
// block (columns_per_block × rows floats) and one read buffer per run while merging.
// The output is bit-for-bit the same whatever the budget.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace prt {

struct BlockSpillOptions {
  uint64_t memory_budget_bytes = 256ull << 20;  // row data held before spilling
  std::string spill_dir = ".";                  // where runs are written (removed afterwards)
  uint32_t columns_per_block = 256;             // width of an output column block
};

class BlockTransposer {
 public:
  // T̂ has `rows` rows; this transposer owns columns [column_begin, column_end).
  BlockTransposer(uint64_t rows, uint32_t column_begin, uint32_t column_end,
                  BlockSpillOptions options);
  ~BlockTransposer();  // removes its spill files
  BlockTransposer(const BlockTransposer&) = delete;
  BlockTransposer& operator=(const BlockTransposer&) = delete;

  // Rows [first_row, first_row + count): row r's owned columns are
  // data[(r − first_row)·stride + 0 … column_end − column_begin). Each row must arrive exactly
  // once (std::invalid_argument otherwise). Throws std::runtime_error when a spill fails.
  void AddRows(uint64_t first_row, uint64_t count, const float* data, std::size_t stride);

  // After all rows: the next column block, column-major (columns[k·rows + r]). Returns false
  // when every block has been produced. Throws std::invalid_argument if rows are missing.
  bool NextColumnBlock(uint32_t& first_column, uint32_t& count, std::vector<float>& columns);

  uint64_t runs_spilled() const;
  uint64_t bytes_spilled() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace prt
