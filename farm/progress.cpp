// Progress lines for long loops (see progress.h).
#include "farm/progress.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <utility>

namespace prt {

namespace {

double SteadySeconds() {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

}  // namespace

Progress::Progress(std::string label, uint64_t total, ProgressOptions options)
    : label_(std::move(label)), total_(total), options_(std::move(options)) {
  if (!options_.clock) options_.clock = SteadySeconds;
  start_s_ = options_.clock();
  last_log_s_ = start_s_;
  done_ = std::min(options_.already_done, total_);
}

void Progress::Advance(uint64_t units, uint64_t rate_units) {
  std::string line;
  {
    std::lock_guard lock(mutex_);
    done_ = std::min(total_, done_ + units);
    rate_units_ += rate_units;
    const double now = options_.clock();
    if (!options_.log || now - last_log_s_ < options_.log_interval_s) return;
    last_log_s_ = now;
    line = LineLocked();
  }
  spdlog::info("{}", line);
}

void Progress::Finish() {
  std::string line;
  {
    std::lock_guard lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (!options_.log) return;
    const ProgressSnapshot s = SnapshotLocked();
    line = fmt::format("[{}] done: {}/{} {} in {}", label_, s.done, s.total, options_.unit,
                       FormatDuration(s.elapsed_s));
    if (!options_.rate_unit.empty()) {
      line += fmt::format(", {} {}/s", FormatCount(s.rate_units_per_s), options_.rate_unit);
    }
    line += fmt::format(", {} {}/s", FormatCount(s.units_per_s), options_.unit);
    if (options_.already_done > 0) {
      line += fmt::format(" ({} {} done before)", std::min(options_.already_done, total_),
                          options_.unit);
    }
    if (options_.suffix) line += options_.suffix(0.0);
  }
  spdlog::info("{}", line);
}

ProgressSnapshot Progress::Snapshot() const {
  std::lock_guard lock(mutex_);
  return SnapshotLocked();
}

std::string Progress::Line() const {
  std::lock_guard lock(mutex_);
  return LineLocked();
}

ProgressSnapshot Progress::SnapshotLocked() const {
  ProgressSnapshot s;
  s.done = done_;
  s.total = total_;
  s.rate_units = rate_units_;
  s.elapsed_s = std::max(0.0, options_.clock() - start_s_);
  s.fraction = total_ == 0 ? 1.0 : static_cast<double>(done_) / static_cast<double>(total_);
  const uint64_t this_run = done_ - std::min(done_, options_.already_done);
  if (s.elapsed_s > 0) {
    s.units_per_s = static_cast<double>(this_run) / s.elapsed_s;
    s.rate_units_per_s = static_cast<double>(rate_units_) / s.elapsed_s;
  }
  if (done_ >= total_) {
    s.eta_s = 0;
  } else if (s.units_per_s > 0) {
    s.eta_s = static_cast<double>(total_ - done_) / s.units_per_s;
  }
  return s;
}

std::string Progress::LineLocked() const {
  const ProgressSnapshot s = SnapshotLocked();
  std::string line = fmt::format("[{}] {:.1f}% ({}/{} {})", label_, 100.0 * s.fraction, s.done,
                                 s.total, options_.unit);
  if (!options_.rate_unit.empty()) {
    line += fmt::format(" {} {}/s,", FormatCount(s.rate_units_per_s), options_.rate_unit);
  }
  line += fmt::format(" {} {}/s, elapsed {}, ETA {}", FormatCount(s.units_per_s), options_.unit,
                      FormatDuration(s.elapsed_s),
                      s.eta_s < 0 ? std::string("unknown") : FormatDuration(s.eta_s));
  if (options_.suffix) line += options_.suffix(s.eta_s);
  return line;
}

std::string Progress::FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "unknown";
  char buf[48];
  if (seconds < 1.0) {
    std::snprintf(buf, sizeof buf, "%.0fms", seconds * 1000.0);
  } else if (seconds < 60.0) {
    std::snprintf(buf, sizeof buf, "%.1fs", seconds);
  } else if (seconds < 3600.0) {
    const auto s = static_cast<long long>(std::llround(seconds));
    std::snprintf(buf, sizeof buf, "%lldm%02llds", s / 60, s % 60);
  } else {
    const auto m = static_cast<long long>(std::llround(seconds / 60.0));
    std::snprintf(buf, sizeof buf, "%lldh%02lldm", m / 60, m % 60);
  }
  return buf;
}

std::string Progress::FormatCount(double value) {
  if (!std::isfinite(value)) return "0";
  char buf[48];
  const double a = std::fabs(value);
  if (a < 1e3) {
    std::snprintf(buf, sizeof buf, "%.0f", value);
  } else if (a < 1e6) {
    std::snprintf(buf, sizeof buf, "%.1fk", value / 1e3);
  } else if (a < 1e9) {
    std::snprintf(buf, sizeof buf, "%.2fM", value / 1e6);
  } else {
    std::snprintf(buf, sizeof buf, "%.2fG", value / 1e9);
  }
  return buf;
}

}  // namespace prt
