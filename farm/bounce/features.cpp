// The sparse method's features step ([sparse] indirect = "features"; docs/sparse-precomputation.md,
// "With interreflection"): after bounce k's dense phase (farm/bounce/gathering.cpp; k = 0: path
// tracing, farm/bounce/path_tracing.cpp) wrote the dense vertices' whole rows on the indirect
// grid into bounce-<k>-dense.prtt (path-traced-dense.prtt), this phase, "bounce-<k>-sparse"
// ("path-trace-sparse"), evaluates every other vertex's feature texels and reconstructs its row
// from its dense neighbours by L1 (ReconstructIndirectRow, Huang & Ramamoorthi 2010 §5), the
// evaluated values kept exactly; dense rows are copied. Path tracing evaluates the texels with
// the same paths, gathering with [sparse] feature_paths directions from the previous bounce's
// rows. Every rank needs the dense rows (and for k > 0 the previous bounce's) of the whole scene,
// together within --memory-budget (read or shared by the driver, farm/bounce/driver.h); the full
// rows go into bounce-<k>.prtt (path-traced.prtt). A job's journal line carries the texels
// evaluated and the fallbacks in the places of escapes and back faces.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"
#include "vocabulary/errors.h"
#include "worker/sparse_indirect.h"

namespace prt {

namespace {

// What a computing rank evaluates sparse vertices with: the estimator at their feature texels,
// the dense vertices to reconstruct from, and the dense rows vertex-major.
struct FeatureEvaluator {
  std::unique_ptr<SceneSurfaces> surfaces;
  std::unique_ptr<PathTraceReference> reference;
  std::unique_ptr<BounceGatherer> gatherer;
  std::unique_ptr<IndirectComponent> component;
  std::unique_ptr<NeighborIndex> index;
  std::vector<float> by_vertex;  // C rows of cols per vertex
};

class FeaturesPhase final : public BouncePhase {
 public:
  FeaturesPhase(int k, std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(k, true, std::move(figures)), k_(k) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
    const std::size_t cols = coarse.texel_count();
    const int prev_channels = k_ == 1 ? 1 : C;
    std::vector<float> previous, dense;
    const uint64_t bytes = (k_ > 0 ? uint64_t(prev_channels) : 0) * V * cols * sizeof(float) +
                           uint64_t(C) * V * cols * sizeof(float);
    driver_.ReadSceneRows(ctx, bytes,
                          k_ > 0 ? "the previous bounce's rows" : "the dense vertices' rows",
                          [&] {
                            if (k_ > 0)
                              previous = ReadPreviousBounce(ctx, k_, fine, coarse, prev_channels);
                            dense = ReadDense(ctx, coarse);
                          },
                          {&previous, &dense});
    driver_.LoadCombination(ctx);

    FeatureEvaluator evaluator;
    if (ctx.computes_here()) evaluator = MakeEvaluator(ctx, previous, prev_channels, dense, cols);
    const SparseIndirectOptions io =
        IndirectOptionsOf(ctx.plan, ctx.params.cubemap_n, ctx.params.indirect_n);
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.combined_rows_are_zero = false;
    jobs.completes_stage = k_ == ctx.params.bounces || k_ == 0;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      Reconstruct(ctx, evaluator, io, cols, range, out);
    };
    jobs.report = [&](FarmContext& c, const BounceTotals& totals) { AddFigures(c, totals); };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
  // The dense vertices' rows of this bounce (or path tracing's), read from the run folder.
  std::vector<float> ReadDense(const FarmContext& ctx, const CubemapLayout& coarse) const {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const std::string path =
        k_ > 0 ? ctx.folder.BounceDenseFile(k_) : ctx.folder.PathTracedDenseFile();
    const TransportFileReader reader(path);
    if (reader.info().rows != C * V || reader.info().cubemap_n != uint32_t(coarse.n()))
      throw InputError(path, "does not hold the dense vertices' rows of " + driver_.name());
    std::vector<float> dense(static_cast<std::size_t>(reader.info().rows * coarse.texel_count()));
    reader.ReadRows(0, reader.info().rows, dense.data());
    return dense;
  }

