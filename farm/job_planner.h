// Dynamic job planning on rank 0 (docs/farm.md, "Jobs"): the spatial samples still to do are
// cut into contiguous ranges handed out one at a time to whichever rank asks. A job's size
// adapts per rank so that it takes about `job_seconds`: the first job is small, then the size
// follows the rank's measured rows/s (growing at most `growth`× per job), and near the end jobs
// shrink to remaining / (2 · workers) so that all ranks finish together (guided scheduling).
// No MPI and no clock here: the coordinator feeds measured busy times.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

namespace prt {

struct RowRange {
  uint64_t first = 0;
  uint64_t count = 0;
  uint64_t end() const { return first + count; }
  bool operator==(const RowRange&) const = default;
};

struct JobSizing {
  double job_seconds = 4.0;
  uint64_t initial_rows = 16;  // first job of every worker
  uint64_t min_rows = 1;
  uint64_t max_rows = 1 << 20;
  double growth = 2.0;  // at most this factor between a worker's consecutive jobs
  int workers = 1;      // ranks computing jobs (for the guided tail)
};

class JobPlanner {
 public:
  // `done`: ranges finished before (checkpoints); may overlap and come in any order.
  JobPlanner(uint64_t total_rows, const std::vector<RowRange>& done, const JobSizing& sizing);

  // The next job for `worker`, or nothing when every row has been handed out.
  std::optional<RowRange> Next(int worker);
  // A job of `worker` finished: `rows` rows in `busy_seconds` of computing.
  void Measured(int worker, uint64_t rows, double busy_seconds);
  // Hands a job's rows back (its worker failed); they are handed out again first.
  void Return(const RowRange& job);

  uint64_t total_rows() const { return total_; }
  uint64_t done_before_rows() const { return done_before_; }  // rows covered by `done`
  uint64_t unassigned_rows() const;
  // Unfinished ranges in row order, for reports and tests.
  const std::vector<RowRange>& gaps() const { return gaps_; }
  // The size the next job of `worker` would have (before clipping to a gap).
  uint64_t NextSize(int worker) const;

 private:
  struct WorkerState {
    uint64_t last_rows = 0;
    double rows_per_second = 0;  // 0 until measured
  };
  WorkerState& State(int worker);

  uint64_t total_;
  uint64_t done_before_ = 0;
  JobSizing sizing_;
  std::vector<RowRange> gaps_;  // sorted, disjoint
  std::vector<WorkerState> workers_;
};

}  // namespace prt
