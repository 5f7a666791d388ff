// prt-farm's interreflection: bounce k of the gather estimator (worker/bounce_gather.h;
// docs/interreflection.md), one phase per bounce, k = 1 … K:
//   Tᵏ(x) = (1/P) Σ_p ρ(y_p) · Tᵏ⁻¹(y_p)   on the indirect grid (m = indirect_n),
// with T⁰ the direct rows coarsened to the grid. Every rank that gathers needs the previous
// bounce's rows of the whole scene: rank 0 reads them (transport.prtt for k = 1, else
// indirect/bounce-<k−1>.prtt) and broadcasts them, prev_channels × V × 6m² floats, which must
// fit in --memory-budget. Jobs are ranges of vertices on the job loop; a worker returns
// channels rows per vertex with their XXH64; rank 0 writes them in place into
// indirect/bounce-<k>.prtt.partial (channel-major rows c·V + v) and journals them in
// checkpoints/indirect-journal.txt, keyed by the indirect stage's inputs, so that a killed run
// resumes bounce by bounce and an edit that changes the bounces starts them afresh.
// With estimator "path" the same phase class (k = 0, "path-trace") runs the indirect stage as one
// phase of per-element path tracing (worker/path_trace_reference.h, Huang & Ramamoorthi 2010 §7's
// baseline): every bounce at once, Σ_k Tᵏ at n into indirect/path-traced.prtt, each job's
// per-bounce energies journaled with it.
// Method "sparse" with [sparse] indirect = "combination" (docs/sparse-precomputation.md, "With
// interreflection"): only the dense vertices gather or trace paths (paths on the indirect grid,
// the paper's "low-resolution grid"); every other vertex's rows are the combination of dense
// rows its direct row was reconstructed with, filled in by rank 0 after the job loop.
#include <mpi.h>
#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/mpi_support.h"
#include "farm/sparse_jobs.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/bounce_gather.h"
#include "worker/composed_transport.h"
#include "worker/path_trace_reference.h"
#include "worker/sparse_indirect.h"

namespace prt {

namespace fs = std::filesystem;

namespace {

struct BounceResultHeader {
  uint64_t rows_checksum = 0;
  uint64_t rays_traced = 0;
  uint64_t rays_escaped = 0;
  uint64_t back_face_hits = 0;
  // 1: the worker wrote the rows into the phase's partial file itself and they do not follow
  // (docs/farm.md, "Where the rows go").
  uint64_t in_place = 0;
};

// Broadcasts rank 0's vector to every rank, in pieces an int count can address.
template <class T>
void BroadcastVector(MPI_Comm comm, std::vector<T>& v, MPI_Datatype type, const char* what) {
  uint64_t size = v.size();
  CheckMpi(MPI_Bcast(&size, 1, MPI_UINT64_T, 0, comm), what);
  v.resize(static_cast<std::size_t>(size));
  constexpr uint64_t kPiece = uint64_t{1} << 28;
  for (uint64_t at = 0; at < size; at += kPiece) {
    const int count = static_cast<int>(std::min(kPiece, size - at));
    CheckMpi(MPI_Bcast(v.data() + at, count, type, 0, comm), what);
  }
}

double Dot(const float* a, const float* b, std::size_t n) {
  double s = 0;
  for (std::size_t i = 0; i < n; ++i) s += double(a[i]) * b[i];
  return s;
}

class BouncePhase final : public FarmPhase {
 public:
  // k ≥ 1: bounce k gathered; k = 0: every bounce by per-element path tracing. With [sparse]
  // indirect = "features" these run at the dense vertices only, and `features_step` is the
  // phase after each that reconstructs the other vertices from their feature texels.
  BouncePhase(int k, bool features_step)
      : k_(k),
        step_(features_step),
        name_((k > 0 ? "bounce-" + std::to_string(k) : std::string("path-trace")) +
              (features_step ? "-sparse" : "")) {}
  const char* name() const override { return name_.c_str(); }

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
    // Path tracing at n, or on the indirect grid when only the dense vertices trace (below).
    const bool path_on_grid = k_ == 0 && ctx.params.sparse_indirect;
    const std::size_t cols = k_ > 0 || path_on_grid ? coarse.texel_count() : fine.texel_count();
    const int prev_channels = k_ == 1 ? 1 : C;
    if (k_ == 0 && !step_) {
      LoadCombination(ctx);
      RunPathTracing(ctx, cols, start);
      return;
    }