  FeatureEvaluator MakeEvaluator(const FarmContext& ctx, const std::vector<float>& previous,
                                 int prev_channels, const std::vector<float>& dense,
                                 std::size_t cols) const {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    FeatureEvaluator ev;
    ev.surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
    if (k_ == 0) {
      ev.reference = std::make_unique<PathTraceReference>(
          *ctx.embree, *ev.surfaces, ctx.params.indirect_n, PathOptionsOf(ctx));
      ev.component = std::make_unique<PathTracedIndirect>(*ev.reference, C);
    } else {
      BounceGatherOptions go = GatherOptionsOf(ctx);
      if (ctx.params.sparse_feature_paths > 0) go.paths = ctx.params.sparse_feature_paths;
      ev.gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *ev.surfaces, go);
      ev.component = std::make_unique<GatheredBounce>(*ev.gatherer, k_, C, previous.data(), V,
                                                      prev_channels, cols);
    }
    std::vector<uint32_t> ids;
    std::vector<Vec3> points;
    for (uint64_t v = 0; v < V; ++v)
      if (!driver_.Combined(v)) {
        ids.push_back(static_cast<uint32_t>(v));
        points.push_back(ctx.samples[v].position);
      }
    ev.index = std::make_unique<NeighborIndex>(points, ids);
    ev.by_vertex.resize(dense.size());
    for (int c = 0; c < C; ++c)
      for (uint64_t v = 0; v < V; ++v)
        std::copy_n(dense.data() + (c * V + v) * cols, cols,
                    ev.by_vertex.data() + (v * C + c) * cols);
    return ev;
  }

  // Vertices `range` into the payload: the header, then every vertex's channels rows
  // (vertex-major), a dense vertex's copied, the others' reconstructed.
  void Reconstruct(const FarmContext& ctx, const FeatureEvaluator& ev,
                   const SparseIndirectOptions& io, std::size_t cols, const RowRange& range,
                   std::string& out) const {
    const std::size_t per_vertex = static_cast<std::size_t>(ctx.params.channels) * cols;
    const std::size_t at = out.size();
    const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
    float* rows = AppendJobResult(out, floats, 0);
    tbb::enumerable_thread_specific<L1Solver> solvers([&] {
      L1Options o;
      o.lambda = io.lambda;
      return L1Solver(o);
    });
    tbb::enumerable_thread_specific<SparseIndirectStats> stats;
    tbb::parallel_for(uint64_t{0}, range.count, [&](uint64_t i) {
      const uint64_t v = range.first + i;
      float* row = rows + i * per_vertex;
      if (!driver_.Combined(v)) {
        std::copy_n(ev.by_vertex.data() + v * per_vertex, per_vertex, row);
        return;
      }
      ReconstructIndirectAt(
          *ev.component, ctx.samples, static_cast<uint32_t>(v), *ev.index, ctx.plan.radius,
          ctx.plan.max_neighbors, [&](uint32_t d) { return ev.by_vertex.data() + d * per_vertex; },
          io, solvers.local(), row, stats.local());
    });
    BounceResultHeader h;
    h.rows_checksum = ChecksumFiniteRows(rows, floats, per_vertex, range, driver_.name());
    for (const SparseIndirectStats& st : stats) {
      h.rays_traced += st.rays;
      h.rays_escaped += st.texels_evaluated;  // journaled: the texels evaluated
      h.back_face_hits += st.fallbacks();     // and the whole rows of fallbacks
    }
    std::memcpy(out.data() + at, &h, sizeof h);
  }

  // Bounce k's entry of per_bounce (its dense phase's) takes the whole bounce's energy and these
  // figures as "features"; path tracing's go into path_trace_features.
  void AddFigures(const FarmContext&, const BounceTotals& t) const {
    nlohmann::ordered_json figures = nlohmann::ordered_json::object();
    figures["energy"] = t.energy;
    figures["rays_traced"] = t.rays;
    figures["jobs_reused"] = t.jobs_reused;
    figures["wall_seconds"] = t.wall_seconds;
    figures["texels_evaluated"] = t.escaped;
    figures["fallbacks"] = t.back_faces;
    nlohmann::ordered_json& all = driver_.figures();
    if (k_ > 0 && !all["per_bounce"].empty()) {
      auto& entry = all["per_bounce"].back();
      entry["energy"] = t.energy;
      entry["features"] = figures;
    } else if (k_ == 0) {
      all["path_trace_features"] = figures;
    }
  }

  int k_;
};

}  // namespace

std::unique_ptr<FarmPhase> MakeFeaturesPhase(int k,
                                             std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<FeaturesPhase>(k, std::move(figures));
}

}  // namespace prt
