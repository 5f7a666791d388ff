// MPI for the programs above farm/ (prt-bench): the ranks of a run without <mpi.h> in the
// interface, so that MPI stays in farm/ (docs/architecture.md, "Where MPI lives"). Every call is
// collective over MPI_COMM_WORLD unless it says otherwise; MPI errors abort the job (MPI's
// default).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace prt {

class MpiSession {
 public:
  // MPI_Init; throws std::runtime_error when it fails. One session per process.
  MpiSession(int* argc, char*** argv);
  ~MpiSession();  // MPI_Finalize
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;

  int rank() const { return rank_; }
  int size() const { return size_; }

  void Barrier() const;
  // Rank r owns rows [SliceBegin(rows, r, size), SliceBegin(rows, r + 1, size)): contiguous
  // slices whose sizes differ by at most one. Local, no communication.
  static std::size_t SliceBegin(std::size_t rows, int rank, int size);
  // Every rank computed its slice (SliceBegin) of a rows × cols float matrix in `data` (which
  // holds the whole matrix on every rank); afterwards every rank holds every slice.
  void AllGatherRowSlices(float* data, std::size_t rows, std::size_t cols) const;
  uint64_t SumOverRanks(uint64_t value) const;
  double SumOverRanks(double value) const;
  // Every rank's text concatenated in rank order, on rank 0 ("" on the others).
  std::string GatherText(const std::string& mine) const;
  // Rank 0's value, on every rank.
  int Broadcast(int value) const;
  // Ends every rank of the job with `code` (local: a rank that cannot go on).
  [[noreturn]] void Abort(int code) const;

 private:
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace prt
