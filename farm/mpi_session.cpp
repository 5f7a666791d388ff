// MPI for the programs above farm/ (see mpi_session.h).
#include "farm/mpi_session.h"

#include <mpi.h>

#include <cstdlib>
#include <stdexcept>
#include <vector>

namespace prt {

MpiSession::MpiSession(int* argc, char*** argv) {
  if (MPI_Init(argc, argv) != MPI_SUCCESS) throw std::runtime_error("MPI_Init failed");
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

MpiSession::~MpiSession() {
  MPI_Finalize();
}

void MpiSession::Barrier() const {
  MPI_Barrier(MPI_COMM_WORLD);
}

std::size_t MpiSession::SliceBegin(std::size_t rows, int rank, int size) {
  return rows * static_cast<std::size_t>(rank) / static_cast<std::size_t>(size);
}

void MpiSession::AllGatherRowSlices(float* data, std::size_t rows, std::size_t cols) const {
  std::vector<int> counts(static_cast<std::size_t>(size_)), displs(counts.size());
  for (int r = 0; r < size_; ++r) {
    counts[r] = static_cast<int>(SliceBegin(rows, r + 1, size_) - SliceBegin(rows, r, size_));
    displs[r] = static_cast<int>(SliceBegin(rows, r, size_));
  }
  MPI_Datatype row;
  MPI_Type_contiguous(static_cast<int>(cols), MPI_FLOAT, &row);
  MPI_Type_commit(&row);
  MPI_Allgatherv(MPI_IN_PLACE, 0, row, data, counts.data(), displs.data(), row, MPI_COMM_WORLD);
  MPI_Type_free(&row);
}

uint64_t MpiSession::SumOverRanks(uint64_t value) const {
  MPI_Allreduce(MPI_IN_PLACE, &value, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
  return value;
}

double MpiSession::SumOverRanks(double value) const {
  MPI_Allreduce(MPI_IN_PLACE, &value, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return value;
}

std::string MpiSession::GatherText(const std::string& mine) const {
  int len = static_cast<int>(mine.size());
  std::vector<int> lens(static_cast<std::size_t>(size_)), displs(lens.size());
  MPI_Gather(&len, 1, MPI_INT, lens.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  std::string all;
  if (rank_ == 0) {
    int total = 0;
    for (int r = 0; r < size_; ++r) {
      displs[r] = total;
      total += lens[r];
    }
    all.resize(static_cast<std::size_t>(total));
  }
  MPI_Gatherv(mine.data(), len, MPI_CHAR, all.data(), lens.data(), displs.data(), MPI_CHAR, 0,
              MPI_COMM_WORLD);
  return all;
}

int MpiSession::Broadcast(int value) const {
  MPI_Bcast(&value, 1, MPI_INT, 0, MPI_COMM_WORLD);
  return value;
}

void MpiSession::Abort(int code) const {
  MPI_Abort(MPI_COMM_WORLD, code);
  std::abort();  // MPI_Abort does not return; this keeps [[noreturn]] honest
}

}  // namespace prt
