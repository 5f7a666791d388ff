// Adaptive job sizes over the unfinished rows (see job_planner.h).
#include "farm/job_planner.h"

#include <algorithm>
#include <cmath>

namespace prt {

JobPlanner::JobPlanner(uint64_t total_rows, const std::vector<RowRange>& done,
                       const JobSizing& sizing)
    : total_(total_rows), sizing_(sizing) {
  sizing_.min_rows = std::max<uint64_t>(1, sizing_.min_rows);
  sizing_.max_rows = std::max(sizing_.min_rows, sizing_.max_rows);
  sizing_.initial_rows = std::clamp(sizing_.initial_rows, sizing_.min_rows, sizing_.max_rows);
  sizing_.workers = std::max(1, sizing_.workers);
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

uint64_t JobPlanner::unassigned_rows() const {
  uint64_t n = 0;
  for (const RowRange& g : gaps_) n += g.count;
  return n;
}

uint64_t JobPlanner::NextSize(int worker) const {
  const WorkerState s = (worker >= 0 && static_cast<std::size_t>(worker) < workers_.size())
                            ? workers_[worker]
                            : WorkerState{};
  double size = static_cast<double>(sizing_.initial_rows);
  if (s.rows_per_second > 0 && s.last_rows > 0) {
    size = std::min(s.rows_per_second * sizing_.job_seconds,
                    static_cast<double>(s.last_rows) * sizing_.growth);
  }
  // Guided tail: no job larger than half of an equal share of what is left.
  const double tail = static_cast<double>(unassigned_rows()) / (2.0 * sizing_.workers);
  size = std::min(size, std::max(tail, static_cast<double>(sizing_.min_rows)));
  const auto rows = static_cast<uint64_t>(std::llround(std::max(1.0, size)));
  return std::clamp(rows, sizing_.min_rows, sizing_.max_rows);
}

std::optional<RowRange> JobPlanner::Next(int worker) {
  if (gaps_.empty()) return std::nullopt;
  const uint64_t size = NextSize(worker);
  RowRange& gap = gaps_.front();
  RowRange job{gap.first, std::min(size, gap.count)};
  gap.first += job.count;
  gap.count -= job.count;
  if (gap.count == 0) gaps_.erase(gaps_.begin());
  State(worker).last_rows = job.count;
  return job;
}

void JobPlanner::Measured(int worker, uint64_t rows, double busy_seconds) {
  if (rows == 0 || !(busy_seconds > 0) || !std::isfinite(busy_seconds)) return;
  WorkerState& s = State(worker);
  const double rate = static_cast<double>(rows) / busy_seconds;
  // Exponential average: later jobs (warm caches, larger batches) weigh more.
  s.rows_per_second = s.rows_per_second > 0 ? 0.5 * s.rows_per_second + 0.5 * rate : rate;
  s.last_rows = rows;
}

void JobPlanner::Return(const RowRange& job) {
  if (job.count == 0) return;
  gaps_.push_back(job);
  std::sort(gaps_.begin(), gaps_.end(),
            [](const RowRange& a, const RowRange& b) { return a.first < b.first; });
}

}  // namespace prt
