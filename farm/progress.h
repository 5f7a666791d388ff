// Progress of a long loop: percentage, rate and ETA, logged with spdlog at most every few
// seconds. Every long loop in prtfarm reports through this class, so that the farm, the
// packager and the benchmarks print the same kind of line:
//   [brute] 42.0% (4200/10000 samples) 1.25 Mrays/s, 3.1k samples/s, elapsed 1.4s, ETA 1.9s
// Thread-safe: Advance() may be called from TBB tasks.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <string>

namespace prt {

struct ProgressOptions {
  std::string unit = "items";     // what `total` counts ("samples", "rows", "blocks")
  std::string rate_unit;          // optional second counter shown as a rate ("rays")
  double log_interval_s = 5.0;    // at most one log line per interval (0: every Advance)
  bool log = true;                // false: only compute (for tests and quiet ranks)
  uint64_t already_done = 0;      // units done before this run (e.g. re-used checkpoints):
                                  // they count towards the percentage, not towards the rate
  std::function<double()> clock;  // seconds; defaults to a steady clock (tests inject one)
  // Appended to every line, given this loop's ETA (−1 unknown): the whole run's ETA
  // (farm/run_eta.h).
  std::function<std::string(double eta_s)> suffix;
};

struct ProgressSnapshot {
  uint64_t done = 0;  // units done, including already_done
  uint64_t total = 0;
  uint64_t rate_units = 0;  // second counter, this run only
  double elapsed_s = 0;
  double fraction = 0;     // done / total in [0, 1] (1 when total is 0)
  double units_per_s = 0;  // this run's units / elapsed (0 before any time has passed)
  double rate_units_per_s = 0;
  double eta_s = -1;  // remaining / units_per_s; −1 while unknown
};

class Progress {
 public:
  Progress(std::string label, uint64_t total, ProgressOptions options = {});

  // Adds finished units (and rate units such as rays); logs when the interval has elapsed.
  void Advance(uint64_t units, uint64_t rate_units = 0);
  // Logs the final line ("done in ...") once; later calls do nothing.
  void Finish();

  ProgressSnapshot Snapshot() const;
  // The line Advance() logs, for the current state.
  std::string Line() const;

  // "950ms", "12.3s", "4m05s", "2h03m".
  static std::string FormatDuration(double seconds);
  // "950", "12.3k", "4.56M", "7.89G".
  static std::string FormatCount(double value);

 private:
  ProgressSnapshot SnapshotLocked() const;
  std::string LineLocked() const;

  std::string label_;
  uint64_t total_;
  ProgressOptions options_;
  double start_s_;
  double last_log_s_;
  uint64_t done_;
  uint64_t rate_units_ = 0;
  bool finished_ = false;
  mutable std::mutex mutex_;
};

}  // namespace prt
