// Dynamic job planning on rank 0 (docs/farm.md, "Jobs"): the items still to do are cut into
// contiguous ranges handed out one at a time to whichever rank asks. A job's size adapts per rank
// so that it takes about `job_seconds`, in units of cost rather than items: a phase may say what
// a range of items costs relative to another (JobSizing::cost: a background pixel next to nothing,
// a pixel that sees the model 1); without it every item costs 1. The first job of a rank is small
// (initial_rows items) and calibrates the rank's seconds per unit of cost; every later job is
// `job_seconds` of cost at that rate, growing at most `growth`× in cost per job, and near the end
// no job exceeds remaining cost / (2 · workers), so that all ranks finish together (guided
// scheduling). A job that ran slower than its rank's average resets the average to its own rate
// at once (a job far over target makes the next one small); faster jobs move it halfway.
// No MPI and no clock here: the coordinator feeds measured busy times.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

namespace prt {

struct RowRange {
  uint64_t first = 0;
  uint64_t count = 0;
  uint64_t end() const { return first + count; }
  bool operator==(const RowRange&) const = default;
};

// The relative cost of items [first, first + count) of a batch: non-negative, additive over
// adjacent ranges, and > 0 for a non-empty range (see ItemCostOfWeights).
using ItemCost = std::function<double(uint64_t first, uint64_t count)>;

// An ItemCost from one weight per item (prefix sums: O(1) per range). Weights below `floor`
// count as `floor`, so that a range of "free" items still costs something and job sizes stay
// finite.
ItemCost ItemCostOfWeights(const std::vector<double>& weights, double floor = 1e-6);

struct JobSizing {
  double job_seconds = 4.0;
  uint64_t initial_rows = 16;   // first job of every worker (items)
  uint64_t min_rows = 1;        // items
  uint64_t max_rows = 1 << 20;  // items
  double growth = 2.0;          // at most this factor of cost between a worker's consecutive jobs
  int workers = 1;              // ranks computing jobs (for the guided tail)
  ItemCost cost;                // empty: every item costs 1
};

class JobPlanner {
 public:
  // `done`: ranges finished before (checkpoints); may overlap and come in any order.
  JobPlanner(uint64_t total_rows, const std::vector<RowRange>& done, const JobSizing& sizing);

  // The next job for `worker`, or nothing when every row has been handed out.
  std::optional<RowRange> Next(int worker);
  // A job of `worker` finished: `job` took `busy_seconds` of computing.
  void Measured(int worker, const RowRange& job, double busy_seconds);
  // Hands a job's rows back (its worker failed); they are handed out again first.
  void Return(const RowRange& job);

  uint64_t total_rows() const { return total_; }
  uint64_t done_before_rows() const { return done_before_; }  // rows covered by `done`
  uint64_t unassigned_rows() const;
  // Unfinished ranges in row order, for reports and tests.
  const std::vector<RowRange>& gaps() const { return gaps_; }
  // The size the next job of `worker` would have (before clipping to its gap), in items.
  uint64_t NextSize(int worker) const;
  // The cost of items [first, first + count) (count without a cost function).
  double Cost(uint64_t first, uint64_t count) const;
  // The cost the next job of `worker` aims at.
  double NextCost(int worker) const;
  // The seconds `job` should take on `worker` at its measured rate (−1 before a measurement).
  double PredictedSeconds(int worker, const RowRange& job) const;

 private:
  struct WorkerState {
    double last_cost = 0;         // of its last job (handed out, then as measured)
    double seconds_per_cost = 0;  // 0 until measured
  };
  WorkerState& State(int worker);
  const WorkerState* Find(int worker) const;
  double UnassignedCost() const;
  // The most items from `first` (at most `limit`) whose cost stays within `budget`; at least
  // min_rows.
  uint64_t ItemsWithin(uint64_t first, uint64_t limit, double budget) const;

  uint64_t total_;
  uint64_t done_before_ = 0;
  JobSizing sizing_;
  std::vector<RowRange> gaps_;  // sorted, disjoint
  std::vector<WorkerState> workers_;
};

}  // namespace prt
