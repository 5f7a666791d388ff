// Stage decisions of a re-run (see stage_plan.h).
#include "farm/stage_plan.h"

#include <stdexcept>

namespace prt {

const char* ToString(StageAction a) {
  switch (a) {
    case StageAction::kReuse:
      return "reused";
    case StageAction::kResume:
      return "resumed";
    case StageAction::kRun:
      return "ran";
    case StageAction::kSkip:
      return "skipped";
  }
  return "?";
}

const StageDecision& StagePlan::Get(const std::string& name) const {
  for (const StageDecision& d : stages)
    if (d.name == name) return d;
  throw std::logic_error("StagePlan: no stage " + name);
}

bool StagePlan::Has(const std::string& name) const {
  for (const StageDecision& d : stages)
    if (d.name == name) return true;
  return false;
}

bool StagePlan::Runs(const std::string& name) const {
  return Has(name) &&
         (Get(name).action == StageAction::kRun || Get(name).action == StageAction::kResume);
}

bool StagePlan::NothingToDo() const {
  for (const StageDecision& d : stages)
    if (d.name != kStageAssets &&
        (d.action == StageAction::kRun || d.action == StageAction::kResume))
      return false;
  return true;
}

namespace {

// Why a stage's own inputs rule out re-use ("" when they do not).
std::string ChangedInputs(const RunManifest* older, const RunManifest& now,
                          const std::string& stage) {
  if (older == nullptr) return "new run";
  if (older->format_version != now.format_version)
    return "checkpoints of an older prt-farm (manifest format " +
           std::to_string(older->format_version) + ")";
  const std::string d = now.StageDifferences(stage, *older);
  return d.empty() ? "" : "changed: " + d;
}

}  // namespace

StagePlan PlanStages(const RunManifest* older, const RunManifest& now, const RunFolderState& folder,
                     const StagePlanOptions& options) {
  StagePlan plan;
  const RunManifest* old = options.force ? nullptr : older;

  // Downstream stages first decide whether they could be re-used, because the rows are needed
  // again when a stage that reads them must run and the raw matrix is gone.
  StageDecision rows{kStageRows, StageAction::kReuse, ""};
  std::string why = options.force ? "--force" : ChangedInputs(old, now, kStageRows);
  bool rows_run = !why.empty();
  StageDecision comp{kStageCompression, StageAction::kReuse, ""};
  StageDecision est{kStageEstimate, StageAction::kReuse, ""};
  std::string comp_why, est_why, ind_why;
  const bool indirect = !options.visibility && now.Stage(kStageIndirect) != nullptr;
  if (indirect) {
    ind_why = ChangedInputs(old, now, kStageIndirect);
    if (ind_why.empty() && !folder.indirect_complete && !folder.indirect_unfinished)
      ind_why = "indirect/ missing";
  }
  if (!options.visibility && options.compress) {
    comp_why = ChangedInputs(old, now, kStageCompression);
    if (comp_why.empty() && !folder.compressed_current) comp_why = "transport.prtc missing";
  }
  if (!options.visibility) {
    est_why = ChangedInputs(old, now, kStageEstimate);
    if (est_why.empty() && !folder.estimate_current) est_why = "accuracy.json missing";
  }

  if (!rows_run) {
    if (folder.rows_complete) {
      rows.action = StageAction::kReuse;
    } else if (folder.rows_unfinished) {
      rows.action = StageAction::kResume;
      rows.reason = "unfinished: journaled jobs are re-used";
    } else if (!comp_why.empty() || !ind_why.empty()) {
      rows_run = true;
      why = "transport.prtt is not in the run folder (discarded with --discard-raw) and the " +
            std::string(ind_why.empty() ? "compression" : "indirect stage") + " must run (" +
            (ind_why.empty() ? comp_why : ind_why) + ")";
    } else {
      rows.action = StageAction::kReuse;
      rows.reason = "transport.prtt discarded (--discard-raw); nothing needs it";
    }
  }
  if (rows_run) {
    rows.action = StageAction::kRun;
    rows.reason = why;
  }
  plan.stages.push_back(rows);
  const bool rows_changed = rows.action != StageAction::kReuse;
  const bool rows_available = rows_changed || folder.rows_complete;

  bool indirect_changed = false;
  if (indirect) {
    StageDecision ind{kStageIndirect, StageAction::kReuse, ""};
    if (rows_changed) {
      ind.action = StageAction::kRun;
      ind.reason =
          std::string("the rows ") + (rows.action == StageAction::kRun ? "ran" : "resumed");
    } else if (!ind_why.empty()) {
      ind.action = StageAction::kRun;
      ind.reason = ind_why;
    } else if (!folder.indirect_complete) {
      ind.action = StageAction::kResume;
      ind.reason = "unfinished: journaled jobs are re-used";
    }
    indirect_changed = ind.action != StageAction::kReuse;
    plan.stages.push_back(ind);
  }

  if (!options.visibility) {
    if (!options.compress) {
      comp.action = StageAction::kSkip;
      comp.reason = "--no-compress";
    } else if (rows_changed) {
      comp.action = StageAction::kRun;
      comp.reason =
          std::string("the rows ") + (rows.action == StageAction::kRun ? "ran" : "resumed");
    } else if (indirect_changed) {
      comp.action = StageAction::kRun;
      comp.reason = "the indirect stage ran";
    } else if (!comp_why.empty()) {
      comp.action = StageAction::kRun;
      comp.reason = comp_why;
    }
    plan.stages.push_back(comp);

    if (rows_changed) {
      est.action = StageAction::kRun;
      est.reason =
          std::string("the rows ") + (rows.action == StageAction::kRun ? "ran" : "resumed");
    } else if (!est_why.empty()) {
      est.action = rows_available ? StageAction::kRun : StageAction::kSkip;
      est.reason = rows_available
                       ? est_why
                       : est_why + "; it needs transport.prtt, discarded (--discard-raw)";
    }
    plan.stages.push_back(est);
  }

  StageDecision assets{kStageAssets, StageAction::kReuse, ""};
  const std::string assets_why = ChangedInputs(old, now, kStageAssets);
  if (!assets_why.empty()) {
    assets.action = StageAction::kRun;
    assets.reason = assets_why;
  }
  plan.stages.push_back(assets);
  return plan;
}

}  // namespace prt
