// What prt-farm's phases share on one rank, and the interface every phase implements
// (docs/architecture.md, "Adding a farm phase"). Internal to farm/: only the phase files and
// farm_run.cpp include this.
//
// Every rank runs the same list of phases (SPMD). A phase that hands out work builds a JobBatch
// and runs it on the job loop (farm/job_loop.h); a phase that only finishes files runs on rank 0
// and returns elsewhere.
#pragma once

#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <typeindex>
#include <unordered_map>
#include <vector>

#include "farm/checkpoint_journal.h"
#include "farm/collectives.h"
#include "farm/farm_options.h"
#include "farm/farm_report.h"
#include "farm/progress.h"
#include "farm/run_eta.h"
#include "farm/stage_inputs.h"
#include "farm/stage_plan.h"
#include "farm/variance_accumulator.h"
#include "farm/visibility_jobs.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "formats/transport_variance.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"
#include "worker/embree_scene.h"
#include "worker/glossy_pixels.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_sampler.h"
#include "worker/visibility_sampler.h"

namespace prt {

// Seconds on a monotonic clock.
inline double FarmNow() {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

// What setup decided, broadcast from rank 0 to every rank as bytes.
struct SetupParams {
  uint64_t rows = 0;
  uint64_t geometry_bytes = 0;
  uint64_t seed = 1;
  int32_t cubemap_n = 32;
  int32_t rays_per_texel = 4;
  int32_t sparse = 0;      // 1: method sparse (the SparsePlan follows in a second broadcast)
  int32_t visibility = 0;  // 1: the visibility job (cubemap_n is then the maps' n)
  int32_t visibility_supersample = 1;
  int32_t visibility_bits = 1;
  // Which stages run (farm/stage_plan.h): 1 = the rows are sampled (fresh or resumed), the
  // compression and the estimate run.
  int32_t run_rows = 1;
  int32_t run_compression = 1;
  int32_t run_estimate = 1;
  // Interreflection (docs/interreflection.md): bounces after the direct term, the bounce rows'
  // cubemap n, gather directions per vertex, rows of T per sample (3: bounces with coloured
  // albedos), and whether the indirect stage runs.
  int32_t bounces = 0;
  int32_t indirect_n = 0;
  int32_t gather_paths = 1024;
  double near_field = 1.0;
  int32_t channels = 1;
  int32_t run_indirect = 0;
  int32_t path_estimator = 0;  // 1: the bounces by per-element path tracing (one phase)
  // Method sparse with bounces ([sparse] indirect): 1 "combination": only the dense vertices
  // gather (or trace paths, on the indirect grid), the others combine them (run/sparse/
  // combination.bin); 2 "features": the others evaluate their feature texels (a -sparse phase
  // after each bounce).
  int32_t sparse_indirect = 0;
  // [sparse] indirect = "features" with gathering: the directions a sparse vertex gathers its
  // feature texels with (0: gather_paths).
  int32_t sparse_feature_paths = 0;
  // Image relighting (docs/image-relighting.md): 1 when the samples are the pixels of `camera`
  // (rows = width·height in raster order), 0 for mesh vertices.
  int32_t image = 0;
  Camera camera;
  // Image runs with glossy pixels (worker/glossy_pixels.h): the size of the per-mesh table rank 0
  // broadcasts after the geometry; 0 when every pixel is diffuse.
  uint64_t glossy_bytes = 0;
  // Glossy vertex transport (docs/glossy-transport.md): the BRDF factorisation's terms m (rows
  // = m × vertices, term-major; 1 when every mesh is diffuse) and the size of the factor table
  // (run/glossy.prtf) rank 0 broadcasts after the geometry.
  int32_t terms = 1;
  uint64_t factor_bytes = 0;
  // 1: --resume of a run whose every stage is re-used (only scene.toml/geometry.prtg may have
  // been rewritten): no phase runs; 2: not even those changed (the report stays as it is).
  int32_t complete = 0;
};

// All ranks stop the run with this exit code (they have agreed on it collectively).
struct CollectiveStop {
  int exit_code;
};

// The lights of the estimate stage (farm/estimate_phase.cpp): a uniform sky and the scene's
// environments as lighting cubemaps, and Σ B² over each mesh's rows under each of them (no
// albedo), which the compression phase accumulates while the rows pass through it.
struct EstimateLights {
  std::vector<std::string> names;
  std::vector<CubemapRgb> lights;
  std::string left_out_json = "[]";  // environments that could not be read, and why
  bool have_norms = false;
  // RadianceNormAccumulator::Flat() of every rank summed: its exact digits, [light][mesh][channel]
  // (the sum is exact in any order, farm/compression_phase.cpp).
  std::vector<double> norms;
};
// "error of B (rays + reconstruction) 0.38% uniform 1.41% sunrise.exr …" from accuracy.json
// (the run summary and the estimate's log line).
std::string AccuracyLine(const nlohmann::ordered_json& accuracy);
// Rank 0: the lights, loaded once and kept as a typed result (ctx.results) for the compression
// phase, which accumulates the norms under them, and the estimate phase (every environment that
// cannot be read is left out, with why).
EstimateLights& LoadEstimateLights(struct FarmContext& ctx);

// What one phase leaves for later ones, by type (the only way phase state travels besides the run
// folder): a phase Puts a value of a type it declares in its header; a later phase Finds it
// (nullptr when the phase that makes it did not run).
class PhaseResults {
 public:
  template <class T>
  T& Put(T value) {
    auto p = std::make_shared<T>(std::move(value));
    T& ref = *p;
    values_[std::type_index(typeid(T))] = std::move(p);
    return ref;
  }
  template <class T>
  T* Find() const {
    const auto it = values_.find(std::type_index(typeid(T)));
    return it == values_.end() ? nullptr : static_cast<T*>(it->second.get());
  }

 private:
  std::unordered_map<std::type_index, std::shared_ptr<void>> values_;
};

// The rows stage's state (a typed result, ctx.results): setup opens it, the rows phase (brute
// force, the sparse method or the visibility job) fills it, finalize closes it.
struct RowsStageState {
  // Rank 0: transport.prtt.partial while sampling.
  std::optional<TransportFileWriter> writer;
  // Rank 0: the sampling jobs' Monte-Carlo variance sums (transport runs).
  std::unique_ptr<VarianceAccumulator> variance;
  bool variance_fresh = false;  // rank 0: its log starts empty (setup)
  // Rank 0: the journal's lines of the method's phase, verified by that phase before it re-uses
  // them (brute force: already verified against the rows by setup).
  std::vector<JournalEntry> journal_entries;
  // A computing rank with rows in place: its variance records and their sum, which finalize
  // reduces.
  std::unique_ptr<RankVarianceLog> rank_variance;
};
struct FarmContext;
// The rows stage's state of this rank (created empty the first time it is asked for).
RowsStageState& RowsStage(FarmContext& ctx);

struct FarmContext {
  // ---- every rank
  FarmOptions options;
  MPI_Comm comm = MPI_COMM_WORLD;
  Collectives collectives;  // what phases call instead of MPI (farm/collectives.h)
  PhaseResults results;     // typed results of earlier phases
  int rank = 0;
  int size = 1;
  int threads = 1;
  std::string host;
  RunFolder folder{"run"};
  SetupParams params;
  std::string method = "brute";  // "brute", "sparse" or "visibility"
  SceneGeometry geometry;        // decoded from the bytes rank 0 broadcast
  std::vector<SpatialSample> samples;
  // Image runs: per pixel, the mesh it sees or kImageBackground (worker/camera_samples.h).
  std::vector<uint32_t> pixel_mesh;
  // Image runs: per pixel, the longest edge of the triangle it sees (CameraSamples::pixel_edge).
  std::vector<float> pixel_edge;
  // Image runs with [camera] supersample > 1: every pixel's surface sub-samples and mixing
  // weights (CameraSamples::footprints; the sampler reads them), else null.
  std::shared_ptr<const SampleFootprints> footprints;
  // Image runs: the glossy pixels' materials per mesh (empty when every pixel is diffuse).
  GlossyPixels glossy_pixels;
  // Image runs: each pixel's row group (RowGroups): the mesh it sees, or meshes.size() for a
  // background pixel. Glossy vertex runs (terms > 1): each row's mesh.
  SampleGroupMap pixel_groups;
  // Glossy vertex runs: the factor table (run/glossy.prtf), which the sampler shares.
  std::shared_ptr<const GlossyFactorTable> glossy_factors;
  // Ranks that compute (computes_here()): the Embree scene and the job's sampler.
  std::unique_ptr<EmbreeScene> embree;
  std::unique_ptr<TransportSampler> sampler;
  std::unique_ptr<VisibilitySampler> visibility_sampler;
  SparsePlan plan;  // method sparse: every rank has rank 0's plan
  // Every rank sees the run folder (setup checked it with a probe file) and --rows-via-rank0 is
  // off: a computing rank writes the rows it computes into the run's files itself and sends
  // rank 0 only their checksums and counters; finalize and the compression's transpose read
  // each rank's share of the rows where it runs (docs/farm.md, "Where the rows go").
  bool rows_in_place = false;

  // ---- rank 0 only
  bool folder_ready = false;    // the run folder is this run's (a report can be written)
  SceneDescription scene;       // as parsed by setup (the estimate reads its environments)
  StagePlan stage_plan;         // what setup decided for each stage (report.json "stages")
  std::string previous_report;  // report.json of the run being continued ("" if none)
  std::string estimate_key;     // the estimate stage's key (accuracy.json "key")
  RunEta run_eta;               // the whole run's ETA on every progress line (rank 0)
  std::unique_ptr<CheckpointJournal> journal;
  // The indirect stage's key (its journal, checkpoints/indirect-journal.txt, is keyed by it).
  uint64_t indirect_key = 0;
  FarmReport report;

  // The row groups the per-mesh figures are taken over (variance sums, the estimate's tables,
  // accuracy.json): each mesh's vertices in scene order; for an image run each mesh's pixels
  // (they interleave in raster order: pixel_groups says which is whose), then the background
  // pixels (zero rows). Image runs: only once setup has traced the camera's pixels.
  // Glossy vertex runs: each mesh's rows of every term.
  std::vector<uint64_t> RowGroups() const {
    if (!GroupsByMap()) return geometry.MeshVertexCounts();
    if (!pixel_groups) throw std::logic_error("RowGroups: the pixels are not traced yet");
    std::vector<uint64_t> rows(geometry.meshes.size() + (params.image ? 1 : 0), 0);
    for (uint32_t g : *pixel_groups) ++rows.at(g);
    return rows;
  }
  bool GroupsByMap() const { return params.image || params.terms > 1; }
  // Each sample's group where they interleave (image runs, terms), else null (contiguous meshes).
  SampleGroupMap SampleGroups() const { return GroupsByMap() ? pixel_groups : nullptr; }
  std::size_t GroupOfRow(uint64_t row) const {
    return GroupsByMap() ? pixel_groups->at(row) : geometry.MeshOfVertex(row);
  }
  std::string GroupName(std::size_t g) const {
    return g < geometry.meshes.size() ? geometry.meshes[g].name : std::string("background");
  }
  // The albedo the per-group figures weigh radiance with: the mesh's (an image's glossy mesh:
  // its pixels' weight, worker/glossy_pixels.h); 0 for an image's background pixels.
  Rgb GroupAlbedo(std::size_t g) const {
    if (g >= geometry.meshes.size()) return Rgb{0.f, 0.f, 0.f};
    if (g < glossy_pixels.glossy.size() && glossy_pixels.glossy[g]) return glossy_pixels.weight[g];
    return geometry.meshes[g].albedo;
  }
  // The albedo of row `row`'s surface (0 for a background pixel; a glossy pixel's weight,
  // worker/glossy_pixels.h).
  Rgb RowAlbedo(uint64_t row) const {
    if (!params.image) return GroupAlbedo(GroupOfRow(row));
    const uint32_t m = pixel_mesh[row];
    if (m == kImageBackground) return Rgb{0.f, 0.f, 0.f};
    if (m < glossy_pixels.glossy.size() && glossy_pixels.glossy[m]) return glossy_pixels.weight[m];
    return geometry.meshes[m].albedo;
  }
  // transport.prtt.partial's dimensions (as setup created it).
  TransportFileInfo RowsFileInfo() const {
    return TransportFileInfo{params.rows, static_cast<uint32_t>(params.cubemap_n),
                             options.rows_per_block, static_cast<uint32_t>(params.rays_per_texel),
                             params.seed};
  }
  // Zero variance sums of this run's shape (n, rays per texel, row groups): what a rank's
  // RankVarianceLog starts from and what a job's sums are added to.
  TransportVariance EmptyVarianceSums() const {
    return MakeTransportVariance(static_cast<uint32_t>(params.cubemap_n),
                                 static_cast<uint32_t>(params.rays_per_texel), RowGroups(),
                                 SampleGroups());
  }
  bool computes_here() const { return rank != 0 || size == 1 || options.coordinator_works; }
  int computing_ranks() const {
    return size - 1 + ((size == 1 || options.coordinator_works) ? 1 : 0);
  }
  // How long a rank with jobs out may stay silent (no result, no heartbeat) before rank 0 gives
  // up on it (rank 0's own jobs are never timed out).
  double rank_timeout() const {
    return options.rank_timeout_s > 0 ? options.rank_timeout_s
                                      : std::max(300.0, 50.0 * options.job_seconds);
  }
};

// One phase of the run (docs/architecture.md, "Adding a farm phase"): everything the run needs
// to know about it is said here, in the phase's own file. The run (farm_run.cpp) knows only the
// list of phases (farm/phase_list.cpp); it runs them in order on every rank, adds each one's wall
// time to its stage, asks each for its share of the run's ETA, and lets each write its section of
// report.json at the end. A phase keeps its own state; what a later phase needs reaches it
// through the run folder or a typed result (PhaseResults).
inline RowsStageState& RowsStage(FarmContext& ctx) {
  if (RowsStageState* state = ctx.results.Find<RowsStageState>()) return *state;
  return ctx.results.Put(RowsStageState{});
}

class FarmPhase {
 public:
  virtual ~FarmPhase() = default;
  // The name in report.json's "phases" (and in progress lines).
  virtual const char* name() const = 0;
  // The stage it belongs to (farm/run_manifest.h: kStageRows, kStageIndirect, …): its wall time
  // counts in report.json's "stages", and the stage's key decides whether it runs at all.
  virtual const char* stage() const = 0;
  // Rank 0, once setup has decided the stages: the steps this phase will run and their predicted
  // durations (farm/run_eta.h), its share of the whole run's ETA. Nothing by default.
  virtual void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const {
    (void)ctx;
    (void)steps;
  }
  // Runs on every rank. Throws CollectiveStop when all ranks agreed to stop; any other
  // exception on a rank is fatal for the whole job (RunFarm aborts it).
  virtual void Run(FarmContext& ctx) = 0;
  // Rank 0, at the end of the run (also of a failed one): the phase's section of report.json
  // from its own state. Nothing by default.
  virtual void Report(FarmReport& report) const { (void)report; }
};

using PhaseList = std::vector<std::unique_ptr<FarmPhase>>;
// A phase's entry in the list (farm/phase_list.cpp): adds the phase (or phases: one per bounce)
// that this run needs, given what setup decided (ctx.params), to `phases`; adds nothing when the
// run does not need it.
using PhaseFactory = void (*)(const FarmContext& ctx, PhaseList& phases);
// The farm's phases in the order every rank runs them (farm/phase_list.cpp). The first is setup,
// which decides what the run is; the others are asked once it has.
const std::vector<PhaseFactory>& FarmPhaseList();

// The indirect stage's files that hold the samples' bounce rows: indirect/bounce-1 … K.prtt,
// indirect/path-traced.prtt, or for an image run that gathers (`image`),
// indirect/pixel-gather.prtt (the vertex support files beside it are not the samples' rows).
inline std::vector<std::string> IndirectFiles(const RunFolder& f, int bounces, bool path,
                                              bool image) {
  std::vector<std::string> files;
  if (path && bounces > 0) return {f.PathTracedFile()};
  if (image && bounces > 0) return {f.PixelGatherFile()};
  for (int k = 1; k <= bounces; ++k) files.push_back(f.BounceFile(k));
  return files;
}

// Vertices of the sparse method's initial dense set that its cross-validation reconstructs
// (farm/sparse_phase.cpp, CrossValidate; docs/farm.md "Accuracy estimates").
inline constexpr std::size_t kSparseCrossValidated = 400;

// Progress options of a farm loop on rank 0: --log-interval, --quiet, and the whole run's ETA
// appended to every line. `whole_step`: the loop is its run step's whole work (its ETA is the
// step's); else the step's prediction counts (a loop that is one part of its step).
ProgressOptions FarmProgressOptions(FarmContext& ctx, const std::string& unit,
                                    bool whole_step = true);

// The cost models' shared prior (phases' PredictSteps; docs/farm.md, "Progress"): the seconds of
// one brute-force row on the computing ranks, ~10 M occlusion rays/s per thread measured on the
// 2-core VM, rays over about half the sphere. The run's ETA replaces priors by what it measures.
inline double SecondsPerRow(const FarmContext& ctx) {
  const double cols = 6.0 * ctx.params.cubemap_n * ctx.params.cubemap_n;
  const double threads = std::max(1, ctx.computing_ranks()) * std::max(1, ctx.threads);
  return cols * ctx.params.rays_per_texel * 0.5 / (1e7 * threads);
}

// Max-reduces every rank's status; if any is non-zero, every rank stops with it.
void AgreeOrStop(FarmContext& ctx, int local_status);

// --fail-after-jobs K --fail-rank R (tests of killed runs): whether this rank is due to fail
// after `jobs` jobs, and the failure itself (_Exit(4), or sleeping forever with --fail-mode hang).
bool FailureDue(const FarmContext& ctx, int jobs);
[[noreturn]] void InjectFailure(const FarmContext& ctx, int jobs);
// --fail-in POINT: this rank dies now, without cleaning up.
[[noreturn]] void ExitAbruptly(int rank, const std::string& where);

}  // namespace prt
