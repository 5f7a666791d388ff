// The distributed blocked transpose (see distributed_transpose.h).
#include "farm/distributed_transpose.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "farm/farm_options.h"
#include "farm/mpi_support.h"
#include "farm/progress.h"
#include "vocabulary/errors.h"
#include "vocabulary/huge_pages.h"

namespace prt {

namespace {

double Now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// BlockTransposer reports a failed spill write or read as std::runtime_error: that is an I/O
// error of the spill folder (exit code 3); its std::invalid_argument (a row missing or added
// twice) stays an internal error.
struct SpillIo {
  std::string dir;
  explicit SpillIo(std::string d) : dir(std::move(d)) {}
  template <class F>
  void operator()(F&& f) const {
    try {
      f();
    } catch (const std::invalid_argument&) {
      throw;
    } catch (const std::runtime_error& e) {
      throw FileIoError(dir, e.what());
    }
  }
};

}  // namespace

std::pair<uint32_t, uint32_t> OwnedColumns(uint32_t cols, int rank, int ranks) {
  const uint64_t c = cols, r = static_cast<uint64_t>(rank), p = static_cast<uint64_t>(ranks);
  return {static_cast<uint32_t>(c * r / p), static_cast<uint32_t>(c * (r + 1) / p)};
}

std::pair<uint64_t, uint64_t> ChunkShare(uint64_t first, uint64_t count, int rank, int ranks,
                                         uint64_t align) {
  const uint64_t r = static_cast<uint64_t>(rank), p = static_cast<uint64_t>(ranks);
  const uint64_t unit = std::max<uint64_t>(1, align);
  const uint64_t units = (count + unit - 1) / unit;
  const uint64_t a = std::min(count, units * r / p * unit);
  const uint64_t b = std::min(count, units * (r + 1) / p * unit);
  return {first + a, b - a};
}

uint64_t ChunkRows(uint64_t row_bytes, uint32_t rows_per_block, uint64_t memory_budget,
                   uint64_t rows) {
  const uint64_t block_bytes =
      std::max<uint64_t>(1, row_bytes * std::max<uint32_t>(1, rows_per_block));
  const uint64_t target = std::min<uint64_t>(memory_budget / 4, 64ull << 20);
  const uint64_t blocks = std::max<uint64_t>(1, target / block_bytes);
  return std::max<uint64_t>(
      1, std::min<uint64_t>(rows, blocks * std::max<uint32_t>(1, rows_per_block)));
}

namespace {

// One rank's side of DistributedTranspose: the state of the chunk loop and its steps, each a
// function of its own (read, scatter, exchange, buffer, merge).
class TransposeRank {
 public:
  TransposeRank(MPI_Comm comm, uint64_t rows, uint32_t cols, const TransposeReading& reading,
                const BlockSpillOptions& spill)
      : comm_(comm), cols_(cols), align_(reading.align), spill_(spill) {
    CheckMpi(MPI_Comm_rank(comm, &rank_), "MPI_Comm_rank");
    CheckMpi(MPI_Comm_size(comm, &size_), "MPI_Comm_size");
    own_reads_ = reading.every_rank_reads && size_ > 1;
    P_ = static_cast<std::size_t>(size_);
    const auto [cb, ce] = OwnedColumns(cols, rank_, size_);
    width_ = ce - cb;
    if (width_ > 0) {
      // Counted as buffering: with the owned data inside the budget, the transposer allocates
      // and first-touches all its column blocks here.
      const double t = Now();
      tr_.emplace(rows, cb, ce, spill);
      st_.buffer_seconds += Now() - t;
    }
    col_first_.resize(P_);
    col_width_.resize(P_);
    for (int r = 0; r < size_; ++r) {
      const auto [a, b] = OwnedColumns(cols, r, size_);
      col_first_[static_cast<std::size_t>(r)] = a;
      col_width_[static_cast<std::size_t>(r)] = b - a;
    }
    for (auto* v : {&counts_, &displs_, &scounts_, &sdispls_, &rcounts_, &rdispls_}) v->resize(P_);
  }

  bool own_reads() const { return own_reads_; }
  int size() const { return size_; }
  TransposeStats& stats() { return st_; }

  // Rows [first, first + count) of T as this rank's share `mine_` (rows my_first + my_count),
  // row-transformed by `prepare`: read by every rank itself, or by rank 0 and scattered.
  void LoadShare(uint64_t first, uint64_t count, const RowReader& read,
                 const RowPreparer& prepare) {
    const auto [my_first, my_count] = ChunkShare(first, count, rank_, size_, align_);
    if (own_reads_) {
      ReadOwnShare(first, my_first, my_count, read);
    } else {
      ReadChunkOnRank0(first, count, read);
      ScatterChunk(first, count, my_count);
    }
    const double t = Now();
    prepare(my_first, my_count, mine_.data());
    st_.row_transform_seconds += Now() - t;
    my_count_ = my_count;
  }

