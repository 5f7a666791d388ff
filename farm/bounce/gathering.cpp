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
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"
#include "vocabulary/errors.h"
#include "worker/composed_transport.h"

namespace prt {

namespace {

class GatheringPhase final : public BouncePhase {
 public:
  GatheringPhase(int k, std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(k, false, std::move(figures)), k_(k) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const uint64_t V = ctx.params.rows;
    const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
    const std::size_t cols = coarse.texel_count();
    const int prev_channels = k_ == 1 ? 1 : ctx.params.channels;
    std::vector<float> previous;
    driver_.ReadSceneRows(
        ctx, uint64_t(prev_channels) * V * cols * sizeof(float), "the previous bounce's rows",
        [&] { previous = ReadPreviousBounce(ctx, k_, fine, coarse, prev_channels); }, {&previous});
    driver_.LoadCombination(ctx);

    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<BounceGatherer> gatherer;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, GatherOptionsOf(ctx));
    }
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.completes_stage = k_ == ctx.params.bounces && ctx.params.sparse_indirect != 2;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      Gather(ctx, *gatherer, previous, prev_channels, cols, range, out);
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      driver_.figures()["per_bounce"].push_back(TracedFigures(totals, k_));
    };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
  // Vertices `range` into the payload: the header, then channels rows per vertex (vertex-major;
  // zeros for a combined vertex, which rank 0 fills from the dense rows).
  void Gather(const FarmContext& ctx, const BounceGatherer& gatherer,
              const std::vector<float>& previous, int prev_channels, std::size_t cols,
              const RowRange& range, std::string& out) const {
    const int C = ctx.params.channels;
    const uint64_t V = ctx.params.rows;
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    const std::size_t at = out.size();
    const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
    float* rows = AppendJobResult(out, floats, 0);
    tbb::enumerable_thread_specific<GatherStats> stats;
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 8),
                      [&](const tbb::blocked_range<uint64_t>& r) {
                        std::vector<GatherTerm> terms;
                        std::vector<float> near;
                        for (uint64_t i = r.begin(); i != r.end(); ++i) {
                          const uint64_t v = range.first + i;
                          if (driver_.Combined(v)) {
                            std::fill_n(rows + i * per_vertex, per_vertex, 0.0f);
                            continue;
                          }
                          stats.local() += gatherer.GatherRow(
                              ctx.samples[v], v, k_, C, previous.data(), V, prev_channels, cols,
                              rows + i * per_vertex, terms, near);
                        }
                      });
    BounceResultHeader h;
    h.rows_checksum = ChecksumFiniteRows(rows, floats, per_vertex, range, driver_.name());
    GatherStats s;
    for (const GatherStats& l : stats) s += l;
    h.rays_traced = s.rays_traced;
    h.rays_escaped = s.rays_escaped;
    h.back_face_hits = s.back_face_hits;
    std::memcpy(out.data() + at, &h, sizeof h);
  }

  int k_;
};

}  // namespace

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
  return std::make_unique<GatheringPhase>(k, std::move(figures));
}

}  // namespace prt
