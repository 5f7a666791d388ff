// Which stages of a run (farm/run_manifest.h) re-run and which are re-used, from the manifest
// the folder holds, the one the inputs given now make, and what the folder's outputs are
// (docs/farm.md, "Stages and re-runs"). A pure function: tested without MPI or files.
#pragma once

#include <string>
#include <vector>

#include "farm/run_manifest.h"

namespace prt {

enum class StageAction {
  kReuse,   // its output is in the folder and its inputs are unchanged
  kResume,  // rows only: unfinished; journaled jobs are re-used, the rest is traced
  kRun,     // computed (again)
  kSkip,    // not computed in this run (--no-compress; an estimate without rows)
};
const char* ToString(StageAction a);

struct StageDecision {
  std::string name;
  StageAction action = StageAction::kRun;
  std::string reason;  // why it runs or is skipped ("keep_fraction 0.05 -> 0.1"), "" if re-used
};

// What the run folder holds, looked at by setup before it changes anything.
struct RunFolderState {
  bool rows_complete = false;        // transport.prtt (or visibility.prtv) complete
  bool rows_unfinished = false;      // transport.prtt.partial or journaled jobs
  bool compressed_current = false;   // transport.prtc exists with the header planned now
  bool estimate_current = false;     // accuracy.json exists for the estimate inputs given now
  bool indirect_complete = false;    // every indirect/bounce-<k>.prtt of the bounces asked for
  bool indirect_unfinished = false;  // bounce files or journal lines of an unfinished stage
};

struct StagePlanOptions {
  bool force = false;       // --force: every stage from scratch
  bool compress = true;     // false: --no-compress (or the visibility job)
  bool visibility = false;  // the visibility job: rows and assets only
};

struct StagePlan {
  std::vector<StageDecision> stages;  // rows, indirect, compression, estimate, assets (as they
                                      // apply)
  const StageDecision& Get(const std::string& name) const;
  bool Has(const std::string& name) const;
  bool Runs(const std::string& name) const;  // kRun or kResume
  // Nothing to compute: every stage re-used or skipped.
  bool NothingToDo() const;
};

// `older` is the folder's manifest (nullptr when it has none); `now` the manifest of the
// inputs given now.
StagePlan PlanStages(const RunManifest* older, const RunManifest& now, const RunFolderState& folder,
                     const StagePlanOptions& options);

}  // namespace prt