    // 1. The previous bounce's rows of the whole scene on every rank (gathering), and in a
    // features step this bounce's dense rows.
    std::vector<float> previous, dense;
    uint64_t status = kExitOk;
    // Rows in place: every rank reads them from the run folder itself; else rank 0 reads and
    // broadcasts them.
    if (ctx.rank == 0 || ctx.rows_in_place) {
      try {
        const uint64_t bytes = (k_ > 0 ? uint64_t(prev_channels) : 0) * V * cols * sizeof(float) +
                               (step_ ? uint64_t(C) : 0) * V * cols * sizeof(float);
        if (bytes > ctx.options.memory_budget_bytes)
          throw UsageError(name_ + " needs " +
                           (k_ > 0 ? "the previous bounce's rows" : "the dense vertices' rows") +
                           " (" + std::to_string(bytes >> 20) +
                           " MiB in all) on every rank, more than " + "--memory-budget (" +
                           std::to_string(ctx.options.memory_budget_bytes >> 20) +
                           " MiB): raise it or lower [sampling] indirect_n");
        if (ctx.rank == 0) ctx.run_eta.StepStarted(name_);
        if (k_ > 0) previous = LoadPrevious(ctx, fine, coarse, prev_channels);
        if (step_) dense = LoadDense(ctx, coarse);
      } catch (...) {
        std::string message;
        status = static_cast<uint64_t>(ExitCodeOf(std::current_exception(), message, name_));
        spdlog::error("rank {}: {}: {}", ctx.rank, name_, message);
        if (ctx.rank == 0) ctx.report.error = message;
      }
    }
    uint64_t any = 0;
    CheckMpi(MPI_Allreduce(&status, &any, 1, MPI_UINT64_T, MPI_MAX, ctx.comm),
             "MPI_Allreduce bounce status");
    if (any != kExitOk) throw CollectiveStop{static_cast<int>(any)};
    if (!ctx.rows_in_place) {
      BroadcastVector(ctx.comm, previous, MPI_FLOAT, "MPI_Bcast bounce rows");
      BroadcastVector(ctx.comm, dense, MPI_FLOAT, "MPI_Bcast dense rows");
    }
    LoadCombination(ctx);
    if (step_) {
      RunFeatures(ctx, previous, prev_channels, dense, cols, start);
      return;
    }

