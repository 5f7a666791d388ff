// The farm's collectives (see collectives.h).
#include "farm/collectives.h"

#include <mpi.h>

#include <algorithm>
#include <climits>
#include <cstdlib>

#include "farm/farm_options.h"
#include "farm/mpi_support.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

static_assert(sizeof(MPI_Fint) <= sizeof(int), "the communicator's handle is kept in an int");

// Counts of one MPI call stay far below INT_MAX: large buffers go in pieces of this many elements.
constexpr std::size_t kPiece = std::size_t{1} << 28;

MPI_Comm Comm(int handle) {
  return MPI_Comm_f2c(static_cast<MPI_Fint>(handle));
}

template <class T>
MPI_Datatype TypeOf();
template <>
MPI_Datatype TypeOf<int64_t>() {
  return MPI_INT64_T;
}
template <>
MPI_Datatype TypeOf<uint64_t>() {
  return MPI_UINT64_T;
}
template <>
MPI_Datatype TypeOf<double>() {
  return MPI_DOUBLE;
}
template <>
MPI_Datatype TypeOf<uint32_t>() {
  return MPI_UINT32_T;
}
template <>
MPI_Datatype TypeOf<int32_t>() {
  return MPI_INT32_T;
}

template <class T>
void AllReduce(int comm, std::span<T> v, MPI_Op op, const char* what) {
  for (std::size_t at = 0; at < v.size(); at += kPiece)
    CheckMpi(MPI_Allreduce(MPI_IN_PLACE, v.data() + at,
                           static_cast<int>(std::min(kPiece, v.size() - at)), TypeOf<T>(), op,
                           Comm(comm)),
             what);
}

template <class T>
void ReduceToRank0(int comm, int rank, std::span<T> v, MPI_Op op, const char* what) {
  for (std::size_t at = 0; at < v.size(); at += kPiece) {
    const int n = static_cast<int>(std::min(kPiece, v.size() - at));
    // Rank 0 receives in place; the others send their values and keep them.
    CheckMpi(MPI_Reduce(rank == 0 ? MPI_IN_PLACE : v.data() + at,
                        rank == 0 ? v.data() + at : nullptr, n, TypeOf<T>(), op, 0, Comm(comm)),
             what);
  }
}

template <class T>
void Concatenate(int comm, int rank, int size, std::span<const T> mine, std::span<T> all,
                 std::span<const uint64_t> counts, const char* what) {
  std::vector<int> c, displs;
  if (rank == 0) {
    if (counts.size() != static_cast<std::size_t>(size))
      throw RankFailure(std::string(what) + ": " + std::to_string(counts.size()) + " counts for " +
                        std::to_string(size) + " ranks");
    uint64_t at = 0;
    for (uint64_t k : counts) {
      if (k > INT_MAX || at > INT_MAX)
        throw RankFailure(std::string(what) + ": more than 2^31 elements in one gather");
      c.push_back(static_cast<int>(k));
      displs.push_back(static_cast<int>(at));
      at += k;
    }
    if (at != all.size())
      throw RankFailure(std::string(what) + ": the counts add up to " + std::to_string(at) +
                        ", not " + std::to_string(all.size()));
  }
  if (mine.size() > INT_MAX)
    throw RankFailure(std::string(what) + ": more than 2^31 elements from one rank");
  CheckMpi(MPI_Gatherv(mine.data(), static_cast<int>(mine.size()), TypeOf<T>(), all.data(),
                       c.data(), displs.data(), TypeOf<T>(), 0, Comm(comm)),
           what);
}

}  // namespace

Collectives::Collectives() {
  comm_ = static_cast<int>(MPI_Comm_c2f(MPI_COMM_WORLD));
  // Errors come back as codes (CheckMpi turns them into RankFailure naming the call), so that a
  // failing rank writes its report before the job is aborted.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

void Collectives::ShareFromRank0(void* data, std::size_t bytes, const char* what) const {
  char* p = static_cast<char*>(data);
  for (std::size_t at = 0; at < bytes; at += kPiece)
    CheckMpi(
        MPI_Bcast(p + at, static_cast<int>(std::min(kPiece, bytes - at)), MPI_BYTE, 0, Comm(comm_)),
        what);
}

void Collectives::ShareFromRank0(std::string& bytes, const char* what) const {
  uint64_t n = bytes.size();
  ShareValueFromRank0(n, what);
  bytes.resize(static_cast<std::size_t>(n));
  ShareFromRank0(bytes.data(), bytes.size(), what);
}

int Collectives::AgreeMax(int mine, const char* what) const {
  int all = mine;
  CheckMpi(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MAX, Comm(comm_)), what);
  return all;
}

