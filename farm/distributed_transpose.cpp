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
  int rank = 0, size = 1;
  CheckMpi(MPI_Comm_rank(comm, &rank), "MPI_Comm_rank");
  CheckMpi(MPI_Comm_size(comm, &size), "MPI_Comm_size");
  if (chunk_rows == 0) throw std::invalid_argument("DistributedTranspose: chunk_rows is 0");
  const bool own_reads = reading.every_rank_reads && size > 1;
  const uint64_t align = reading.align;
  // MPI counts: the scatter's (the whole chunk) or, reading shares, the largest share.
  const uint64_t counted =
      own_reads ? ChunkShare(0, chunk_rows, 0, size, align).second + std::max<uint64_t>(1, align)
                : chunk_rows;
  if (counted * cols > static_cast<uint64_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("DistributedTranspose: chunk exceeds 2^31 floats");
  TransposeStats st;
  const auto [cb, ce] = OwnedColumns(cols, rank, size);
  const uint32_t width = ce - cb;
  std::optional<BlockTransposer> tr;
  if (width > 0) {
    // Counted as buffering: with the owned data inside the budget, the transposer allocates and
    // first-touches all its column blocks here.
    const double t = Now();
    tr.emplace(rows, cb, ce, spill);
    st.buffer_seconds += Now() - t;
  }
  std::vector<uint32_t> col_first(static_cast<std::size_t>(size)),
      col_width(static_cast<std::size_t>(size));
  for (int r = 0; r < size; ++r) {
    const auto [a, b] = OwnedColumns(cols, r, size);
    col_first[static_cast<std::size_t>(r)] = a;
    col_width[static_cast<std::size_t>(r)] = b - a;
  }
  const std::size_t P = static_cast<std::size_t>(size);
  std::vector<float> chunk, mine, sendbuf, recvbuf;
  std::vector<int> counts(P), displs(P), scounts(P), sdispls(P), rcounts(P), rdispls(P);
  for (uint64_t first = 0; first < rows; first += chunk_rows) {
    const uint64_t count = std::min(chunk_rows, rows - first);
    const auto [my_first, my_count] = ChunkShare(first, count, rank, size, align);
    // Rank 0 reads the chunk (or every rank its share); a failure is shared so that no rank
    // waits forever.
    int ok = 1;
    std::exception_ptr failure;
    if (own_reads) {
      const double t = Now();
      try {
        ReserveFreshHuge(mine, my_count * cols);
        mine.resize(my_count * cols);
        if (my_count > 0) read(my_first, my_count, mine.data());
        st.bytes_read += my_count * cols * sizeof(float);
      } catch (...) {
        ok = 0;
        failure = std::current_exception();
      }
      st.read_seconds += Now() - t;
      int all = 0;
      CheckMpi(MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, comm), "MPI_Allreduce");
      if (!all) {
        if (failure) std::rethrow_exception(failure);
        throw RankFailure("another rank could not read rows " + std::to_string(first) + "..");
      }
    } else if (rank == 0) {
      const double t = Now();
      try {
        ReserveFreshHuge(chunk, count * cols);
        chunk.resize(count * cols);
        read(first, count, chunk.data());
        st.bytes_read += count * cols * sizeof(float);
      } catch (...) {
        ok = 0;
        failure = std::current_exception();
      }
      st.read_seconds += Now() - t;
    }
    double t = Now();
    if (!own_reads) {
      CheckMpi(MPI_Bcast(&ok, 1, MPI_INT, 0, comm), "MPI_Bcast");
      if (!ok) {
        if (failure) std::rethrow_exception(failure);
        throw RankFailure("rank 0 could not read rows " + std::to_string(first) + "..");
      }
      // Scatter: rank r gets rows ChunkShare(r) of the chunk.
      for (std::size_t r = 0; r < P; ++r) {
        const auto [f, c] = ChunkShare(first, count, static_cast<int>(r), size, align);
        counts[r] = static_cast<int>(c * cols);
        displs[r] = static_cast<int>((f - first) * cols);
        if (rank == 0 && static_cast<int>(r) != 0) st.bytes_sent += c * cols * sizeof(float);
      }
      ReserveFreshHuge(mine, my_count * cols);
      mine.resize(my_count * cols);
    }
    if (own_reads) {
      // Each rank read its own share above.
    } else if (size == 1) {
      mine.swap(chunk);
    } else {
      CheckMpi(MPI_Scatterv(chunk.data(), counts.data(), displs.data(), MPI_FLOAT, mine.data(),
                            static_cast<int>(my_count * cols), MPI_FLOAT, 0, comm),
               "MPI_Scatterv");
    }
    st.exchange_seconds += Now() - t;
    t = Now();
    prepare(my_first, my_count, mine.data());
    st.row_transform_seconds += Now() - t;
    // All-to-all: rank j receives rows_i × columns_j from every rank i.
    t = Now();
    const float* slabs = nullptr;
    if (size == 1) {
      slabs = mine.data();
    } else {
      int so = 0, ro = 0;
      for (std::size_t j = 0; j < P; ++j) {
        scounts[j] = static_cast<int>(my_count * col_width[j]);
        sdispls[j] = so;
        so += scounts[j];
        if (static_cast<int>(j) != rank)
          st.bytes_sent += static_cast<uint64_t>(scounts[j]) * sizeof(float);
        const uint64_t ci = ChunkShare(first, count, static_cast<int>(j), size, align).second;
        rcounts[j] = static_cast<int>(ci * width);
        rdispls[j] = ro;
        ro += rcounts[j];
      }
      ReserveFreshHuge(sendbuf, static_cast<std::size_t>(so));
      ReserveFreshHuge(recvbuf, static_cast<std::size_t>(ro));
      sendbuf.resize(static_cast<std::size_t>(so));
      recvbuf.resize(static_cast<std::size_t>(ro));
      for (std::size_t j = 0; j < P; ++j) {
        float* dst = sendbuf.data() + sdispls[j];
        for (uint64_t r = 0; r < my_count; ++r)
          std::memcpy(dst + r * col_width[j], mine.data() + r * cols + col_first[j],
                      col_width[j] * sizeof(float));
      }
      CheckMpi(MPI_Alltoallv(sendbuf.data(), scounts.data(), sdispls.data(), MPI_FLOAT,
                             recvbuf.data(), rcounts.data(), rdispls.data(), MPI_FLOAT, comm),
               "MPI_Alltoallv");
      slabs = recvbuf.data();
    }
    st.exchange_seconds += Now() - t;
    t = Now();
    if (tr) {
      SpillIo io(spill.spill_dir);
      for (std::size_t i = 0; i < P; ++i) {
        const auto [f, c] = ChunkShare(first, count, static_cast<int>(i), size, align);
        if (c == 0) continue;
        io([&] {
          tr->AddRows(f, c, size == 1 ? slabs : slabs + rdispls[i], size == 1 ? cols : width);
        });
      }
    }
    st.buffer_seconds += Now() - t;
    if (size == 1 && !own_reads) mine.swap(chunk);
    if (progress) progress->Advance(count);
  }
  if (tr) {
    uint32_t f = 0, c = 0;
    std::vector<float> columns;
    for (;;) {
      double t = Now();
      bool more = false;
      SpillIo(spill.spill_dir)([&] { more = tr->NextColumnBlock(f, c, columns); });
      st.merge_seconds += Now() - t;
      if (!more) break;
      t = Now();
      sink(f, c, columns);
      st.sink_seconds += Now() - t;
    }
    st.bytes_spilled = tr->bytes_spilled();
    st.runs_spilled = tr->runs_spilled();
  }
  return st;
}

}  // namespace prt
