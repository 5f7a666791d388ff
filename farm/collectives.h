// The farm's collectives, named by what they mean (docs/architecture.md, "Where MPI lives"):
// share rank 0's bytes with every rank, agree on a status, add up sums, gather small per-rank
// figures, move a rank's bytes to rank 0. Every phase that needs more than the job loop
// (farm/job_loop.h) calls these; none calls MPI itself. The interface has no MPI types: the
// communicator is held as its Fortran handle (MPI_Comm_c2f), which is an int in every MPI.
//
// Every call here is collective over the communicator unless it says otherwise (SendTo /
// ReceiveFrom are point to point), and throws RankFailure naming what it was doing when MPI
// reports an error. Messages of any size are cut into pieces an int count can address.
//
// Determinism: SumEverywhere/SumOnRank0 of integers are exact, hence the same for any number of
// ranks; sums of doubles are not (MPI may add them in any order), so they are used only for
// figures that go to report.json, never for a file whose bytes must not depend on the ranks.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace prt {

class Collectives {
 public:
  // MPI_COMM_WORLD.
  Collectives();
  int rank() const { return rank_; }
  int size() const { return size_; }

  // ---- rank 0's values on every rank
  // `bytes` bytes at `data`, from rank 0 to every rank (the others' buffers are overwritten).
  void ShareFromRank0(void* data, std::size_t bytes, const char* what) const;
  // A value of a plain type (a struct of numbers sent as its bytes).
  template <class T>
  void ShareValueFromRank0(T& value, const char* what) const {
    static_assert(std::is_trivially_copyable_v<T>);
    ShareFromRank0(&value, sizeof(T), what);
  }
  // Rank 0's string (its size first): the others' are resized and overwritten.
  void ShareFromRank0(std::string& bytes, const char* what) const;
  // Rank 0's vector (its size first): the others' are resized and overwritten.
  template <class T>
  void ShareVectorFromRank0(std::vector<T>& v, const char* what) const {
    static_assert(std::is_trivially_copyable_v<T>);
    uint64_t n = v.size();
    ShareValueFromRank0(n, what);
    v.resize(static_cast<std::size_t>(n));
    ShareFromRank0(v.data(), v.size() * sizeof(T), what);
  }

  // ---- agreement
  int AgreeMax(int mine, const char* what) const;  // the largest value of every rank's
  int AgreeMin(int mine, const char* what) const;  // the smallest

  // ---- sums and maxima, element by element
  // On every rank: exact integer sums (the same bytes for any number of ranks).
  void SumEverywhere(std::span<int64_t> values, const char* what) const;
  void SumEverywhere(std::span<uint64_t> values, const char* what) const;
  void MaxEverywhere(std::span<double> values, const char* what) const;
  // On rank 0 only (the others' spans are left as they were).
  void SumOnRank0(std::span<uint64_t> values, const char* what) const;
  void SumOnRank0(std::span<double> values, const char* what) const;  // report figures only
  void MaxOnRank0(std::span<double> values, const char* what) const;

  // ---- gathers of per-rank figures
  // Rank 0 gets every rank's `mine` (rank r's at [r·k, r·k + k), all ranks giving k values); the
  // others get an empty vector.
  std::vector<uint64_t> GatherOnRank0(std::span<const uint64_t> mine, const char* what) const;
  // The same on every rank.
  std::vector<uint64_t> GatherEverywhere(std::span<const uint64_t> mine, const char* what) const;
  // Rank 0 gets every rank's elements one after the other in rank order (ranks give different
  // counts; `all` on rank 0 must hold their total, `counts` on rank 0 lists them).
  void ConcatenateOnRank0(std::span<const uint32_t> mine, std::span<uint32_t> all,
                          std::span<const uint64_t> counts, const char* what) const;
  void ConcatenateOnRank0(std::span<const int32_t> mine, std::span<int32_t> all,
                          std::span<const uint64_t> counts, const char* what) const;

  // ---- one rank's bytes to another (point to point, any size; `tag` tells streams apart)
  void SendTo(int rank, const void* data, std::size_t bytes, int tag, const char* what) const;
  void ReceiveFrom(int rank, void* data, std::size_t bytes, int tag, const char* what) const;

  // Every rank waits here until all have arrived (files one rank wrote are then there for all).
  void WaitForEveryRank(const char* what) const;
  // Ends the whole job at once (every rank, blocked in MPI or not) with `exit_code`.
  [[noreturn]] void AbortEveryRank(int exit_code) const;

 private:
  int comm_ = 0;  // MPI_Comm_c2f(MPI_COMM_WORLD)
  int rank_ = 0;
  int size_ = 1;
};

}  // namespace prt