  // All-to-all: rank j receives rows_i × columns_j from every rank i; then its transposer
  // buffers (and spills) the slabs.
  void ExchangeAndBuffer(uint64_t first, uint64_t count) {
    double t = Now();
    const float* slabs = size_ == 1 ? mine_.data() : ExchangeSlabs(first, count);
    st_.exchange_seconds += Now() - t;
    t = Now();
    if (tr_) {
      SpillIo io(spill_.spill_dir);
      for (std::size_t i = 0; i < P_; ++i) {
        const auto [f, c] = ChunkShare(first, count, static_cast<int>(i), size_, align_);
        if (c == 0) continue;
        io([&] {
          tr_->AddRows(f, c, size_ == 1 ? slabs : slabs + rdispls_[i], size_ == 1 ? cols_ : width_);
        });
      }
    }
    st_.buffer_seconds += Now() - t;
    if (size_ == 1 && !own_reads_) mine_.swap(chunk_);
  }

  // The owned column blocks, merged from the buffered (and spilled) rows, to `sink`.
  void MergeColumns(const ColumnBlockSink& sink) {
    if (!tr_) return;
    uint32_t f = 0, c = 0;
    std::vector<float> columns;
    for (;;) {
      double t = Now();
      bool more = false;
      SpillIo(spill_.spill_dir)([&] { more = tr_->NextColumnBlock(f, c, columns); });
      st_.merge_seconds += Now() - t;
      if (!more) break;
      t = Now();
      sink(f, c, columns);
      st_.sink_seconds += Now() - t;
    }
    st_.bytes_spilled = tr_->bytes_spilled();
    st_.runs_spilled = tr_->runs_spilled();
  }

 private:
  // Every rank reads its own share; a failure anywhere stops every rank (none waits forever).
  void ReadOwnShare(uint64_t first, uint64_t my_first, uint64_t my_count, const RowReader& read) {
    int ok = 1;
    std::exception_ptr failure;
    const double t = Now();
    try {
      ReserveFreshHuge(mine_, my_count * cols_);
      mine_.resize(my_count * cols_);
      if (my_count > 0) read(my_first, my_count, mine_.data());
      st_.bytes_read += my_count * cols_ * sizeof(float);
    } catch (...) {
      ok = 0;
      failure = std::current_exception();
    }
    st_.read_seconds += Now() - t;
    int all = 0;
    CheckMpi(MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, comm_), "MPI_Allreduce");
    if (!all) {
      if (failure) std::rethrow_exception(failure);
      throw RankFailure("another rank could not read rows " + std::to_string(first) + "..");
    }
  }

  // Rank 0 reads the whole chunk; whether it could is shared with every rank.
  void ReadChunkOnRank0(uint64_t first, uint64_t count, const RowReader& read) {
    int ok = 1;
    std::exception_ptr failure;
    if (rank_ == 0) {
      const double t = Now();
      try {
        ReserveFreshHuge(chunk_, count * cols_);
        chunk_.resize(count * cols_);
        read(first, count, chunk_.data());
        st_.bytes_read += count * cols_ * sizeof(float);
      } catch (...) {
        ok = 0;
        failure = std::current_exception();
      }
      st_.read_seconds += Now() - t;
    }
    const double t = Now();
    CheckMpi(MPI_Bcast(&ok, 1, MPI_INT, 0, comm_), "MPI_Bcast");
    st_.exchange_seconds += Now() - t;
    if (!ok) {
      if (failure) std::rethrow_exception(failure);
      throw RankFailure("rank 0 could not read rows " + std::to_string(first) + "..");
    }
  }

  // Scatter: rank r gets rows ChunkShare(r) of rank 0's chunk.
  void ScatterChunk(uint64_t first, uint64_t count, uint64_t my_count) {
    const double t = Now();
    for (std::size_t r = 0; r < P_; ++r) {
      const auto [f, c] = ChunkShare(first, count, static_cast<int>(r), size_, align_);
      counts_[r] = static_cast<int>(c * cols_);
      displs_[r] = static_cast<int>((f - first) * cols_);
      if (rank_ == 0 && static_cast<int>(r) != 0) st_.bytes_sent += c * cols_ * sizeof(float);
    }
    ReserveFreshHuge(mine_, my_count * cols_);
    mine_.resize(my_count * cols_);
    if (size_ == 1) {
      mine_.swap(chunk_);
    } else {
      CheckMpi(MPI_Scatterv(chunk_.data(), counts_.data(), displs_.data(), MPI_FLOAT, mine_.data(),
                            static_cast<int>(my_count * cols_), MPI_FLOAT, 0, comm_),
               "MPI_Scatterv");
    }
    st_.exchange_seconds += Now() - t;
  }

