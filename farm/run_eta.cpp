// The whole run's ETA (see run_eta.h).
#include "farm/run_eta.h"

#include <chrono>

#include "farm/progress.h"

namespace prt {

RunEta::RunEta(std::function<double()> clock) : clock_(std::move(clock)) {
  if (!clock_) {
    clock_ = [] {
      using C = std::chrono::steady_clock;
      return std::chrono::duration<double>(C::now().time_since_epoch()).count();
    };
  }
  start_s_ = clock_();
}

void RunEta::SetSteps(std::vector<RunStep> steps) {
  std::lock_guard lock(mutex_);
  steps_ = std::move(steps);
  done_s_.assign(steps_.size(), -1.0);
  current_ = -1;
}

double RunEta::CostLocked(const RunStep& s) const {
  for (const auto& [kind, cost] : measured_cost_)
    if (kind == s.kind) return cost * s.units;
  return s.prior_seconds_per_unit * speed_ * s.units;
}

void RunEta::StepStarted(const std::string& name) {
  std::lock_guard lock(mutex_);
  for (std::size_t i = 0; i < steps_.size(); ++i) {
    if (steps_[i].name != name || done_s_[i] >= 0) continue;
    current_ = static_cast<int>(i);
    current_start_s_ = clock_();
    const double elapsed = current_start_s_ - start_s_;
    history_.push_back({elapsed, name, elapsed + RemainingLocked(-1)});
    return;
  }
}

void RunEta::StepFinished(const std::string& name) {
  std::lock_guard lock(mutex_);
  if (current_ < 0 || steps_[static_cast<std::size_t>(current_)].name != name) return;
  const RunStep& s = steps_[static_cast<std::size_t>(current_)];
  const double took = clock_() - current_start_s_;
  done_s_[static_cast<std::size_t>(current_)] = took;
  current_ = -1;
  if (s.units <= 0 || took <= 0) return;
  bool known = false;
  for (auto& [kind, cost] : measured_cost_) {
    if (kind == s.kind) {
      cost = took / s.units;
      known = true;
    }
  }
  if (!known) measured_cost_.emplace_back(s.kind, took / s.units);
  // The machine's speed relative to the priors: the total of the finished steps.
  double measured = 0, prior = 0;
  for (std::size_t i = 0; i < steps_.size(); ++i) {
    if (done_s_[i] < 0 || steps_[i].prior_seconds_per_unit <= 0) continue;
    measured += done_s_[i];
    prior += steps_[i].prior_seconds_per_unit * steps_[i].units;
  }
  if (prior > 0 && measured > 0) speed_ = measured / prior;
}

double RunEta::RemainingLocked(double current_step_eta_s) const {
  if (steps_.empty()) return -1;
  double left = 0;
  for (std::size_t i = 0; i < steps_.size(); ++i) {
    if (done_s_[i] >= 0) continue;
    if (static_cast<int>(i) == current_) {
      const double predicted = CostLocked(steps_[i]) - (clock_() - current_start_s_);
      left += current_step_eta_s >= 0 ? current_step_eta_s : std::max(0.0, predicted);
    } else {
      left += CostLocked(steps_[i]);
    }
  }
  return left;
}

double RunEta::RemainingSeconds(double current_step_eta_s) const {
  std::lock_guard lock(mutex_);
  return RemainingLocked(current_step_eta_s);
}

std::string RunEta::Suffix(double current_step_eta_s) const {
  std::lock_guard lock(mutex_);
  if (steps_.empty()) return "";
  const double left = RemainingLocked(current_step_eta_s);
  const double elapsed = clock_() - start_s_;
  const double total = elapsed + left;
  char pct[16];
  std::snprintf(pct, sizeof pct, "%.0f%%", total > 0 ? 100.0 * elapsed / total : 0.0);
  return std::string(" | run ") + pct + " ETA " + Progress::FormatDuration(left);
}

std::vector<RunEtaSample> RunEta::History() const {
  std::lock_guard lock(mutex_);
  return history_;
}

}  // namespace prt