    // 2. The gatherer on every rank that computes.
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<BounceGatherer> gatherer;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, GatherOptions(ctx));
    }
    RunJobPhase(
        ctx,
        [&](const RowRange& range, std::string_view, std::string& out) {
          const std::size_t at = out.size();
          Compute(ctx, *gatherer, previous, prev_channels, cols, range, out);
          WriteInPlace(ctx, cols, range, out, at);
        },
        [&](JobLoop& loop) { Coordinate(ctx, loop, cols, start); });
  }

 private:
  // The file this phase writes (its partial file while the jobs run) and its dimensions.
  std::string FinalPath(const FarmContext& ctx) const {
    const RunFolder& f = ctx.folder;
    // With features: the dense rows first (bounce-k, path-trace), then every row (-sparse).
    const bool features = ctx.params.sparse_indirect == 2;
    return features && !step_ ? (k_ > 0 ? f.BounceDenseFile(k_) : f.PathTracedDenseFile())
                              : (k_ > 0 ? f.BounceFile(k_) : f.PathTracedFile());
  }
  TransportFileInfo FileInfo(const FarmContext& ctx) const {
    const bool on_grid = k_ > 0 || ctx.params.sparse_indirect;
    return TransportFileInfo{
        static_cast<uint64_t>(ctx.params.channels) * ctx.params.rows,
        static_cast<uint32_t>(on_grid ? ctx.params.indirect_n : ctx.params.cubemap_n),
        ctx.options.rows_per_block, static_cast<uint32_t>(ctx.params.gather_paths),
        ctx.params.seed};
  }

  // Rows in place (docs/farm.md, "Where the rows go"): the job's rows, vertex-major after the
  // header at `at` of `out`, go into the phase's partial file by channel (row c·V + v), durably;
  // `out` keeps the header (in_place = 1) and what followed the rows (path tracing's energies).
  void WriteInPlace(const FarmContext& ctx, std::size_t cols, const RowRange& range,
                    std::string& out, std::size_t at) {
    if (!ctx.rows_in_place) return;
    if (!rows_out_)
      rows_out_.emplace(TransportFileWriter::OpenRows(FinalPath(ctx) + ".partial", FileInfo(ctx)));
    const int C = ctx.params.channels;
    const uint64_t V = ctx.params.rows;
    const std::size_t floats = static_cast<std::size_t>(range.count) * C * cols;
    if (out.size() < at + sizeof(BounceResultHeader) + floats * sizeof(float))
      throw std::logic_error(name_ + ": a job's result is shorter than its rows");
    const float* rows =
        reinterpret_cast<const float*>(out.data() + at + sizeof(BounceResultHeader));
    std::vector<float> channel(static_cast<std::size_t>(range.count) * cols);
    for (int c = 0; c < C; ++c) {
      for (uint64_t i = 0; i < range.count; ++i)
        std::copy_n(rows + (i * C + c) * cols, cols, channel.data() + i * cols);
      rows_out_->WriteRows(c * V + range.first, range.count, channel.data());
    }
    rows_out_->Sync();
    BounceResultHeader h;
    std::memcpy(&h, out.data() + at, sizeof h);
    h.in_place = 1;
    std::memcpy(out.data() + at, &h, sizeof h);
    out.erase(at + sizeof h, floats * sizeof(float));
  }

  // The path-traced estimator: one phase, every bounce at once; a job's payload holds each
  // vertex's Σ_k Tᵏ (channels rows at n) and then, per bounce and channel, the energy of its
  // vertices.
  void RunPathTracing(FarmContext& ctx, std::size_t cols, double start) {
    if (ctx.rank == 0) ctx.run_eta.StepStarted(name_);
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<PathTraceReference> reference;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      const PathTraceOptions po = PathOptions(ctx);
      // Sparse: the dense vertices' rows on the indirect grid (Huang & Ramamoorthi 2010 §4.2:
      // "we directly use the low-resolution grid"), the others combined from them.
      const int grid_n = ctx.params.sparse_indirect ? ctx.params.indirect_n : ctx.params.cubemap_n;
      reference = std::make_unique<PathTraceReference>(*ctx.embree, *surfaces, grid_n, po);
    }
    RunJobPhase(
        ctx,
        [&](const RowRange& range, std::string_view, std::string& out) {
          const std::size_t at = out.size();
          ComputePaths(ctx, *reference, cols, range, out);
          WriteInPlace(ctx, cols, range, out, at);
        },
        [&](JobLoop& loop) { Coordinate(ctx, loop, cols, start); });
  }

  // [sparse] indirect = "features" (docs/sparse-precomputation.md, "With interreflection"):
  // after the dense vertices evaluated their whole rows on the indirect grid (the phase before,
  // its dense file broadcast as `dense`), every other vertex evaluates its feature texels and is
  // reconstructed from its dense neighbours by L1 (ReconstructIndirectRow, §5), the evaluated
  // values kept exactly; dense rows are copied. Path tracing evaluates them with the same paths,
  // gathering with [sparse] feature_paths directions from the previous bounce's rows.
  void RunFeatures(FarmContext& ctx, const std::vector<float>& previous, int prev_channels,
                   const std::vector<float>& dense, std::size_t cols, double start) {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<PathTraceReference> reference;
    std::unique_ptr<BounceGatherer> gatherer;
    std::unique_ptr<IndirectComponent> component;
    std::unique_ptr<NeighborIndex> index;
    std::vector<float> by_vertex;  // the dense rows vertex-major: C rows of cols per vertex
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      if (k_ == 0) {
        reference = std::make_unique<PathTraceReference>(*ctx.embree, *surfaces,
                                                         ctx.params.indirect_n, PathOptions(ctx));
        component = std::make_unique<PathTracedIndirect>(*reference, C);
      } else {
        BounceGatherOptions go = GatherOptions(ctx);
        if (ctx.params.sparse_feature_paths > 0) go.paths = ctx.params.sparse_feature_paths;
        gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, go);
        component = std::make_unique<GatheredBounce>(*gatherer, k_, C, previous.data(), V,
                                                     prev_channels, cols);
      }
      std::vector<uint32_t> ids;
      std::vector<Vec3> points;
      for (uint64_t v = 0; v < V; ++v)
        if (!Combined(v)) {
          ids.push_back(static_cast<uint32_t>(v));
          points.push_back(ctx.samples[v].position);
        }
      index = std::make_unique<NeighborIndex>(points, ids);
      by_vertex.resize(dense.size());
      for (int c = 0; c < C; ++c)
        for (uint64_t v = 0; v < V; ++v)
          std::copy_n(dense.data() + (c * V + v) * cols, cols,
                      by_vertex.data() + (v * C + c) * cols);
    }
    const SparseIndirectOptions io =
        IndirectOptionsOf(ctx.plan, ctx.params.cubemap_n, ctx.params.indirect_n);
    RunJobPhase(
        ctx,
        [&](const RowRange& range, std::string_view, std::string& out) {
          const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
          const std::size_t at = out.size();
          const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
          out.resize(at + sizeof(BounceResultHeader) + floats * sizeof(float));
          float* rows = reinterpret_cast<float*>(out.data() + at + sizeof(BounceResultHeader));
          tbb::enumerable_thread_specific<L1Solver> solvers([&] {
            L1Options o;
            o.lambda = io.lambda;
            return L1Solver(o);
          });
          tbb::enumerable_thread_specific<SparseIndirectStats> stats;
          tbb::parallel_for(uint64_t{0}, range.count, [&](uint64_t i) {
            const uint64_t v = range.first + i;
            float* row = rows + i * per_vertex;
            if (!Combined(v)) {
              std::copy_n(by_vertex.data() + v * per_vertex, per_vertex, row);
              return;
            }
            ReconstructIndirectAt(
                *component, ctx.samples, static_cast<uint32_t>(v), *index, ctx.plan.radius,
                ctx.plan.max_neighbors,
                [&](uint32_t d) { return by_vertex.data() + d * per_vertex; }, io, solvers.local(),
                row, stats.local());
          });
          for (std::size_t i = 0; i < floats; ++i)
            if (!std::isfinite(rows[i]))
              throw NumericalError(name_ + ": a non-finite value for sample " +
                                   std::to_string(range.first + i / per_vertex));
          BounceResultHeader h;
          for (const SparseIndirectStats& st : stats) {
            h.rays_traced += st.rays;
            h.rays_escaped += st.texels_evaluated;  // journaled: the texels evaluated
            h.back_face_hits += st.fallbacks();     // and the whole rows of fallbacks
          }
          h.rows_checksum = Checksum64(rows, floats * sizeof(float));
          std::memcpy(out.data() + at, &h, sizeof h);
          WriteInPlace(ctx, cols, range, out, at);
        },
        [&](JobLoop& loop) { Coordinate(ctx, loop, cols, start); });
  }

  static BounceGatherOptions GatherOptions(const FarmContext& ctx) {
    BounceGatherOptions go;
    go.paths = ctx.params.gather_paths;
    go.seed = ctx.params.seed;
    go.indirect_n = ctx.params.indirect_n;
    go.near_field = ctx.params.near_field;
    return go;
  }

  static PathTraceOptions PathOptions(const FarmContext& ctx) {
    PathTraceOptions po;
    po.bounces = ctx.params.bounces;
    po.paths = ctx.params.gather_paths;
    po.rays_per_texel = ctx.params.rays_per_texel;
    po.path_rays_per_texel = 1;
    po.seed = ctx.params.seed;
    return po;
  }

  void ComputePaths(const FarmContext& ctx, const PathTraceReference& reference, std::size_t cols,
                    const RowRange& range, std::string& out) const {
    const int C = ctx.params.channels, K = ctx.params.bounces;
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    const std::size_t at = out.size();
    const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
    const std::size_t energies = static_cast<std::size_t>(K) * C;
    out.resize(at + sizeof(BounceResultHeader) + floats * sizeof(float) +
               energies * sizeof(double));
    float* rows = reinterpret_cast<float*>(out.data() + at + sizeof(BounceResultHeader));
    struct Local {
      PathTraceStats stats;
      std::vector<double> energy;
    };
    tbb::enumerable_thread_specific<Local> locals([&] {
      return Local{{}, std::vector<double>(energies, 0.0)};
    });
    tbb::parallel_for(uint64_t{0}, range.count, [&](uint64_t i) {
      thread_local std::vector<float> row, bounce_rows;
      if (Combined(range.first + i)) {  // filled by rank 0 from the dense rows
        std::fill_n(rows + i * per_vertex, per_vertex, 0.0f);
        return;
      }
      row.resize(per_vertex);
      bounce_rows.resize((K + 1) * per_vertex);
      PathTraceExtras ex;
      ex.bounce_rows = bounce_rows.data();
      Local& local = locals.local();
      float* dst = rows + i * per_vertex;
      if (ctx.params.sparse_indirect) {
        // The indirect rows alone, as the sparse kernels evaluate them (worker/
        // sparse_indirect.h: PathTracedIndirect); no per-bounce split.
        local.stats +=
            reference.ComputeIndirect(ctx.samples[range.first + i], range.first + i, C, {}, dst);
        return;
      }
      local.stats +=
          reference.ComputeRow(ctx.samples[range.first + i], range.first + i, C, row.data(), ex);
      std::fill(dst, dst + per_vertex, 0.0f);
      for (int k = 1; k <= K; ++k)
        for (int c = 0; c < C; ++c) {
          const float* src = bounce_rows.data() + (static_cast<std::size_t>(k) * C + c) * cols;
          double e = 0;
          for (std::size_t j = 0; j < cols; ++j) {
            dst[c * cols + j] += src[j];
            e += src[j];
          }
          local.energy[(k - 1) * C + c] += e;
        }
    });
    for (std::size_t i = 0; i < floats; ++i)
      if (!std::isfinite(rows[i]))
        throw NumericalError(name_ + ": a non-finite value for sample " +
                             std::to_string(range.first + i / per_vertex));
    BounceResultHeader h;
    std::vector<double> energy(energies, 0.0);
    for (const Local& l : locals) {
      h.rays_traced += l.stats.rays_traced();
      h.rays_escaped += l.stats.escaped;
      h.back_face_hits += l.stats.back_faces;
      for (std::size_t e = 0; e < energies; ++e) energy[e] += l.energy[e];
    }
    h.rows_checksum = Checksum64(rows, floats * sizeof(float));
    std::memcpy(out.data() + at, &h, sizeof h);
    std::memcpy(out.data() + at + sizeof h + floats * sizeof(float), energy.data(),
                energies * sizeof(double));
  }

  // T⁰ coarsened to the indirect grid (k = 1) or bounce k − 1's rows (rank 0, or every rank with
  // rows in place).
  std::vector<float> LoadPrevious(FarmContext& ctx, const CubemapLayout& fine,
                                  const CubemapLayout& coarse, int prev_channels) const {
    const std::size_t cols = coarse.texel_count();
    const uint64_t V = ctx.params.rows;
    std::vector<float> previous(static_cast<std::size_t>(prev_channels * V * cols));
    if (k_ == 1) {
      const TransportFileReader reader(ctx.folder.transport);
      if (reader.info().rows != V || reader.info().cubemap_n != uint32_t(fine.n()))
        throw InputError(ctx.folder.transport, "does not hold the run's direct rows");
      AddCoarsenedRows(reader, coarse, previous.data());
    } else {
      const std::string path = ctx.folder.BounceFile(k_ - 1);
      const TransportFileReader reader(path);
      if (reader.info().rows != prev_channels * V ||
          reader.info().cubemap_n != uint32_t(coarse.n()))
        throw InputError(path, "does not hold bounce " + std::to_string(k_ - 1) + "'s rows");
      reader.ReadRows(0, reader.info().rows, previous.data());
    }
    return previous;
  }

  // In a features step (rank 0, or every rank with rows in place): the dense vertices' rows of
  // this bounce (or path tracing's).
  std::vector<float> LoadDense(FarmContext& ctx, const CubemapLayout& coarse) const {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const std::string path =
        k_ > 0 ? ctx.folder.BounceDenseFile(k_) : ctx.folder.PathTracedDenseFile();
    const TransportFileReader reader(path);
    if (reader.info().rows != C * V || reader.info().cubemap_n != uint32_t(coarse.n()))
      throw InputError(path, "does not hold the dense vertices' rows of " + name_);
    std::vector<float> dense(static_cast<std::size_t>(reader.info().rows * coarse.texel_count()));
    reader.ReadRows(0, reader.info().rows, dense.data());
    return dense;
  }

  // Vertices `range` into the payload: the header, then channels rows per vertex
  // (vertex-major).
  void Compute(const FarmContext& ctx, const BounceGatherer& gatherer,
               const std::vector<float>& previous, int prev_channels, std::size_t cols,
               const RowRange& range, std::string& out) const {
    const int C = ctx.params.channels;
    const uint64_t V = ctx.params.rows;
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    const std::size_t at = out.size();
    const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
    out.resize(at + sizeof(BounceResultHeader) + floats * sizeof(float));
    float* rows = reinterpret_cast<float*>(out.data() + at + sizeof(BounceResultHeader));
    tbb::enumerable_thread_specific<GatherStats> stats;
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 8),
                      [&](const tbb::blocked_range<uint64_t>& r) {
                        std::vector<GatherTerm> terms;
                        std::vector<float> near;
                        for (uint64_t i = r.begin(); i != r.end(); ++i) {
                          const uint64_t v = range.first + i;
                          if (Combined(v)) {  // filled by rank 0 from the dense rows
                            std::fill_n(rows + i * per_vertex, per_vertex, 0.0f);
                            continue;
                          }
                          stats.local() += gatherer.GatherRow(
                              ctx.samples[v], v, k_, C, previous.data(), V, prev_channels, cols,
                              rows + i * per_vertex, terms, near);
                        }
                      });
    for (std::size_t i = 0; i < floats; ++i)
      if (!std::isfinite(rows[i]))
        throw NumericalError(name_ + ": a non-finite value for sample " +
                             std::to_string(range.first + i / per_vertex));
    GatherStats s;
    for (const GatherStats& l : stats) s += l;
    BounceResultHeader h;
    h.rows_checksum = Checksum64(rows, floats * sizeof(float));
    h.rays_traced = s.rays_traced;
    h.rays_escaped = s.rays_escaped;
    h.back_face_hits = s.back_face_hits;
    std::memcpy(out.data() + at, &h, sizeof h);
  }

  // Rows [first, first + count) of every channel from the file, vertex-major (as a job returns
  // them).
  static void ReadVertexMajor(const TransportFileWriter& w, uint64_t V, int C, std::size_t cols,
                              const RowRange& range, std::vector<float>& out) {
    out.resize(static_cast<std::size_t>(range.count * C * cols));
    std::vector<float> channel(static_cast<std::size_t>(range.count * cols));
    for (int c = 0; c < C; ++c) {
      w.ReadRows(c * V + range.first, range.count, channel.data());
      for (uint64_t i = 0; i < range.count; ++i)
        std::copy_n(channel.data() + i * cols, cols, out.data() + (i * C + c) * cols);
    }
  }

  void Coordinate(FarmContext& ctx, JobLoop& loop, std::size_t cols, double start) {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const RunFolder& f = ctx.folder;
    const bool features = ctx.params.sparse_indirect == 2;
    const std::string final_path = FinalPath(ctx);
    const int K = ctx.params.bounces;
    // Path tracing: each job's per-bounce energies (journaled as its counters, bit-cast).
    const std::size_t energies = k_ == 0 && !step_ ? static_cast<std::size_t>(K) * C : 0;
    std::vector<double> path_energy(energies, 0.0);
    auto add_energy = [&](const std::vector<uint64_t>& counters) {
      for (std::size_t e = 0; e < energies && e < counters.size(); ++e)
        path_energy[e] += std::bit_cast<double>(counters[e]);
    };
    const std::string partial = final_path + ".partial";
    std::error_code ec;
    fs::create_directories(f.indirect, ec);
    const TransportFileInfo info = FileInfo(ctx);
    nlohmann::ordered_json bounce = nlohmann::ordered_json::object();
    if (k_ > 0) bounce["bounce"] = k_;
    JobBatch batch;
    uint64_t reused_jobs = 0;
    std::optional<TransportFileWriter> writer;
    // The indirect stage's journal: this stage's lines, if its key is the one of the inputs
    // given now (the setup removed the folder and the journal when they changed).
    const std::string journal_path = f.indirect_journal;
    std::vector<JournalEntry> kept;
    {
      const JournalContents journal = ReadJournal(journal_path);
      if (journal.has_header && journal.run_key == ctx.indirect_key) kept = journal.entries;
    }
    bool complete = false;
    if (fs::exists(final_path, ec)) {
      try {
        const TransportFileReader r(final_path);
        complete = r.info().rows == info.rows && r.info().cubemap_n == info.cubemap_n;
      } catch (const InputError&) {
      }
    }
    if (complete) {
      batch.done.push_back({0, V});
      spdlog::info("[{}] re-used: {} is complete", name_, final_path);
    } else {
      if (fs::exists(partial, ec)) {
        try {
          writer.emplace(TransportFileWriter::Reopen(partial, info));
        } catch (const InputError& e) {
          spdlog::warn("{}; its jobs are redone", e.what());
        }
      }
      if (!writer) writer.emplace(TransportFileWriter::Create(partial, info));
      std::vector<float> rows;
      for (const JournalEntry& e : kept) {
        if (e.phase != name_ || e.rows.end() > V || e.rows.count * C * cols * 4 > kMaxJobBytes)
          continue;
        const bool overlaps = std::any_of(
            batch.done.begin(), batch.done.end(),
            [&](const RowRange& d) { return e.rows.first < d.end() && d.first < e.rows.end(); });
        if (overlaps) continue;
        ReadVertexMajor(*writer, V, C, cols, e.rows, rows);
        // As the job returned them: zeros for combined vertices, except in path-trace-sparse,
        // whose jobs return every row.
        for (uint64_t i = 0; i < e.rows.count && !step_; ++i)
          if (Combined(e.rows.first + i))
            std::fill_n(rows.data() + i * C * cols, static_cast<std::size_t>(C) * cols, 0.0f);
        if (Checksum64(rows.data(), rows.size() * sizeof(float)) != e.rows_checksum) {
          ++ctx.report.checkpoints_rejected;
          continue;
        }
        batch.done.push_back(e.rows);
        add_energy(e.counters);
        ++reused_jobs;
      }
      if (reused_jobs > 0)
        spdlog::info("[{}] {} job(s) re-used from checkpoints", name_, reused_jobs);
    }
    ctx.report.jobs_reused += reused_jobs;
    // The journal, rewritten with the lines still valid, takes this phase's lines.
    std::unique_ptr<CheckpointJournal> journal =
        std::make_unique<CheckpointJournal>(journal_path, ctx.indirect_key, kept);
    std::swap(journal, ctx.journal);

    uint64_t rays = 0, escaped = 0, back = 0;
    batch.name = name_;
    batch.items = V;
    batch.unit = "samples";
    batch.max_items = std::max<uint64_t>(1, kMaxJobBytes / (C * cols * sizeof(float)));
    batch.cost = SampleCost(ctx);  // image runs: background pixels next to free (issue 37)
    const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
    batch.accept = [&](int rank, const RowRange& range, std::string_view payload) {
      BounceResultHeader h;
      if (payload.size() >= sizeof h) std::memcpy(&h, payload.data(), sizeof h);
      // Rows in place: the worker wrote them; only the header and the energies came.
      const std::size_t floats =
          h.in_place ? 0 : static_cast<std::size_t>(range.count) * per_vertex;
      if (payload.size() != sizeof h + floats * sizeof(float) + energies * sizeof(double))
        throw RankFailure("rank " + std::to_string(rank) + " returned " +
                          std::to_string(payload.size()) + " bytes for " +
                          std::to_string(range.count) + " samples of " + name_);
      const float* rows = reinterpret_cast<const float*>(payload.data() + sizeof h);
      if (!h.in_place && Checksum64(rows, floats * sizeof(float)) != h.rows_checksum)
        throw RankFailure("rows of " + name_ + " from rank " + std::to_string(rank) +
                          " arrived damaged (checksum mismatch)");
      std::vector<float> channel(static_cast<std::size_t>(range.count) * cols);
      for (int c = 0; c < C && !h.in_place; ++c) {
        for (uint64_t i = 0; i < range.count; ++i)
          std::copy_n(rows + (i * C + c) * cols, cols, channel.data() + i * cols);
        writer->WriteRows(c * V + range.first, range.count, channel.data());
      }
      JournalEntry e;
      e.phase = name_;
      e.rows = range;
      e.rows_checksum = h.rows_checksum;
      for (std::size_t i = 0; i < energies; ++i) {
        double x = 0;
        std::memcpy(&x, payload.data() + sizeof h + floats * sizeof(float) + i * sizeof x,
                    sizeof x);
        e.counters.push_back(std::bit_cast<uint64_t>(x));
      }
      e.rays_traced = h.rays_traced;
      e.texels_traced = h.rays_escaped;
      e.texels_below_horizon = h.back_face_hits;
      return e;
    };
    batch.sync = [&] { writer->Sync(); };
    batch.committed = [&](const JournalEntry& e) {
      rays += e.rays_traced;
      escaped += e.texels_traced;
      back += e.texels_below_horizon;
      add_energy(e.counters);
    };
    try {
      loop.Run(batch);
    } catch (...) {
      std::swap(journal, ctx.journal);
      throw;
    }
    std::swap(journal, ctx.journal);
    if (writer && !pairs_.empty() && ctx.params.sparse_indirect == 1)
      FillCombined(ctx, *writer, cols);
    if (writer) {
      writer->Finalize();
      writer.reset();
      fs::rename(partial, final_path);
      SyncDirectory(f.indirect);
    }

    // This bounce's figures: energy Σ T per channel, rays, and (after the last bounce) the
    // indirect share of B under each scene environment.
    const TransportFileReader reader(final_path);
    std::vector<float> all(static_cast<std::size_t>(info.rows * cols));
    reader.ReadRows(0, info.rows, all.data());
    nlohmann::ordered_json energy = nlohmann::ordered_json::array();
    for (int c = 0; c < C; ++c) {
      double s = 0;
      for (std::size_t i = c * V * cols; i < (c + 1) * V * cols; ++i) s += all[i];
      energy.push_back(s);
    }
    bounce["energy"] = energy;
    bounce["rays_traced"] = rays;
    bounce["rays_escaped"] = escaped;
    bounce["back_face_hits"] = back;
    bounce["jobs_reused"] = reused_jobs;
    bounce["wall_seconds"] = FarmNow() - start;
    if (step_) {
      bounce["texels_evaluated"] = escaped;  // journaled in place of escapes (RunFeatures)
      bounce["fallbacks"] = back;
      bounce.erase("rays_escaped");
      bounce.erase("back_face_hits");
      bounce.erase("bounce");
      if (k_ > 0 && !ctx.interreflection["per_bounce"].empty()) {
        // The bounce's entry (its dense phase's) takes the whole bounce's energy.
        auto& entry = ctx.interreflection["per_bounce"].back();
        entry["energy"] = energy;
        entry["features"] = bounce;
      } else if (k_ == 0) {
        ctx.interreflection["path_trace_features"] = bounce;
      }
    } else if (k_ > 0) {
      ctx.interreflection["per_bounce"].push_back(bounce);
    } else {
      // Path tracing: the whole indirect part in one phase; each bounce's energy from the jobs'
      // (none with the sparse method: its rows are Σ_k Tᵏ, evaluated at once).
      for (int k = 1; k <= K && !ctx.params.sparse_indirect; ++k) {
        nlohmann::ordered_json e = nlohmann::ordered_json::array();
        for (int c = 0; c < C; ++c) e.push_back(path_energy[(k - 1) * C + c]);
        ctx.interreflection["per_bounce"].push_back({{"bounce", k}, {"energy", e}});
      }
      ctx.interreflection["path_trace"] = bounce;
    }
    spdlog::info("[{}] energy {} (sum of the bounce's T per channel), {} rays, {:.1f} s", name_,
                 energy.dump(), rays, FarmNow() - start);
    ctx.report.jobs_total = ctx.report.jobs_done + ctx.report.jobs_reused;
    if ((k_ == K || k_ == 0) && (step_ || !features)) IndirectShare(ctx);
    ctx.report.interreflection_json = ctx.interreflection.dump();
  }

  // Rank 0, after the last bounce: Σ_v ρ·(indirect · L) / Σ_v ρ·(T · L) under each scene
  // environment and a uniform sky, on the indirect grid.
  static void IndirectShare(FarmContext& ctx) {
    LoadEstimateLights(ctx);
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    const std::vector<std::string> files =
        IndirectFiles(ctx.folder, ctx.params.bounces, ctx.params.path_estimator != 0);
    const CubemapLayout fine(ctx.params.cubemap_n), coarse(ctx.params.indirect_n);
    const std::size_t cols = coarse.texel_count();
    // T⁰ coarsened, and Σ_k Tᵏ.
    std::vector<float> direct(static_cast<std::size_t>(V * cols), 0.0f);
    AddCoarsenedRows(TransportFileReader(ctx.folder.transport), coarse, direct.data());
    // Bounce rows are on the indirect grid already; path-traced ones at n are coarsened.
    std::vector<float> indirect(static_cast<std::size_t>(C * V * cols), 0.0f);
    for (const std::string& file : files)
      AddCoarsenedRows(TransportFileReader(file), coarse, indirect.data());
    nlohmann::ordered_json share = nlohmann::ordered_json::array();
    for (std::size_t l = 0; l < ctx.estimate.lights.size(); ++l) {
      double d = 0, ind = 0;
      for (int c = 0; c < 3; ++c) {
        const std::vector<float> L = CoarsenLight(fine, coarse, ctx.estimate.lights[l].Channel(c));
        const int tc = C == 1 ? 0 : c;
        for (uint64_t v = 0; v < V; ++v) {
          const double rho = ctx.RowAlbedo(v)[c];
          d += rho * Dot(direct.data() + v * cols, L.data(), cols);
          ind += rho * Dot(indirect.data() + (tc * V + v) * cols, L.data(), cols);
        }
      }
      share.push_back({{"light", ctx.estimate.names[l]},
                       {"indirect_share", d + ind > 0 ? ind / (d + ind) : 0.0}});
      spdlog::info("interreflection: {:.1f}% of B is bounce light under {}",
                   d + ind > 0 ? 100 * ind / (d + ind) : 0.0, ctx.estimate.names[l]);
    }
    ctx.interreflection["indirect_share"] = share;
  }

  // Sparse precomputation with interreflection ([sparse] indirect = "combination"; docs/
  // sparse-precomputation.md): rank 0 reads run/sparse/combination.bin and every rank learns
  // which vertices have a combination; those gather nothing (their job rows are zeros), and rank
  // 0 fills them after the job loop, Tᵏ(x) = max(0, Σ α_j Tᵏ(d_j)) over the dense vertices d_j
  // x's direct row was reconstructed from. Without the file (a run folder from before it) every
  // vertex gathers.
  void LoadCombination(FarmContext& ctx) {
    mask_.clear();
    pairs_.clear();
    if (!ctx.params.sparse_indirect) return;
    const uint64_t V = ctx.params.rows;
    if (ctx.rank == 0) {
      try {
        pairs_ = ReadCombinationFile(ctx.folder.SparseCombinationFile(), V, slots_);
        mask_.assign(static_cast<std::size_t>(V), 0);
        for (uint64_t v = 0; v < V; ++v) mask_[v] = pairs_[v * slots_ * 2] != kNoSample ? 1 : 0;
        uint64_t combined = 0;
        for (uint8_t m : mask_) combined += m;
        if (step_)
          spdlog::info("[{}] {} of {} vertices are dense; {} evaluate their features", name_,
                       V - combined, V, combined);
        else
          spdlog::info("[{}] {} of {} vertices gather; {} combine the dense vertices' rows", name_,
                       V - combined, V, combined);
        ctx.interreflection["sparse_combined_vertices"] = combined;
      } catch (const InputError& e) {
        spdlog::warn("{}: every vertex gathers", e.what());
        pairs_.clear();
        mask_.clear();
      }
    }
    BroadcastVector(ctx.comm, mask_, MPI_BYTE, "MPI_Bcast bounce mask");
  }
  bool Combined(uint64_t v) const { return !mask_.empty() && mask_[v] != 0; }

  // Rank 0: the combined vertices' rows from the dense ones, written over their zeros.
  void FillCombined(const FarmContext& ctx, TransportFileWriter& writer, std::size_t cols) const {
    const uint64_t V = ctx.params.rows;
    const int C = ctx.params.channels;
    std::vector<float> all(static_cast<std::size_t>(V * cols));
    std::vector<SampleWeight> w;
    for (int c = 0; c < C; ++c) {
      writer.ReadRows(c * V, V, all.data());
      std::vector<float> filled = all;
      for (uint64_t v = 0; v < V; ++v) {
        if (!Combined(v)) continue;
        w.clear();
        for (std::size_t j = 0; j < slots_; ++j) {
          const uint32_t d = pairs_[(v * slots_ + j) * 2];
          if (d == kNoSample) continue;
          if (Combined(d))
            throw InputError(ctx.folder.SparseCombinationFile(),
                             "combines vertex " + std::to_string(v) + " from vertex " +
                                 std::to_string(d) + ", which is not dense");
          w.push_back({d, std::bit_cast<float>(pairs_[(v * slots_ + j) * 2 + 1])});
        }
        CombineRows(
            w, [&](uint32_t d) { return all.data() + static_cast<std::size_t>(d) * cols; }, cols,
            filled.data() + v * cols);
      }
      writer.WriteRows(c * V, V, filled.data());
    }
  }

  int k_;
  bool step_;
  std::string name_;
  // This rank's handle on the phase's partial file (rows in place), opened at its first job.
  std::optional<TransportFileWriter> rows_out_;
  std::vector<uint8_t> mask_;    // per vertex: 1 = combined (every rank)
  std::vector<uint32_t> pairs_;  // rank 0: combination.bin's pairs
  uint64_t slots_ = 0;
};

}  // namespace

std::unique_ptr<FarmPhase> MakeBouncePhase(int k, bool features_step) {
  return std::make_unique<BouncePhase>(k, features_step);
}

}  // namespace prt