  // The all-to-all of the share's columns; returns the received slabs (rank i's at rdispls_[i]).
  const float* ExchangeSlabs(uint64_t first, uint64_t count) {
    int so = 0, ro = 0;
    for (std::size_t j = 0; j < P_; ++j) {
      scounts_[j] = static_cast<int>(my_count_ * col_width_[j]);
      sdispls_[j] = so;
      so += scounts_[j];
      if (static_cast<int>(j) != rank_)
        st_.bytes_sent += static_cast<uint64_t>(scounts_[j]) * sizeof(float);
      const uint64_t ci = ChunkShare(first, count, static_cast<int>(j), size_, align_).second;
      rcounts_[j] = static_cast<int>(ci * width_);
      rdispls_[j] = ro;
      ro += rcounts_[j];
    }
    ReserveFreshHuge(sendbuf_, static_cast<std::size_t>(so));
    ReserveFreshHuge(recvbuf_, static_cast<std::size_t>(ro));
    sendbuf_.resize(static_cast<std::size_t>(so));
    recvbuf_.resize(static_cast<std::size_t>(ro));
    for (std::size_t j = 0; j < P_; ++j) {
      float* dst = sendbuf_.data() + sdispls_[j];
      for (uint64_t r = 0; r < my_count_; ++r)
        std::memcpy(dst + r * col_width_[j], mine_.data() + r * cols_ + col_first_[j],
                    col_width_[j] * sizeof(float));
    }
    CheckMpi(MPI_Alltoallv(sendbuf_.data(), scounts_.data(), sdispls_.data(), MPI_FLOAT,
                           recvbuf_.data(), rcounts_.data(), rdispls_.data(), MPI_FLOAT, comm_),
             "MPI_Alltoallv");
    return recvbuf_.data();
  }

  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  std::size_t P_ = 1;
  uint32_t cols_ = 0, width_ = 0;
  uint64_t align_ = 0;
  bool own_reads_ = false;
  BlockSpillOptions spill_;
  TransposeStats st_;
  std::optional<BlockTransposer> tr_;
  std::vector<uint32_t> col_first_, col_width_;
  std::vector<float> chunk_, mine_, sendbuf_, recvbuf_;
  uint64_t my_count_ = 0;
  std::vector<int> counts_, displs_, scounts_, sdispls_, rcounts_, rdispls_;
};

}  // namespace

// §4.4 step 3, distributed: chunks of rows are scattered from rank 0, row-transformed where they
// land, then exchanged all-to-all so that each rank receives, for every row of the chunk, the
// slab of columns it owns; its BlockTransposer buffers (and spills) them and finally merges
// them into column blocks. No rank holds more than one chunk, its share, the exchange buffers
// and its transposer's budget.
TransposeStats DistributedTranspose(MPI_Comm comm, uint64_t rows, uint32_t cols,
                                    uint64_t chunk_rows, const RowReader& read,
                                    const RowPreparer& prepare, const BlockSpillOptions& spill,
                                    const ColumnBlockSink& sink, Progress* progress,
                                    const TransposeReading& reading) {
  if (chunk_rows == 0) throw std::invalid_argument("DistributedTranspose: chunk_rows is 0");
  TransposeRank me(comm, rows, cols, reading, spill);
  // MPI counts: the scatter's (the whole chunk) or, reading shares, the largest share.
  const uint64_t align = reading.align;
  const uint64_t counted = me.own_reads() ? ChunkShare(0, chunk_rows, 0, me.size(), align).second +
                                                std::max<uint64_t>(1, align)
                                          : chunk_rows;
  if (counted * cols > static_cast<uint64_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("DistributedTranspose: chunk exceeds 2^31 floats");
  for (uint64_t first = 0; first < rows; first += chunk_rows) {
    const uint64_t count = std::min(chunk_rows, rows - first);
    me.LoadShare(first, count, read, prepare);
    me.ExchangeAndBuffer(first, count);
    if (progress) progress->Advance(count);
  }
  me.MergeColumns(sink);
  return me.stats();
}

}  // namespace prt
