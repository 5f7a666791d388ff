// The indirect stage by per-element path tracing (worker/path_trace_reference.h; Huang &
// Ramamoorthi 2010 §7's baseline; docs/interreflection.md): with [sampling] estimator = "path"
// one phase, "path-trace" (k = 0), traces every bounce at once and writes Σ_k Tᵏ at n into
// indirect/path-traced.prtt. A job's payload holds each vertex's Σ_k Tᵏ (channels rows) and then,
// per bounce and channel, the energy of its vertices, which the journal keeps with the job so
// that a resume still reports each bounce's energy.
// Method "sparse" ([sparse] indirect, docs/sparse-precomputation.md "With interreflection"):
// only the dense vertices trace, on the indirect grid (§4.2: "we directly use the low-resolution
// grid"), their rows the indirect part alone, without a per-bounce split; "combination" fills the
// others on rank 0 (farm/bounce/driver.h), "features" writes path-traced-dense.prtt and leaves
// them to farm/bounce/features.cpp.
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"

namespace prt {

namespace {

class PathTracingPhase final : public BouncePhase {
 public:
  explicit PathTracingPhase(std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(0, false, std::move(figures)) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    // Sparse: the dense vertices' rows on the indirect grid, the others combined from them.
    const int grid_n = ctx.params.sparse_indirect ? ctx.params.indirect_n : ctx.params.cubemap_n;
    const std::size_t cols = CubemapLayout(grid_n).texel_count();
    driver_.LoadCombination(ctx);
    if (ctx.rank == 0) ctx.run_eta.StepStarted(driver_.name());
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<PathTraceReference> reference;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      reference =
          std::make_unique<PathTraceReference>(*ctx.embree, *surfaces, grid_n, PathOptionsOf(ctx));
    }
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.energies = static_cast<std::size_t>(ctx.params.bounces) * ctx.params.channels;
    jobs.completes_stage = ctx.params.sparse_indirect != 2;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      TracePaths(ctx, *reference, cols, range, out);
    };
    jobs.report = [this](FarmContext& c, const BounceTotals& totals) { AddFigures(c, totals); };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
  // Vertices `range` into the payload: the header, channels rows per vertex (vertex-major;
  // zeros for a combined vertex), then the energy of each bounce and channel over the job.
  void TracePaths(const FarmContext& ctx, const PathTraceReference& reference, std::size_t cols,
                  const RowRange& range, std::string& out) const {
    const int C = ctx.params.channels, K = ctx.params.bounces;
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    const std::size_t at = out.size();
    const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
    const std::size_t energies = static_cast<std::size_t>(K) * C;
    float* rows = AppendJobResult(out, floats, energies);
    struct Local {
      PathTraceStats stats;
      std::vector<double> energy;
    };
    tbb::enumerable_thread_specific<Local> locals([&] {
      return Local{{}, std::vector<double>(energies, 0.0)};
    });
    tbb::parallel_for(uint64_t{0}, range.count, [&](uint64_t i) {
      const uint64_t v = range.first + i;
      float* dst = rows + i * per_vertex;
      if (driver_.Combined(v)) {  // filled by rank 0 from the dense rows
        std::fill_n(dst, per_vertex, 0.0f);
        return;
      }
      Local& local = locals.local();
      if (ctx.params.sparse_indirect) {
        // The indirect rows alone, as the sparse kernels evaluate them (worker/
        // sparse_indirect.h: PathTracedIndirect); no per-bounce split.
        local.stats += reference.ComputeIndirect(ctx.samples[v], v, C, {}, dst);
        return;
      }
      local.stats += TraceVertex(reference, ctx.samples[v], v, C, K, cols, dst, local.energy);
    });
    BounceResultHeader h;
    h.rows_checksum = ChecksumFiniteRows(rows, floats, per_vertex, range, driver_.name());
    std::vector<double> energy(energies, 0.0);
    for (const Local& l : locals) {
      h.rays_traced += l.stats.rays_traced();
      h.rays_escaped += l.stats.escaped;
      h.back_face_hits += l.stats.back_faces;
      for (std::size_t e = 0; e < energies; ++e) energy[e] += l.energy[e];
    }
    std::memcpy(out.data() + at, &h, sizeof h);
    std::memcpy(out.data() + at + sizeof h + floats * sizeof(float), energy.data(),
                energies * sizeof(double));
  }

  // One vertex's Σ_k Tᵏ (k = 1 … K) into `dst` (C rows), each bounce's sum per channel added to
  // `energy` [(k − 1)·C + c].
  static PathTraceStats TraceVertex(const PathTraceReference& reference,
                                    const SpatialSample& sample, uint64_t v, int C, int K,
                                    std::size_t cols, float* dst, std::vector<double>& energy) {
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    thread_local std::vector<float> row, bounce_rows;
    row.resize(per_vertex);
    bounce_rows.resize((K + 1) * per_vertex);
    PathTraceExtras ex;
    ex.bounce_rows = bounce_rows.data();
    const PathTraceStats stats = reference.ComputeRow(sample, v, C, row.data(), ex);
    std::fill(dst, dst + per_vertex, 0.0f);
    for (int k = 1; k <= K; ++k)
      for (int c = 0; c < C; ++c) {
        const float* src = bounce_rows.data() + (static_cast<std::size_t>(k) * C + c) * cols;
        double e = 0;
        for (std::size_t j = 0; j < cols; ++j) {
          dst[c * cols + j] += src[j];
          e += src[j];
        }
        energy[(k - 1) * C + c] += e;
      }
    return stats;
  }

  // The whole indirect part in one phase: each bounce's energy from the jobs' (none with the
  // sparse method: its rows are Σ_k Tᵏ, evaluated at once), then the phase's figures.
  void AddFigures(const FarmContext& ctx, const BounceTotals& totals) const {
    const int C = ctx.params.channels;
    for (int k = 1; k <= ctx.params.bounces && !ctx.params.sparse_indirect; ++k) {
      nlohmann::ordered_json e = nlohmann::ordered_json::array();
      for (int c = 0; c < C; ++c) e.push_back(totals.job_energies[(k - 1) * C + c]);
      driver_.figures()["per_bounce"].push_back({{"bounce", k}, {"energy", e}});
    }
    driver_.figures()["path_trace"] = TracedFigures(totals, 0);
  }
};

}  // namespace

PathTraceOptions PathOptionsOf(const FarmContext& ctx) {
  PathTraceOptions po;
  po.bounces = ctx.params.bounces;
  po.paths = ctx.params.gather_paths;
  po.rays_per_texel = ctx.params.rays_per_texel;
  po.path_rays_per_texel = 1;
  po.seed = ctx.params.seed;
  return po;
}

std::unique_ptr<FarmPhase> MakePathTracingPhase(std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<PathTracingPhase>(std::move(figures));
}

}  // namespace prt
