// The farm's phases, in the order every rank runs them (docs/architecture.md, "Adding a farm
// phase"). This list is all the run (farm_run.cpp) knows of them: each entry is a phase's file,
// which decides whether the run needs it (from what setup decided) and says everything else
// itself: its name, stage, cost model, report section and state.
#include "farm/farm_context.h"

namespace prt {

// Defined in the phase's own file.
void AddSetupPhase(const FarmContext& ctx, PhaseList& phases);        // setup_phase.cpp
void AddVisibilityPhases(const FarmContext& ctx, PhaseList& phases);  // visibility_phase.cpp
void AddBrutePhase(const FarmContext& ctx, PhaseList& phases);        // brute_phase.cpp
void AddSparsePhase(const FarmContext& ctx, PhaseList& phases);       // sparse_phase.cpp
void AddFinalizePhase(const FarmContext& ctx, PhaseList& phases);     // finalize_phase.cpp
void AddBouncePhases(const FarmContext& ctx, PhaseList& phases);      // bounce/
void AddCompressionPhase(const FarmContext& ctx, PhaseList& phases);  // compression_phase.cpp
void AddEstimatePhase(const FarmContext& ctx, PhaseList& phases);     // estimate_phase.cpp

const std::vector<PhaseFactory>& FarmPhaseList() {
  static const std::vector<PhaseFactory> list = {
      AddSetupPhase,        // the scene, the run folder, the stages; every rank's geometry
      AddVisibilityPhases,  // the visibility job: maps, then visibility.prtv
      AddBrutePhase,        // rows by brute force
      AddSparsePhase,       // rows by the sparse method (Huang & Ramamoorthi 2010)
      AddFinalizePhase,     // the sampled rows packed into transport.prtt
      AddBouncePhases,      // interreflection: one phase per bounce, or path tracing
      AddCompressionPhase,  // transport.prtc (wavelets or CPCA)
      AddEstimatePhase,     // accuracy.json
  };
  return list;
}

}  // namespace prt
