// One ETA for the whole run (docs/farm.md, "Progress"): the run's remaining steps (brute force,
// or every sub-phase of the sparse method, then finalize, compress, estimate), each with a
// predicted duration. A step's prediction is its amount of work (rows, candidates, bytes) times
// a cost per unit; the costs start from priors measured on a 2-core machine
// (each phase's PredictSteps, farm_context.h) and are replaced, as the run goes, by what this run
// measured: a finished step gives its kind's cost, and scales the priors of the kinds not yet seen
// by how much slower or faster than its prior it ran (the machine's speed today). The step running
// now counts with its own progress ETA. Thread-safe.
#pragma once

#include <functional>
#include <mutex>
#include <string>
#include <vector>

namespace prt {

struct RunStep {
  std::string name;  // the progress label (brute, dense-initial, rank-1, …, compress, estimate)
  std::string kind;  // steps of one kind share a cost per unit (row, dense, rank, sparse, …)
  double units = 0;  // the work, in the kind's unit
  double prior_seconds_per_unit = 0;
};

struct RunEtaSample {
  double elapsed_s = 0;          // since the run started
  std::string step;              // the step that had just started
  double predicted_total_s = 0;  // elapsed + predicted remaining, then
};

class RunEta {
 public:
  explicit RunEta(std::function<double()> clock = {});
  void SetSteps(std::vector<RunStep> steps);
  // A step starts / ends (steps not in the plan are ignored).
  void StepStarted(const std::string& name);
  void StepFinished(const std::string& name);
  // Seconds left in the run, given the current step's own ETA (< 0: unknown, its prediction is
  // used). −1 when nothing is planned.
  double RemainingSeconds(double current_step_eta_s) const;
  // " | run 42% ETA 1m05s" for a progress line ("" when nothing is planned).
  std::string Suffix(double current_step_eta_s) const;
  std::vector<RunEtaSample> History() const;

 private:
  double CostLocked(const RunStep& s) const;
  double RemainingLocked(double current_step_eta_s) const;

  std::function<double()> clock_;
  double start_s_ = 0;
  mutable std::mutex mutex_;
  std::vector<RunStep> steps_;
  std::vector<double> done_s_;  // measured seconds of finished steps (−1 not finished)
  int current_ = -1;
  double current_start_s_ = 0;
  double speed_ = 1.0;  // measured / prior of the finished steps (the machine today)
  std::vector<std::pair<std::string, double>> measured_cost_;  // kind → seconds per unit
  std::vector<RunEtaSample> history_;
};

}  // namespace prt
