// Rank 0's sum of the sampling jobs' Monte-Carlo variance (formats/transport_variance.h): each
// new job's record is appended to checkpoints/variance.log (made durable with the rows, before
// the job's journal line); a resumed run adds the logged records of the jobs it re-uses; the
// finalize phase writes the total as run/transport.variance.
//
// Where the ranks write their own rows (docs/farm.md, "Where the rows go") the records do not
// travel to rank 0 either: each computing rank appends its jobs' records to its own
// checkpoints/variance.rank-<r>.log (RankVarianceLog), durably before its result leaves, and
// keeps their running sum, which the finalize phase reduces onto rank 0. The next run's
// VarianceAccumulator merges the rank logs into variance.log, so that a resume finds every
// journaled job's record wherever it was computed.
//
// Every sum here is exact (integers, formats/transport_variance.h), so the total, and the bytes of
// transport.variance, are the same whatever order the jobs finish in, whichever rank computed
// them and however many ranks reduce them (docs/farm.md, "Determinism").
#pragma once

#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "formats/run_folder.h"
#include "formats/transport_variance.h"
#include "vocabulary/scene_geometry.h"

namespace prt {

class VarianceAccumulator {
 public:
  // `fresh`: the log starts empty; else the records already in it are kept for Reuse().
  VarianceAccumulator(const RunFolder& folder, std::vector<uint64_t> group_rows, int cubemap_n,
                      int rays_per_texel, bool fresh);
  ~VarianceAccumulator();
  VarianceAccumulator(const VarianceAccumulator&) = delete;
  VarianceAccumulator& operator=(const VarianceAccumulator&) = delete;

  // Empty sums of this run's shape (a job fills them with AddRow).
  TransportVariance Empty() const;
  // A new job's sums: added, and appended to the log (durable after Sync()).
  void Record(const std::string& phase, uint64_t first, uint64_t count,
              const TransportVariance& sums);
  // A re-used job: its logged sums are added. False when the log does not hold them (a run of
  // an older prt-farm, a torn log): the rows stay uncovered (TransportVariance::rows_covered).
  bool Reuse(const std::string& phase, uint64_t first, uint64_t count);
  void Sync();
  // run/transport.variance, durably.
  void WriteFile() const;
  const TransportVariance& total() const { return total_; }
  // Adds sums recorded elsewhere (the ranks' RankVarianceLog totals, reduced).
  void AddTotal(const TransportVariance& sums) { total_.Add(sums); }

 private:
  std::string log_path_, file_path_;
  TransportVariance total_;
  std::map<std::tuple<std::string, uint64_t, uint64_t>, TransportVariance> logged_;
  int fd_ = -1;
  uint64_t end_ = 0;
  bool dirty_ = false;
};

// A computing rank's own variance records (see above). Not thread-safe: one per rank, used by the
// thread that computes its jobs.
class RankVarianceLog {
 public:
  RankVarianceLog(const RunFolder& folder, int rank, TransportVariance empty);
  ~RankVarianceLog();
  RankVarianceLog(const RankVarianceLog&) = delete;
  RankVarianceLog& operator=(const RankVarianceLog&) = delete;

  // Appends the job's record (durable after Sync()) and adds it to total().
  void Record(const std::string& phase, uint64_t first, uint64_t count,
              const TransportVariance& sums);
  void Sync();
  const TransportVariance& total() const { return total_; }

 private:
  std::string path_;
  TransportVariance total_;
  int fd_ = -1;
  bool dirty_ = false;
};

// checkpoints/variance.rank-<rank>.log
std::string RankVarianceLogPath(const RunFolder& folder, int rank);

}  // namespace prt
