// Bounce k of the gather estimator (worker/bounce_gather.h; docs/interreflection.md), one phase
// per bounce, k = 1 … K ("bounce-<k>"):
//   Tᵏ(x) = (1/P) Σ_p ρ(y_p) · Tᵏ⁻¹(y_p)   on the indirect grid (m = indirect_n),
// with T⁰ the direct rows coarsened to the grid. Every rank that gathers needs the previous
// bounce's rows of the whole scene (transport.prtt for k = 1, else indirect/bounce-<k−1>.prtt),
// prev_channels × V × 6m² floats within --memory-budget: each rank reads them from the run folder
// itself, or rank 0 reads and broadcasts them (--rows-via-rank0; farm/bounce/driver.h). A job is a
// range of vertices; its channels rows per vertex go into indirect/bounce-<k>.prtt.
// Method "sparse" with [sparse] indirect = "combination": only the dense vertices gather, the
// others are combined by rank 0 after the job loop (the driver); with "features" this phase
// writes the dense vertices' rows (bounce-<k>-dense.prtt) and farm/bounce/features.cpp the rest.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"
#include "vocabulary/errors.h"
#include "worker/composed_transport.h"

namespace prt {

namespace {

// Bounce k on the run's samples (pass kSamples) or, in an image run, on the mesh vertices'
// support rows (kVertexBounce, "vertex-bounce-<k>": the same gather, from the vertices' own
// previous bounce; farm/bounce/pixel_gathering.cpp).
class GatheringPhase final : public BouncePhase {
 public:
  GatheringPhase(int k, std::shared_ptr<nlohmann::ordered_json> figures, BouncePass pass)
      : BouncePhase(k, false, std::move(figures), pass), k_(k) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const bool support = driver_.on_vertices_of_image();
    const std::vector<SpatialSample>& samples = support ? ImageVertexSamples(ctx) : ctx.samples;
    const uint64_t V = driver_.Rows(ctx);
    const int C = ctx.params.channels;
    const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
    const std::size_t cols = coarse.texel_count();
    const int prev_channels = k_ == 1 ? 1 : C;
    std::vector<float> previous;
    driver_.ReadSceneRows(ctx, uint64_t(prev_channels) * V * cols * sizeof(float),
                          "the previous bounce's rows",
                          [&] {
                            if (support)
                              ReadSupportRows(k_ == 1 ? ctx.folder.VertexDirectFile()
                                                      : ctx.folder.VertexBounceFile(k_ - 1),
                                              V, prev_channels, coarse, previous, false);
                            else
                              previous = ReadPreviousBounce(ctx, k_, fine, coarse, prev_channels);
                          },
                          {&previous});
    driver_.LoadCombination(ctx);

    const GatherKernels kernels(ctx);
    const BounceGatherer* gatherer = kernels.gatherer.get();
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.completes_stage = !support && k_ == ctx.params.bounces && ctx.params.sparse_indirect != 2;
    // Channels rows per vertex; zeros for a combined vertex, which rank 0 fills from the dense
    // rows.
    jobs.compute = [&](const RowRange& range, std::string& out) {
      const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
      ComputeJobRows(driver_.name(), range, per_vertex, out, [&](uint64_t v, float* dst) {
        if (driver_.Combined(v)) {
          std::fill_n(dst, per_vertex, 0.0f);
          return GatherStats{};
        }
        thread_local std::vector<GatherTerm> terms;
        thread_local std::vector<float> near;
        return gatherer->GatherRow(samples[v], v, k_, C, previous.data(), V, prev_channels, cols,
                                   dst, terms, near);
      });
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      if (support)
        AddImagePassFigures(driver_, totals, k_);
      else
        driver_.figures()["per_bounce"].push_back(TracedFigures(totals, k_));
    };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
  int k_;
};

}  // namespace

GatherKernels::GatherKernels(const FarmContext& ctx) {
  if (!ctx.computes_here()) return;
  // An image run's glossy meshes, reached by bounce rays, reflect as worker/glossy_pixels.h's
  // BounceAlbedo says (their lobe's energy, spread diffusely).
  surfaces = std::make_unique<SceneSurfaces>(ctx.geometry,
                                             ctx.params.image && ctx.glossy_pixels.any()
                                                 ? BounceAlbedo(ctx.glossy_pixels, ctx.geometry)
                                                 : std::vector<Rgb>{});
  gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, GatherOptionsOf(ctx));
}

BounceGatherOptions GatherOptionsOf(const FarmContext& ctx) {
  BounceGatherOptions go;
  go.paths = ctx.params.gather_paths;
  go.seed = ctx.params.seed;
  go.indirect_n = ctx.params.indirect_n;
  go.near_field = ctx.params.near_field;
  return go;
}

std::vector<float> ReadPreviousBounce(const FarmContext& ctx, int k, const CubemapLayout& fine,
                                      const CubemapLayout& coarse, int prev_channels) {
  const std::size_t cols = coarse.texel_count();
  const uint64_t V = ctx.params.rows;
  std::vector<float> previous(static_cast<std::size_t>(prev_channels * V * cols));
  if (k == 1) {
    const TransportFileReader reader(ctx.folder.transport);
    if (reader.info().rows != V || reader.info().cubemap_n != uint32_t(fine.n()))
      throw InputError(ctx.folder.transport, "does not hold the run's direct rows");
    AddCoarsenedRows(reader, coarse, previous.data());
  } else {
    const std::string path = ctx.folder.BounceFile(k - 1);
    const TransportFileReader reader(path);
    if (reader.info().rows != prev_channels * V || reader.info().cubemap_n != uint32_t(coarse.n()))
      throw InputError(path, "does not hold bounce " + std::to_string(k - 1) + "'s rows");
    reader.ReadRows(0, reader.info().rows, previous.data());
  }
  return previous;
}

std::unique_ptr<FarmPhase> MakeGatheringPhase(int k,
                                              std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<GatheringPhase>(k, std::move(figures), BouncePass::kSamples);
}

std::unique_ptr<FarmPhase> MakeVertexBouncePhase(int k,
                                                 std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<GatheringPhase>(k, std::move(figures), BouncePass::kVertexBounce);
}

}  // namespace prt
