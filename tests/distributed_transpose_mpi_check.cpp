// The distributed blocked transpose (farm/compression_phase.h, Cheslack-Postava et al. 2008 §4.4
// step 3) under mpirun with any number of ranks: a synthetic 203 × 97 matrix (odd sizes, so the
// column ranges and chunk shares are uneven) is streamed from rank 0 in chunks of 16 rows, each
// rank "row-transforms" its share (a row-dependent map, so that rows landing on the wrong rank
// or at the wrong index would show), and the owned column blocks gathered on rank 0 must equal
// the in-memory transpose of the transformed rows bit for bit: once with a 1 KiB budget (every
// rank spills many runs) and once with 1 GiB (no spill). Exit 0 when all holds, 1 otherwise.
#include <mpi.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "farm/distributed_transpose.h"

namespace {

constexpr uint64_t kRows = 203;
constexpr uint32_t kCols = 97;

float Value(uint64_t r, uint32_t c) {
  uint64_t x = r * 1000003u + c * 7919u + 12345u;
  x ^= x >> 17;
  x *= 0x9E3779B97F4A7C15ull;
  return static_cast<float>(static_cast<double>(x >> 40) / 16777216.0 - 0.5);
}

// The "row transform": depends on the global row index.
float Prepared(uint64_t r, float v) {
  return v * static_cast<float>(r + 1) + static_cast<float>(r);
}

// Returns the number of failures seen on rank 0.
int Check(uint64_t budget, bool expect_spill, int rank, int size) {
  prt::BlockSpillOptions spill;
  spill.memory_budget_bytes = budget;
  spill.columns_per_block = 5;
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("prt-transpose-check-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  spill.spill_dir = dir.string();
  const auto [cb, ce] = prt::OwnedColumns(kCols, rank, size);
  std::vector<float> owned(static_cast<std::size_t>(ce - cb) * kRows, -1.0f);
  const prt::TransposeStats st = prt::DistributedTranspose(
      MPI_COMM_WORLD, kRows, kCols, 16,
      [](uint64_t first, uint64_t count, float* out) {
        for (uint64_t r = 0; r < count; ++r)
          for (uint32_t c = 0; c < kCols; ++c) out[r * kCols + c] = Value(first + r, c);
      },
      [](uint64_t first, uint64_t count, float* rows) {
        for (uint64_t r = 0; r < count; ++r)
          for (uint32_t c = 0; c < kCols; ++c)
            rows[r * kCols + c] = Prepared(first + r, rows[r * kCols + c]);
      },
      spill,
      [&](uint32_t first, uint32_t count, std::vector<float>& columns) {
        std::memcpy(owned.data() + static_cast<std::size_t>(first - cb) * kRows, columns.data(),
                    static_cast<std::size_t>(count) * kRows * sizeof(float));
      });
  std::filesystem::remove_all(dir);
  int failures = 0;
  const int spilled = st.runs_spilled > 0 ? 1 : 0;
  int all_spilled = 0, any_spilled = 0;
  MPI_Reduce(&spilled, &all_spilled, 1, MPI_INT, MPI_MIN, 0, MPI_COMM_WORLD);
  MPI_Reduce(&spilled, &any_spilled, 1, MPI_INT, MPI_MAX, 0, MPI_COMM_WORLD);
  // Gather every rank's columns on rank 0 (column-major, rank order = column order).
  const int n = static_cast<int>(owned.size());
  std::vector<int> counts(static_cast<std::size_t>(size)), displs(static_cast<std::size_t>(size));
  MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  for (int r = 1; r < size; ++r) displs[r] = displs[r - 1] + counts[r - 1];
  std::vector<float> all(static_cast<std::size_t>(kRows) * kCols);
  MPI_Gatherv(owned.data(), n, MPI_FLOAT, all.data(), counts.data(), displs.data(), MPI_FLOAT, 0,
              MPI_COMM_WORLD);
  if (rank != 0) return 0;
  std::vector<float> ref(all.size());
  for (uint64_t r = 0; r < kRows; ++r)
    for (uint32_t c = 0; c < kCols; ++c) ref[c * kRows + r] = Prepared(r, Value(r, c));
  if (std::memcmp(all.data(), ref.data(), ref.size() * sizeof(float)) != 0) {
    std::fprintf(stderr, "FAIL: budget %llu: the distributed transpose differs from memory\n",
                 static_cast<unsigned long long>(budget));
    ++failures;
  }
  if (expect_spill && !all_spilled) {
    std::fprintf(stderr, "FAIL: budget %llu: some rank did not spill\n",
                 static_cast<unsigned long long>(budget));
    ++failures;
  }
  if (!expect_spill && any_spilled) {
    std::fprintf(stderr, "FAIL: budget %llu: a rank spilled\n",
                 static_cast<unsigned long long>(budget));
    ++failures;
  }
  std::printf(
      "budget %llu bytes on %d rank(s): rank 0 sent %llu bytes, spilled %llu bytes in "
      "%llu runs: %s\n",
      static_cast<unsigned long long>(budget), size, static_cast<unsigned long long>(st.bytes_sent),
      static_cast<unsigned long long>(st.bytes_spilled),
      static_cast<unsigned long long>(st.runs_spilled), failures ? "FAIL" : "ok");
  return failures;
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  int failures = 0;
  try {
    failures += Check(1024, true, rank, size);
    failures += Check(1ull << 30, false, rank, size);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rank %d: %s\n", rank, e.what());
    MPI_Abort(MPI_COMM_WORLD, 1);
  }
  MPI_Bcast(&failures, 1, MPI_INT, 0, MPI_COMM_WORLD);
  MPI_Finalize();
  return failures == 0 ? 0 : 1;
}
