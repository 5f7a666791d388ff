// The indirect stage's estimators (docs/interreflection.md), one phase class and one file each,
// all running their jobs on the shared driver (farm/bounce/driver.h); AddBouncePhases
// (farm/bounce/driver.cpp, in the phase list) picks them. What one estimator's file lends
// another is here too: the features step evaluates a sparse vertex's feature texels with the
// gathering or path-tracing settings.
// Internal to farm/bounce/.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "vocabulary/cubemap.h"
#include "worker/bounce_gather.h"
#include "worker/path_trace_reference.h"

namespace prt {

class BounceDriver;  // farm/bounce/driver.h
struct BounceTotals;

// farm/bounce/gathering.cpp: bounce k ≥ 1 ("bounce-<k>"), and an image run's vertex-bounce-<k>
// (MakeVertexBouncePhase, below).
// Each shares `figures`, report.json "interreflection" (farm/bounce/driver.h).
std::unique_ptr<FarmPhase> MakeGatheringPhase(int k,
                                              std::shared_ptr<nlohmann::ordered_json> figures);
// farm/bounce/path_tracing.cpp: every bounce at once (k = 0, "path-trace").
std::unique_ptr<FarmPhase> MakePathTracingPhase(std::shared_ptr<nlohmann::ordered_json> figures);
// farm/bounce/features.cpp: the step after bounce k (k = 0: after path tracing) with [sparse]
// indirect = "features" ("bounce-<k>-sparse", "path-trace-sparse").
std::unique_ptr<FarmPhase> MakeFeaturesPhase(int k,
                                             std::shared_ptr<nlohmann::ordered_json> figures);

// farm/bounce/pixel_gathering.cpp: an image run's bounce light by gathering
// (docs/image-relighting.md, "Interreflection"): T⁰ at the mesh vertices on the indirect grid
// ("vertex-direct"), bounces 1 … K−1 at the vertices ("vertex-bounce-<k>"), and the pixels'
// Σ_k Tᵏ gathered from those ("pixel-gather").
// Every rank, image runs: the mesh vertices as samples (made once, kept in ctx.results).
const std::vector<SpatialSample>& ImageVertexSamples(FarmContext& ctx);
// Reads all `channels` × `rows` rows of a support file on the `grid` into `out` (resized), or
// adds them to `out` with `add`. Throws InputError naming the file when its shape differs.
void ReadSupportRows(const std::string& path, uint64_t rows, int channels,
                     const CubemapLayout& grid, std::vector<float>& out, bool add);
// Rank 0: a support or pixel phase's figures, report.json "interreflection.image_passes[]".
void AddImagePassFigures(BounceDriver& driver, const BounceTotals& totals, int k);
std::unique_ptr<FarmPhase> MakeVertexDirectPhase(std::shared_ptr<nlohmann::ordered_json> figures);
std::unique_ptr<FarmPhase> MakeVertexBouncePhase(int k,
                                                 std::shared_ptr<nlohmann::ordered_json> figures);
std::unique_ptr<FarmPhase> MakePixelGatherPhase(std::shared_ptr<nlohmann::ordered_json> figures);

// The gather estimator's settings of the run ([sampling] gather_paths, seed, indirect_n,
// near_field).
BounceGatherOptions GatherOptionsOf(const FarmContext& ctx);
// The gather kernels of a computing rank, with the run's settings (none elsewhere).
struct GatherKernels {
  explicit GatherKernels(const FarmContext& ctx);
  std::unique_ptr<SceneSurfaces> surfaces;
  std::unique_ptr<BounceGatherer> gatherer;
};
// The rows bounce k gathers from, on the indirect grid: T⁰ coarsened (k = 1, prev_channels 1) or
// bounce k − 1's (channels rows per vertex), read from the run folder.
std::vector<float> ReadPreviousBounce(const FarmContext& ctx, int k, const CubemapLayout& fine,
                                      const CubemapLayout& coarse, int prev_channels);

// The path tracer's settings of the run ([sampling] bounces, gather_paths, rays_per_texel, seed;
// one ray per texel for the direct row at each path vertex).
PathTraceOptions PathOptionsOf(const FarmContext& ctx);

}  // namespace prt
