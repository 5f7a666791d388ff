// Adaptive job sizes over the unfinished rows (see job_planner.h).
#include "farm/job_planner.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

namespace prt {

ItemCost ItemCostOfWeights(const std::vector<double>& weights, double floor) {
  auto prefix = std::make_shared<std::vector<double>>(weights.size() + 1, 0.0);
  for (std::size_t i = 0; i < weights.size(); ++i) {
    const double w = std::isfinite(weights[i]) ? std::max(weights[i], floor) : floor;
    (*prefix)[i + 1] = (*prefix)[i] + w;
  }
  return [prefix, floor](uint64_t first, uint64_t count) {
    const uint64_t n = prefix->size() - 1;
    const uint64_t a = std::min(first, n), b = std::min(first + count, n);
    // Items past the weights (none in a batch built right) cost the floor.
    return (*prefix)[b] - (*prefix)[a] + static_cast<double>(count - (b - a)) * floor;
  };
}

JobPlanner::JobPlanner(uint64_t total_rows, const std::vector<RowRange>& done,
                       const JobSizing& sizing)
    : total_(total_rows), sizing_(sizing) {
  sizing_.min_rows = std::max<uint64_t>(1, sizing_.min_rows);
  sizing_.max_rows = std::max(sizing_.min_rows, sizing_.max_rows);
  sizing_.initial_rows = std::clamp(sizing_.initial_rows, sizing_.min_rows, sizing_.max_rows);
  sizing_.workers = std::max(1, sizing_.workers);
  if (!(sizing_.growth >= 1.0)) sizing_.growth = 1.0;
  std::vector<RowRange> sorted;
  for (const RowRange& r : done) {
    const uint64_t first = std::min(r.first, total_);
    const uint64_t end = std::min(r.first + r.count, total_);
    if (end > first) sorted.push_back({first, end - first});
  }
  std::sort(sorted.begin(), sorted.end(),
            [](const RowRange& a, const RowRange& b) { return a.first < b.first; });
  uint64_t cursor = 0;
  for (const RowRange& r : sorted) {
    if (r.first > cursor) gaps_.push_back({cursor, r.first - cursor});
    if (r.end() > cursor) {
      done_before_ += r.end() - std::max(cursor, r.first);
      cursor = r.end();
    }
  }
  if (cursor < total_) gaps_.push_back({cursor, total_ - cursor});
}

JobPlanner::WorkerState& JobPlanner::State(int worker) {
  if (worker < 0) worker = 0;
  if (static_cast<std::size_t>(worker) >= workers_.size()) workers_.resize(worker + 1);
  return workers_[worker];
}

const JobPlanner::WorkerState* JobPlanner::Find(int worker) const {
  if (worker < 0 || static_cast<std::size_t>(worker) >= workers_.size()) return nullptr;
  return &workers_[worker];
}

uint64_t JobPlanner::unassigned_rows() const {
  uint64_t n = 0;
  for (const RowRange& g : gaps_) n += g.count;
  return n;
}

double JobPlanner::Cost(uint64_t first, uint64_t count) const {
  if (count == 0) return 0;
  return sizing_.cost ? sizing_.cost(first, count) : static_cast<double>(count);
}

double JobPlanner::UnassignedCost() const {
  double c = 0;
  for (const RowRange& g : gaps_) c += Cost(g.first, g.count);
  return c;
}

uint64_t JobPlanner::ItemsWithin(uint64_t first, uint64_t limit, double budget) const {
  limit = std::min(limit, sizing_.max_rows);
  uint64_t lo = 0, hi = limit;  // the most items whose cost is ≤ budget: in [lo, hi]
  if (!sizing_.cost) {
    lo = hi =
        static_cast<uint64_t>(std::clamp(std::floor(budget), 0.0, static_cast<double>(limit)));
  }
  while (lo < hi) {
    const uint64_t mid = lo + (hi - lo + 1) / 2;
    if (Cost(first, mid) <= budget) {
      lo = mid;
    } else {
      hi = mid - 1;
    }
  }
  // The count whose cost is nearest the budget (a half rounds up).
  if (lo < limit && Cost(first, lo + 1) - budget <= budget - Cost(first, lo)) ++lo;
  return std::clamp(lo, sizing_.min_rows, sizing_.max_rows);
}

double JobPlanner::NextCost(int worker) const {
  const WorkerState* s = Find(worker);
  double cost = std::numeric_limits<double>::infinity();
  if (s && s->seconds_per_cost > 0) {
    cost = sizing_.job_seconds / s->seconds_per_cost;
    if (s->last_cost > 0) cost = std::min(cost, s->last_cost * sizing_.growth);
  }
  // Guided tail: no job costs more than half of an equal share of what is left.
  return std::min(cost, UnassignedCost() / (2.0 * sizing_.workers));
}

uint64_t JobPlanner::NextSize(int worker) const {
  if (gaps_.empty()) return sizing_.min_rows;
  const uint64_t first = gaps_.front().first;
  uint64_t rows = ItemsWithin(first, total_ - first, NextCost(worker));
  const WorkerState* s = Find(worker);
  // Before its first measurement a worker gets initial_rows items, to calibrate its rate.
  if (!s || s->seconds_per_cost <= 0) rows = std::min(rows, sizing_.initial_rows);
  return rows;
}

std::optional<RowRange> JobPlanner::Next(int worker) {
  if (gaps_.empty()) return std::nullopt;
  const uint64_t size = NextSize(worker);
  RowRange& gap = gaps_.front();
  RowRange job{gap.first, std::min(size, gap.count)};
  gap.first += job.count;
  gap.count -= job.count;
  if (gap.count == 0) gaps_.erase(gaps_.begin());
  State(worker).last_cost = Cost(job.first, job.count);
  return job;
}

double JobPlanner::PredictedSeconds(int worker, const RowRange& job) const {
  const WorkerState* s = Find(worker);
  if (!s || s->seconds_per_cost <= 0) return -1;
  return Cost(job.first, job.count) * s->seconds_per_cost;
}

void JobPlanner::Measured(int worker, const RowRange& job, double busy_seconds) {
  const double cost = Cost(job.first, job.count);
  if (!(cost > 0) || !(busy_seconds > 0) || !std::isfinite(busy_seconds)) return;
  WorkerState& s = State(worker);
  const double spc = busy_seconds / cost;
  // Slower than the average: believed at once, so that a job far over its target makes the next
  // one small (its items were dearer than the cost model said, and so may the next ones be).
  // Faster: averaged (later jobs, with warm caches and larger batches, weigh half).
  s.seconds_per_cost = (s.seconds_per_cost <= 0 || spc > s.seconds_per_cost)
                           ? spc
                           : 0.5 * s.seconds_per_cost + 0.5 * spc;
  s.last_cost = cost;
}

void JobPlanner::Return(const RowRange& job) {
  if (job.count == 0) return;
  gaps_.push_back(job);
  std::sort(gaps_.begin(), gaps_.end(),
            [](const RowRange& a, const RowRange& b) { return a.first < b.first; });
}

}  // namespace prt