int Collectives::AgreeMin(int mine, const char* what) const {
  int all = mine;
  CheckMpi(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, Comm(comm_)), what);
  return all;
}

void Collectives::SumEverywhere(std::span<int64_t> values, const char* what) const {
  AllReduce(comm_, values, MPI_SUM, what);
}
void Collectives::SumEverywhere(std::span<uint64_t> values, const char* what) const {
  AllReduce(comm_, values, MPI_SUM, what);
}
void Collectives::MaxEverywhere(std::span<double> values, const char* what) const {
  AllReduce(comm_, values, MPI_MAX, what);
}
void Collectives::SumOnRank0(std::span<uint64_t> values, const char* what) const {
  ReduceToRank0(comm_, rank_, values, MPI_SUM, what);
}
void Collectives::SumOnRank0(std::span<double> values, const char* what) const {
  ReduceToRank0(comm_, rank_, values, MPI_SUM, what);
}
void Collectives::MaxOnRank0(std::span<double> values, const char* what) const {
  ReduceToRank0(comm_, rank_, values, MPI_MAX, what);
}

std::vector<uint64_t> Collectives::GatherOnRank0(std::span<const uint64_t> mine,
                                                 const char* what) const {
  std::vector<uint64_t> all(rank_ == 0 ? mine.size() * static_cast<std::size_t>(size_) : 0);
  if (mine.size() > kPiece) throw RankFailure(std::string(what) + ": too many values to gather");
  CheckMpi(MPI_Gather(mine.data(), static_cast<int>(mine.size()), MPI_UINT64_T, all.data(),
                      static_cast<int>(mine.size()), MPI_UINT64_T, 0, Comm(comm_)),
           what);
  return all;
}

std::vector<uint64_t> Collectives::GatherEverywhere(std::span<const uint64_t> mine,
                                                    const char* what) const {
  std::vector<uint64_t> all(mine.size() * static_cast<std::size_t>(size_));
  if (mine.size() > kPiece) throw RankFailure(std::string(what) + ": too many values to gather");
  CheckMpi(MPI_Allgather(mine.data(), static_cast<int>(mine.size()), MPI_UINT64_T, all.data(),
                         static_cast<int>(mine.size()), MPI_UINT64_T, Comm(comm_)),
           what);
  return all;
}

void Collectives::ConcatenateOnRank0(std::span<const uint32_t> mine, std::span<uint32_t> all,
                                     std::span<const uint64_t> counts, const char* what) const {
  Concatenate(comm_, rank_, size_, mine, all, counts, what);
}
void Collectives::ConcatenateOnRank0(std::span<const int32_t> mine, std::span<int32_t> all,
                                     std::span<const uint64_t> counts, const char* what) const {
  Concatenate(comm_, rank_, size_, mine, all, counts, what);
}

void Collectives::SendTo(int rank, const void* data, std::size_t bytes, int tag,
                         const char* what) const {
  const char* p = static_cast<const char*>(data);
  for (std::size_t at = 0; at < bytes; at += kPiece)
    CheckMpi(MPI_Send(p + at, static_cast<int>(std::min(kPiece, bytes - at)), MPI_BYTE, rank, tag,
                      Comm(comm_)),
             what);
}

void Collectives::ReceiveFrom(int rank, void* data, std::size_t bytes, int tag,
                              const char* what) const {
  char* p = static_cast<char*>(data);
  for (std::size_t at = 0; at < bytes; at += kPiece)
    CheckMpi(MPI_Recv(p + at, static_cast<int>(std::min(kPiece, bytes - at)), MPI_BYTE, rank, tag,
                      Comm(comm_), MPI_STATUS_IGNORE),
             what);
}

void Collectives::WaitForEveryRank(const char* what) const {
  if (size_ > 1) CheckMpi(MPI_Barrier(Comm(comm_)), what);
}

void Collectives::AbortEveryRank(int exit_code) const {
  MPI_Abort(Comm(comm_), exit_code);
  std::_Exit(exit_code);  // MPI_Abort does not return; this keeps [[noreturn]] honest
}

}  // namespace prt
