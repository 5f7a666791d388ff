// prt-farm's coordinator (see farm_coordinator.h and docs/farm.md).
#include "farm/farm_coordinator.h"

#include <fcntl.h>
#include <mpi.h>
#include <sched.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <unordered_map>
#include <vector>

#include "farm/checkpoint_journal.h"
#include "farm/compression_phase.h"
#include "farm/farm_report.h"
#include "farm/job_planner.h"
#include "farm/mpi_support.h"
#include "farm/run_folder.h"
#include "farm/sparse_jobs.h"
#include "farm/visibility_jobs.h"
#include "vocabulary/errors.h"
#include "vocabulary/progress.h"
#include "vocabulary/scene.h"
#include "vocabulary/transport_file.h"
#include "worker/embree_scene.h"
#include "worker/local_rank.h"
#include "worker/neighbor_index.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_sampler.h"
#include "worker/visibility_sampler.h"

#ifndef PRT_DEFAULT_DATA_DIR
#define PRT_DEFAULT_DATA_DIR ""
#endif

namespace prt {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDefaultSceneName = "<default scene>";
constexpr uint64_t kMaxMessageBytes = uint64_t{64} << 20;  // rows travel in ≤ 64 MiB messages
constexpr uint64_t kMaxJobBytes = uint64_t{256} << 20;     // a job's rows fit in 256 MiB
// A sparse-method job's rows (the dense neighbours it is sent, or the rows it returns) fit in
// 24 MiB: glibc serves blocks above its mmap threshold (at most 32 MiB) with fresh pages on
// every allocation, so jobs of ~100 MiB paid a page fault per 4 KiB of every copy of every job
// (encode, MPI, decode, result) — 14 % of a 2-rank run's samples (docs/farm.md). Below it the
// buffers are reused from the heap.
constexpr uint64_t kMaxSparseJobBytes = uint64_t{24} << 20;
constexpr uint64_t kMaxBroadcastBytes = uint64_t{1} << 30;

// A worker waits for rank 0's next message without spinning: MPI_Probe busy-polls, and where
// ranks share cores (2 ranks on a laptop or in CI, oversubscribed nodes) a waiting worker took a
// core from rank 0's coordinator and its worker thread. Polls with MPI_Iprobe, sleeping 20 µs
// doubling to 1 ms in between (a job takes tens of milliseconds at least).
int ProbeFromRankZero(MPI_Comm comm, MPI_Status* st) {
  auto pause = std::chrono::microseconds(20);
  for (;;) {
    int flag = 0;
    const int rc = MPI_Iprobe(0, MPI_ANY_TAG, comm, &flag, st);
    if (rc != MPI_SUCCESS || flag) return rc;
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::microseconds(1000));
  }
}

// Messages sent with MPI_Isend whose buffers must live until the send completes, oldest first
// (a deque keeps its elements in place, so a buffer never moves while MPI holds it).
class BackgroundSends {
 public:
  void Send(std::string bytes, int dest, int tag, MPI_Comm comm, const std::string& what) {
    auto& [request, buffer] = sends_.emplace_back(MPI_REQUEST_NULL, std::move(bytes));
    CheckMpi(MPI_Isend(buffer.data(), static_cast<int>(buffer.size()), MPI_BYTE, dest, tag, comm,
                       &request),
             what);
  }
  // Frees the buffers of the sends that have left (and keeps MPI progressing).
  void Retire() {
    while (!sends_.empty()) {
      int sent = 0;
      CheckMpi(MPI_Test(&sends_.front().first, &sent, MPI_STATUS_IGNORE), "MPI_Test");
      if (!sent) return;
      sends_.pop_front();
    }
  }
  void WaitAll() {
    for (auto& [request, buffer] : sends_)
      CheckMpi(MPI_Wait(&request, MPI_STATUS_IGNORE), "MPI_Wait");
    sends_.clear();
  }

 private:
  std::deque<std::pair<MPI_Request, std::string>> sends_;
};

enum Tag : int {
  kTagReady = 1,
  kTagJob,
  kTagStop,
  kTagResult,
  kTagRows,
  kTagFailed,
  kTagSparseJob,         // an encoded sparse-method job (farm/sparse_jobs.h), one message
  kTagSparseResult,      // its encoded result, one message
  kTagVisibilityResult,  // an encoded visibility job result (farm/visibility_jobs.h)
};

struct ReadyMsg {
  int32_t threads = 0;
  char host[64] = {};
};

struct JobMsg {
  uint64_t first = 0;
  uint64_t count = 0;
};

struct ResultMsg {
  uint64_t first = 0;
  uint64_t count = 0;
  uint64_t rows_checksum = 0;
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
  double busy_seconds = 0;
};

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
  // 1: --resume of a transport run that already finished (transport.prtc written, the raw
  // matrix removed) whose inputs still match its manifest: nothing is left to do.
  int32_t complete = 0;
};
static_assert(std::is_trivially_copyable_v<SparsePlan>, "SparsePlan is broadcast as bytes");

double Now() {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

// All ranks stop the run with this exit code (they have agreed on it collectively).
struct CollectiveStop {
  int exit_code;
};

// What the phases share on one rank.
struct FarmContext {
  FarmOptions options;
  MPI_Comm comm = MPI_COMM_WORLD;
  int rank = 0;
  int size = 1;
  int threads = 1;
  std::string host;
  RunFolder folder{"run"};
  bool folder_ready = false;  // rank 0: the run folder exists (a report can be written)

  SetupParams params;
  std::string method = "brute";
  SceneGeometry geometry;
  std::vector<SpatialSample> samples;
  std::unique_ptr<EmbreeScene> embree;
  std::unique_ptr<TransportSampler> sampler;
  SparsePlan plan;  // method sparse: every rank has rank 0's plan
  std::unique_ptr<VisibilitySampler> visibility_sampler;  // the visibility job
  // Rank 0, the visibility job: the chunks of visibility.chunks that make up the result
  // (verified re-used ones and this run's), for the finalize phase.
  std::vector<VisibilityChunkRef> visibility_chunks;

  // Rank 0, method sparse or the visibility job: the journal's lines (verified when the phase
  // is planned).
  std::vector<JournalEntry> sparse_entries;

  // Rank 0 only.
  std::optional<TransportFileWriter> writer;
  std::unique_ptr<CheckpointJournal> journal;
  std::vector<JournalEntry> reused;
  FarmReport report;

  bool computes_here() const { return rank != 0 || size == 1 || options.coordinator_works; }
  int computing_ranks() const {
    return size - 1 + ((size == 1 || options.coordinator_works) ? 1 : 0);
  }
};

class FarmPhase {
 public:
  virtual ~FarmPhase() = default;
  virtual const char* name() const = 0;
  // Runs on every rank. Throws CollectiveStop when all ranks agreed to stop; any other
  // exception on a rank is fatal for the whole job.
  virtual void Run(FarmContext& ctx) = 0;
};

// Max-reduces every rank's status; if any is non-zero, every rank stops with it.
void AgreeOrStop(FarmContext& ctx, int local_status) {
  int status = local_status;
  CheckMpi(MPI_Allreduce(&local_status, &status, 1, MPI_INT, MPI_MAX, ctx.comm), "MPI_Allreduce");
  if (status != kExitOk) throw CollectiveStop{status};
}

void BroadcastBytes(FarmContext& ctx, std::string& bytes, uint64_t size) {
  bytes.resize(static_cast<std::size_t>(size));
  for (uint64_t at = 0; at < size; at += kMaxBroadcastBytes) {
    const auto n = static_cast<int>(std::min(kMaxBroadcastBytes, size - at));
    CheckMpi(MPI_Bcast(bytes.data() + at, n, MPI_BYTE, 0, ctx.comm), "MPI_Bcast geometry");
  }
}

// Computes one job on this rank: rows into `rows`, counters and checksum into the result.
ResultMsg ComputeJob(const FarmContext& ctx, const JobMsg& job, std::vector<float>& rows) {
  const uint64_t cols = ctx.sampler->layout().texel_count();
  rows.resize(static_cast<std::size_t>(job.count * cols));
  const double t0 = Now();
  const SampleStats stats = ctx.sampler->ComputeRows(
      std::span<const SpatialSample>(ctx.samples.data() + job.first, job.count), job.first,
      rows.data());
  ResultMsg r;
  r.busy_seconds = Now() - t0;
  r.first = job.first;
  r.count = job.count;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (!std::isfinite(rows[i])) {
      throw NumericalError("worker returned a non-finite value for sample " +
                           std::to_string(job.first + i / cols) + ", texel " +
                           std::to_string(i % cols));
    }
  }
  r.rows_checksum = Checksum64(rows.data(), rows.size() * sizeof(float));
  r.rays_traced = stats.rays_traced;
  r.texels_traced = stats.texels_traced;
  r.texels_below_horizon = stats.texels_below_horizon;
  r.rays_below_horizon = stats.rays_below_horizon;
  return r;
}

[[noreturn]] void InjectFailure(const FarmContext& ctx, int jobs) {
  if (ctx.options.fail_mode == "hang") {
    spdlog::warn("debug: rank {} hangs after {} jobs (--fail-after-jobs)", ctx.rank, jobs);
    for (;;) std::this_thread::sleep_for(std::chrono::seconds(3600));
  }
  spdlog::warn("debug: rank {} exits abruptly after {} jobs (--fail-after-jobs)", ctx.rank, jobs);
  spdlog::default_logger()->flush();
  std::_Exit(kExitRankFailed);
}

bool FailureDue(const FarmContext& ctx, int jobs) {
  return ctx.options.fail_after_jobs >= 0 && ctx.rank == ctx.options.fail_rank &&
         jobs >= ctx.options.fail_after_jobs;
}

// run/sparse/: the sparse method's durable side results (docs/farm.md, "Sparse method").
std::string SparseDir(const RunFolder& f) {
  return (fs::path(f.dir) / "sparse").string();
}

// --fail-after-jobs K on rank 0: when several finished jobs are committed together, journal only
// those up to the K-th, so that the kill lands after exactly K journaled jobs.
void KeepJobsBeforeFailure(const FarmContext& ctx, int jobs_so_far,
                           std::vector<JournalEntry>& pending) {
  if (ctx.options.fail_after_jobs < 0 || ctx.rank != ctx.options.fail_rank) return;
  const int left = std::max(0, ctx.options.fail_after_jobs - jobs_so_far);
  if (pending.size() > static_cast<std::size_t>(left))
    pending.resize(static_cast<std::size_t>(left));
}

// ------------------------------------------------------------------------------- setup phase

class SetupPhase : public FarmPhase {
 public:
  const char* name() const override { return "setup"; }

  void Run(FarmContext& ctx) override {
    std::string geometry_bytes;
    int status = kExitOk;
    if (ctx.rank == 0) {
      try {
        PrepareOnRank0(ctx, geometry_bytes);
      } catch (...) {
        std::string message;
        status = ExitCodeOf(std::current_exception(), message);
        spdlog::error("{}", message);
        ctx.report.error = message;
      }
    }
    CheckMpi(MPI_Bcast(&status, 1, MPI_INT, 0, ctx.comm), "MPI_Bcast status");
    if (status != kExitOk) throw CollectiveStop{status};
    CheckMpi(MPI_Bcast(&ctx.params, sizeof(SetupParams), MPI_BYTE, 0, ctx.comm), "MPI_Bcast");
    if (ctx.params.complete) return;  // a finished run: RunFarm stops after this phase
    if (ctx.params.sparse) {
      CheckMpi(MPI_Bcast(&ctx.plan, sizeof(SparsePlan), MPI_BYTE, 0, ctx.comm), "MPI_Bcast plan");
      ctx.method = "sparse";
    }
    if (ctx.params.visibility) ctx.method = kVisibilityPhaseName;
    BroadcastBytes(ctx, geometry_bytes, ctx.params.geometry_bytes);

    // Every rank, rank 0 included, samples the geometry decoded from the same bytes.
    int local = kExitOk;
    try {
      ctx.geometry = ParseSceneGeometry(geometry_bytes, kGeometryFileName);
      ctx.samples = SpatialSamplesOf(ctx.geometry);
      if (ctx.samples.size() != ctx.params.rows) {
        throw std::logic_error("sample count " + std::to_string(ctx.samples.size()) +
                               " differs from the geometry's vertex count " +
                               std::to_string(ctx.params.rows));
      }
      if (ctx.computes_here() && ctx.params.visibility) {
        ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        VisibilitySamplerOptions vo;
        vo.n = ctx.params.cubemap_n;
        vo.supersample = ctx.params.visibility_supersample;
        vo.bits = ctx.params.visibility_bits;
        ctx.visibility_sampler = std::make_unique<VisibilitySampler>(*ctx.embree, vo);
      } else if (ctx.computes_here()) {
        ctx.embree = std::make_unique<EmbreeScene>(ctx.geometry);
        TransportSamplerOptions so;
        so.rays_per_texel = ctx.params.rays_per_texel;
        so.seed = ctx.params.seed;
        ctx.sampler = std::make_unique<TransportSampler>(*ctx.embree, ctx.params.cubemap_n, so);
      }
    } catch (...) {
      std::string message;
      local = ExitCodeOf(std::current_exception(), message);
      spdlog::error("rank {}: {}", ctx.rank, message);
      if (ctx.rank == 0) ctx.report.error = message;
    }
    AgreeOrStop(ctx, local);
  }

 private:
  static void PrepareOnRank0(FarmContext& ctx, std::string& geometry_bytes) {
    const FarmOptions& o = ctx.options;
    std::vector<std::string> data_dirs = o.data_dirs;
    if (std::strlen(PRT_DEFAULT_DATA_DIR) > 0) data_dirs.emplace_back(PRT_DEFAULT_DATA_DIR);

    // 1. The scene (bad input: exit code 2).
    std::string scene_text;
    SceneDescription scene;
    if (o.scene_path.empty()) {
      scene_text = DefaultSceneText();
      scene = ParseScene(scene_text, kDefaultSceneName, "", data_dirs);
      ctx.report.scene = kDefaultSceneName;
    } else {
      std::error_code ec;
      if (!fs::is_regular_file(o.scene_path, ec)) {
        throw InputError(o.scene_path, fs::exists(o.scene_path, ec)
                                           ? "the scene is not a regular file"
                                           : "scene file not found");
      }
      scene_text = ReadWholeFile(o.scene_path);
      scene = LoadSceneFile(o.scene_path, data_dirs);
      ctx.report.scene = o.scene_path;
    }
    ctx.method = o.method.empty() ? scene.sampling.method : o.method;
    if (ctx.method != "brute" && ctx.method != "sparse") {
      throw InputError(scene.file, "unknown method '" + ctx.method + "' (brute or sparse)");
    }
    const std::string job = o.job.empty() ? scene.sampling.job : o.job;
    if (job != "transport" && job != "visibility") {
      throw InputError(scene.file, "unknown job '" + job + "' (transport or visibility)");
    }
    const bool visibility = job == "visibility";
    if (visibility) ctx.method = kVisibilityPhaseName;
    if (scene.samples != SpatialSamples::kVertices) {
      throw InputError(scene.file,
                       "samples = \"camera\" (image relighting) is not supported by prt-farm yet");
    }
    const VisibilitySettings& vis = scene.visibility;
    const int n = visibility ? vis.n : scene.cubemap_n;
    const int rays = visibility             ? vis.supersample * vis.supersample
                     : o.rays_per_texel > 0 ? o.rays_per_texel
                                            : scene.sampling.rays_per_texel;
    if (visibility) {
      spdlog::info("scene {} ('{}'): visibility cubemaps at n = {}, {} ray(s) per texel, {} bit(s)",
                   ctx.report.scene, scene.name, n, rays, vis.bits);
    } else {
      spdlog::info("scene {} ('{}'): n = {}, {} rays per texel, method {}", ctx.report.scene,
                   scene.name, n, rays, ctx.method);
    }
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    geometry_bytes = SerializeSceneGeometry(geometry);
    uint64_t rows = 0;
    for (const SceneMesh& m : geometry.meshes) rows += m.mesh.positions.size();
    if (rows == 0) throw InputError(scene.file, "the scene has no spatial samples");

    ctx.params.rows = rows;
    ctx.params.geometry_bytes = geometry_bytes.size();
    const uint64_t seed = o.seed ? *o.seed : scene.sampling.seed;
    ctx.params.seed = seed;
    ctx.params.cubemap_n = n;
    ctx.params.rays_per_texel = rays;
    if (visibility) {
      ctx.params.visibility = 1;
      ctx.params.visibility_supersample = vis.supersample;
      ctx.params.visibility_bits = vis.bits;
    } else if (ctx.method == "sparse") {
      ctx.params.sparse = 1;
      ctx.plan = PlanFromSettings(scene.sparse, geometry.diagonal(), scene.cubemap_n);
    }

    RunManifest manifest;
    manifest.method = ctx.method;
    manifest.cubemap_n = n;
    manifest.rays_per_texel = rays;
    if (visibility) manifest.visibility_bits = vis.bits;
    manifest.seed = seed;
    manifest.rows = rows;
    manifest.rows_per_block = o.rows_per_block;
    manifest.scene_checksum = Checksum64(scene_text.data(), scene_text.size());
    manifest.geometry_checksum = Checksum64(geometry_bytes.data(), geometry_bytes.size());

    FarmReport& rep = ctx.report;
    rep.scene_name = scene.name;
    rep.method = ctx.method;
    rep.cubemap_n = n;
    rep.rays_per_texel = rays;
    if (visibility) {
      rep.visibility.enabled = true;
      rep.visibility.n = n;
      rep.visibility.supersample = vis.supersample;
      rep.visibility.bits = vis.bits;
      rep.visibility.vertices = rows;
    }
    rep.seed = seed;
    rep.rows = rows;
    rep.rows_per_block = o.rows_per_block;

    // 2. The run folder (I/O errors: exit code 3).
    PrepareRunFolder(ctx, manifest, scene_text, geometry_bytes);
  }

  static void PrepareRunFolder(FarmContext& ctx, const RunManifest& manifest,
                               const std::string& scene_text, const std::string& geometry_bytes) {
    const FarmOptions& o = ctx.options;
    const RunFolder& f = ctx.folder;
    std::error_code ec;
    if (fs::exists(f.dir, ec) && !fs::is_directory(f.dir, ec)) {
      throw FileIoError(f.dir, "the output path exists and is not a folder");
    }
    fs::create_directories(f.checkpoints, ec);
    if (ec) throw FileIoError(f.checkpoints, "cannot create the run folder: " + ec.message());

    const std::string vis_final = (fs::path(f.dir) / kVisibilityFileName).string();
    const std::string vis_chunks = (fs::path(f.dir) / kVisibilityChunksFileName).string();
    const bool has_run = fs::exists(f.journal) || fs::exists(f.partial) ||
                         fs::exists(f.transport) || fs::exists(vis_final);
    bool fresh = true;
    if (o.resume && fs::exists(f.manifest)) {
      const RunManifest old = RunManifest::FromJsonText(ReadWholeFile(f.manifest), f.manifest);
      if (old.Key() != manifest.Key()) {
        throw InputError(f.manifest, "the checkpoints in " + f.dir +
                                         " belong to a different run (" +
                                         manifest.DifferencesFrom(old) +
                                         "); use --force to start over, or another --out");
      }
      fresh = false;
      // A finished transport run (the compression phase wrote transport.prtc and removed the raw
      // matrix): its inputs were checked just above, so the finished asset stays untouched.
      if (!ctx.params.visibility && !o.no_compress && !fs::exists(f.partial, ec) &&
          !fs::exists(f.transport, ec) && fs::exists(f.journal, ec) &&
          fs::exists(fs::path(f.dir) / kCompressedTransportFile, ec)) {
        ctx.params.complete = 1;
        if (!o.quiet) {
          std::fprintf(stderr,
                       "prt-farm: --resume: %s is complete (%s written, raw matrix removed) and "
                       "its inputs are unchanged; nothing to do (use --force to start over)\n",
                       f.dir.c_str(), kCompressedTransportFile);
        }
        return;
      }
    } else if (o.resume) {
      spdlog::info("--resume: {} holds no checkpoints yet; starting a fresh run", f.dir);
    } else if (has_run && !o.force) {
      throw UsageError(f.dir +
                       " already holds a prt-farm run; pass --resume to continue it or "
                       "--force to start over");
    }

    const TransportFileInfo info{manifest.rows, static_cast<uint32_t>(manifest.cubemap_n),
                                 manifest.rows_per_block,
                                 static_cast<uint32_t>(manifest.rays_per_texel), manifest.seed};
    if (fresh) {
      for (const std::string& p :
           {f.transport, f.partial, f.journal, f.manifest, f.report, vis_final, vis_chunks}) {
        fs::remove(p, ec);
      }
      fs::remove_all(SparseDir(f), ec);
    }
    // The compressed transport of an earlier run (compression_phase.h) goes only now, once the
    // scene and settings are valid: a --force with a bad scene must not lose a finished run.
    if (fresh) fs::remove(fs::path(f.dir) / "transport.prtc", ec);
    // From here on the folder is this run's: a failure report may replace an older report.
    ctx.folder_ready = true;
    WriteFileDurably(f.scene_copy, scene_text);
    WriteFileDurably(f.geometry, geometry_bytes);
    WriteFileDurably(f.manifest, manifest.ToJsonText());

    std::vector<JournalEntry> reused;
    if (!fresh && ctx.params.visibility) {
      // The chunks are verified against visibility.chunks by the visibility phase.
      const JournalContents journal = ReadJournal(f.journal);
      if (journal.has_header && journal.run_key != manifest.Key()) {
        throw InputError(f.journal, "journal of a different run; use --force to start over");
      }
      ctx.report.damaged_journal_lines = journal.damaged_lines;
      for (const JournalEntry& e : journal.entries) {
        if (e.phase == kVisibilityPhaseName) ctx.sparse_entries.push_back(e);
      }
      fs::remove(vis_final, ec);  // written again by the finalize phase
    } else if (!fresh) {
      if (!fs::exists(f.partial) && fs::exists(f.transport)) {
        // A finished run: its rows are re-verified and re-used, the file finalized again.
        fs::rename(f.transport, f.partial);
        SyncDirectory(f.dir);
      }
      if (fs::exists(f.partial)) {
        ctx.writer.emplace(TransportFileWriter::Reopen(f.partial, info));
        const JournalContents journal = ReadJournal(f.journal);
        if (journal.has_header && journal.run_key != manifest.Key()) {
          throw InputError(f.journal, "journal of a different run; use --force to start over");
        }
        ctx.report.damaged_journal_lines = journal.damaged_lines;
        if (journal.damaged_lines > 0) {
          spdlog::warn("{}: {} damaged or torn journal line(s) ignored (those jobs are redone)",
                       f.journal, journal.damaged_lines);
        }
        std::vector<float> rows;
        for (const JournalEntry& e : journal.entries) {
          if (ctx.params.sparse) {
            // Verified against the files when its phase is planned (SparseSamplingPhase).
            if (!e.phase.empty()) ctx.sparse_entries.push_back(e);
            continue;
          }
          if (e.rows.end() > info.rows || e.rows.count * info.row_bytes() > kMaxJobBytes * 4) {
            ++ctx.report.checkpoints_rejected;
            continue;
          }
          rows.resize(static_cast<std::size_t>(e.rows.count * info.cols()));
          ctx.writer->ReadRows(e.rows.first, e.rows.count, rows.data());
          if (Checksum64(rows.data(), rows.size() * sizeof(float)) == e.rows_checksum) {
            reused.push_back(e);
          } else {
            ++ctx.report.checkpoints_rejected;
          }
        }
        if (ctx.report.checkpoints_rejected > 0) {
          spdlog::warn("{} journaled job(s) did not verify against {} and are redone",
                       ctx.report.checkpoints_rejected, f.partial);
        }
      } else {
        spdlog::warn("--resume: {} is missing; every job is redone", f.partial);
      }
    }
    if (!ctx.writer && !ctx.params.visibility) {
      ctx.writer.emplace(TransportFileWriter::Create(f.partial, info));
    }
    ctx.journal = std::make_unique<CheckpointJournal>(
        f.journal, manifest.Key(),
        ctx.params.sparse || ctx.params.visibility ? ctx.sparse_entries : reused);
    ctx.reused = std::move(reused);
    if (!fresh && ctx.params.visibility) {
      spdlog::info("--resume: {} journaled visibility job(s) are verified against {}",
                   ctx.sparse_entries.size(), vis_chunks);
    } else if (!fresh && ctx.params.sparse) {
      spdlog::info("--resume: {} journaled sparse job(s) are verified phase by phase",
                   ctx.sparse_entries.size());
    } else if (!fresh) {
      uint64_t rows_reused = 0;
      for (const JournalEntry& e : ctx.reused) rows_reused += e.rows.count;
      spdlog::info("--resume: {} finished job(s) ({} of {} samples) re-used from checkpoints",
                   ctx.reused.size(), rows_reused, manifest.rows);
    }
  }
};

// ----------------------------------------------------------------------- brute sampling phase

// Rank 0's own worker thread (when rank 0 computes): takes one job at a time from the
// coordinator's main thread, which alone calls MPI, runs `compute(job, result)` on it (an
// exception is carried in result.error) and queues the result. Result needs an
// `std::exception_ptr error` member.
template <class Job, class Result>
class LocalWorker {
 public:
  using Compute = std::function<void(Job&, Result&)>;

  explicit LocalWorker(Compute compute)
      : compute_(std::move(compute)), thread_([this] { Loop(); }) {}
  ~LocalWorker() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

  // Queues a job (the worker takes them in order).
  void Give(Job job) {
    {
      std::lock_guard lock(mutex_);
      jobs_.push_back(std::move(job));
    }
    cv_.notify_all();
  }
  std::optional<Result> Poll() {
    std::lock_guard lock(mutex_);
    if (results_.empty()) return std::nullopt;
    Result r = std::move(results_.front());
    results_.pop_front();
    return r;
  }
  // Sleeps until a result arrives or `seconds` pass.
  void Wait(double seconds) {
    std::unique_lock lock(mutex_);
    cv_done_.wait_for(lock, std::chrono::duration<double>(seconds),
                      [&] { return !results_.empty(); });
  }

 private:
  void Loop() {
    for (;;) {
      Job job;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      Result r;
      try {
        compute_(job, r);
      } catch (...) {
        r.error = std::current_exception();
      }
      {
        std::lock_guard lock(mutex_);
        results_.push_back(std::move(r));
      }
      cv_done_.notify_all();
    }
  }

  Compute compute_;
  std::mutex mutex_;
  std::condition_variable cv_, cv_done_;
  std::deque<Job> jobs_;
  std::deque<Result> results_;
  bool stop_ = false;
  std::thread thread_;  // last: starts after every other member exists
};

// ----------------------------------------------------------------------- brute sampling phase

struct BruteLocalResult {
  ResultMsg msg;
  std::vector<float> rows;
  std::exception_ptr error;
};
using BruteLocalWorker = LocalWorker<JobMsg, BruteLocalResult>;

class BruteSamplingPhase : public FarmPhase {
 public:
  const char* name() const override { return "brute"; }

  void Run(FarmContext& ctx) override {
    if (ctx.rank == 0) {
      RunCoordinator(ctx);
    } else {
      RunWorker(ctx);
    }
  }

 private:
  static uint64_t RowsPerMessage(uint64_t cols) {
    return std::max<uint64_t>(1, kMaxMessageBytes / (cols * sizeof(float)));
  }

  // ---- a worker rank (1..N−1)
  static void RunWorker(FarmContext& ctx) {
    ReadyMsg ready;
    ready.threads = ctx.threads;
    std::snprintf(ready.host, sizeof ready.host, "%s", ctx.host.c_str());
    CheckMpi(MPI_Send(&ready, sizeof ready, MPI_BYTE, 0, kTagReady, ctx.comm), "MPI_Send ready");
    const uint64_t cols = ctx.sampler->layout().texel_count();
    std::vector<float> rows;
    int jobs = 0;
    for (;;) {
      MPI_Status st;
      CheckMpi(ProbeFromRankZero(ctx.comm, &st), "MPI_Iprobe from rank 0");
      if (st.MPI_TAG == kTagStop) {
        CheckMpi(MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE),
                 "MPI_Recv stop");
        return;
      }
      JobMsg job;
      CheckMpi(MPI_Recv(&job, sizeof job, MPI_BYTE, 0, kTagJob, ctx.comm, MPI_STATUS_IGNORE),
               "MPI_Recv job");
      if (FailureDue(ctx, jobs)) InjectFailure(ctx, jobs);
      ResultMsg result;
      try {
        result = ComputeJob(ctx, job, rows);
      } catch (const std::exception& e) {
        // Tell rank 0 (which writes the report and aborts the job), then wait to be killed.
        const std::string message = e.what();
        spdlog::error("rank {}: {}", ctx.rank, message);
        MPI_Send(message.data(), static_cast<int>(message.size()), MPI_CHAR, 0, kTagFailed,
                 ctx.comm);
        MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE);
        throw CollectiveStop{kExitRankFailed};
      }
      CheckMpi(MPI_Send(&result, sizeof result, MPI_BYTE, 0, kTagResult, ctx.comm),
               "MPI_Send result");
      const uint64_t per_message = RowsPerMessage(cols);
      for (uint64_t at = 0; at < job.count; at += per_message) {
        const uint64_t n = std::min(per_message, job.count - at);
        CheckMpi(MPI_Send(rows.data() + at * cols, static_cast<int>(n * cols), MPI_FLOAT, 0,
                          kTagRows, ctx.comm),
                 "MPI_Send rows");
      }
      ++jobs;
    }
  }

  // ---- rank 0
  struct Slot {
    int rank = 0;
    bool local = false;
    bool ready = false;  // remote: its READY arrived
    bool stopped = false;
    std::optional<JobMsg> job;
    double since = 0;  // when the job (or the wait for READY) started
  };

  static void RunCoordinator(FarmContext& ctx) {
    const uint64_t total = ctx.params.rows;
    const uint64_t cols = 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n;
    const uint64_t row_bytes = cols * sizeof(float);
    FarmReport& rep = ctx.report;

    std::vector<RowRange> done;
    for (const JournalEntry& e : ctx.reused) {
      done.push_back(e.rows);
      rep.rows_reused += e.rows.count;
      rep.rays_traced_all += e.rays_traced;
      rep.texels_below_horizon_all += e.texels_below_horizon;
    }
    rep.jobs_reused = ctx.reused.size();

    JobSizing sizing;
    sizing.job_seconds = ctx.options.job_seconds;
    sizing.workers = ctx.computing_ranks();
    sizing.max_rows = ctx.options.max_job_rows > 0
                          ? ctx.options.max_job_rows
                          : std::max<uint64_t>(1, kMaxJobBytes / row_bytes);
    sizing.initial_rows = ctx.options.initial_job_rows > 0 ? ctx.options.initial_job_rows
                                                           : 4 * static_cast<uint64_t>(ctx.threads);
    JobPlanner planner(total, done, sizing);

    ProgressOptions po;
    po.unit = "samples";
    po.rate_unit = "rays";
    po.log_interval_s = ctx.options.log_interval_s;
    po.log = !ctx.options.quiet;
    po.already_done = planner.done_before_rows();
    Progress progress(ctx.method, total, po);

    const double timeout = ctx.options.rank_timeout_s > 0
                               ? ctx.options.rank_timeout_s
                               : std::max(300.0, 50.0 * ctx.options.job_seconds);
    const double start = Now();
    std::vector<Slot> slots;
    for (int r = 1; r < ctx.size; ++r) slots.push_back({r, false, false, false, {}, start});
    std::unique_ptr<BruteLocalWorker> local;
    if (ctx.computes_here()) {
      slots.push_back({0, true, true, false, {}, start});
      local = std::make_unique<BruteLocalWorker>(
          [&ctx](JobMsg& job, BruteLocalResult& r) { r.msg = ComputeJob(ctx, job, r.rows); });
    }
    auto slot_of = [&](int rank) -> Slot& {
      for (Slot& s : slots) {
        if (s.rank == rank) return s;
      }
      throw std::logic_error("no slot for rank " + std::to_string(rank));
    };
    rep.rank_reports[0].threads = ctx.threads;
    rep.rank_reports[0].host = ctx.host;
    rep.rank_reports[0].computes = ctx.computes_here();

    std::vector<JournalEntry> pending;
    std::vector<float> rows;
    int jobs_this_run = 0;

    // A finished job: rows into the file now, counted once the journal has it (Commit).
    auto accept = [&](int rank, const ResultMsg& m, const float* data) {
      Slot& s = slot_of(rank);
      if (!s.job || s.job->first != m.first || s.job->count != m.count) {
        throw RankFailure("rank " + std::to_string(rank) + " returned rows " +
                          std::to_string(m.first) + "+" + std::to_string(m.count) +
                          " it was not given");
      }
      if (Checksum64(data, m.count * row_bytes) != m.rows_checksum) {
        throw RankFailure("rows from rank " + std::to_string(rank) +
                          " arrived damaged (checksum mismatch)");
      }
      ctx.writer->WriteRows(m.first, m.count, data);
      JournalEntry e;
      e.rows = {m.first, m.count};
      e.rows_checksum = m.rows_checksum;
      e.rank = rank;
      e.rays_traced = m.rays_traced;
      e.texels_traced = m.texels_traced;
      e.texels_below_horizon = m.texels_below_horizon;
      e.rays_below_horizon = m.rays_below_horizon;
      e.busy_seconds = m.busy_seconds;
      pending.push_back(e);
      planner.Measured(rank, m.count, m.busy_seconds);
      s.job.reset();
    };

    auto commit = [&] {
      if (pending.empty()) return;
      KeepJobsBeforeFailure(ctx, jobs_this_run, pending);
      ctx.writer->Sync();            // rows durable first,
      ctx.journal->Append(pending);  // then the journal line that counts them
      for (const JournalEntry& e : pending) {
        RankReport& rr = rep.rank_reports[e.rank];
        ++rr.jobs;
        rr.rows += e.rows.count;
        rr.rays_traced += e.rays_traced;
        rr.busy_seconds += e.busy_seconds;
        ++rep.jobs_done;
        rep.rows_done += e.rows.count;
        rep.rays_traced += e.rays_traced;
        rep.texels_traced += e.texels_traced;
        rep.texels_below_horizon += e.texels_below_horizon;
        rep.rays_below_horizon += e.rays_below_horizon;
        rep.rays_traced_all += e.rays_traced;
        rep.texels_below_horizon_all += e.texels_below_horizon;
        progress.Advance(e.rows.count, e.rays_traced);
        ++jobs_this_run;
      }
      pending.clear();
      if (FailureDue(ctx, jobs_this_run)) InjectFailure(ctx, jobs_this_run);
    };

    if (FailureDue(ctx, 0)) InjectFailure(ctx, 0);
    for (;;) {
      // Hand out work to every idle rank; stop the ranks there is no work left for.
      for (Slot& s : slots) {
        if (s.stopped || s.job || !s.ready) continue;
        const std::optional<RowRange> next = planner.Next(s.rank);
        if (next) {
          s.job = JobMsg{next->first, next->count};
          s.since = Now();
          if (s.local) {
            local->Give(*s.job);
          } else {
            CheckMpi(MPI_Send(&*s.job, sizeof(JobMsg), MPI_BYTE, s.rank, kTagJob, ctx.comm),
                     "MPI_Send job to rank " + std::to_string(s.rank));
          }
        } else {
          s.stopped = true;
          if (!s.local) {
            CheckMpi(MPI_Send(nullptr, 0, MPI_BYTE, s.rank, kTagStop, ctx.comm),
                     "MPI_Send stop to rank " + std::to_string(s.rank));
          }
        }
      }
      if (std::all_of(slots.begin(), slots.end(), [](const Slot& s) { return s.stopped; }) &&
          pending.empty()) {
        break;
      }

      bool busy = false;
      if (local) {
        while (std::optional<BruteLocalResult> r = local->Poll()) {
          if (r->error) std::rethrow_exception(r->error);
          accept(0, r->msg, r->rows.data());
          busy = true;
        }
      }
      for (;;) {
        int flag = 0;
        MPI_Status st;
        CheckMpi(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, ctx.comm, &flag, &st), "MPI_Iprobe");
        if (!flag) break;
        busy = true;
        const int src = st.MPI_SOURCE;
        if (st.MPI_TAG == kTagReady) {
          ReadyMsg ready;
          CheckMpi(
              MPI_Recv(&ready, sizeof ready, MPI_BYTE, src, kTagReady, ctx.comm, MPI_STATUS_IGNORE),
              "MPI_Recv ready");
          ready.host[sizeof ready.host - 1] = '\0';
          rep.rank_reports[src].threads = ready.threads;
          rep.rank_reports[src].host = ready.host;
          slot_of(src).ready = true;
        } else if (st.MPI_TAG == kTagResult) {
          ResultMsg m;
          CheckMpi(MPI_Recv(&m, sizeof m, MPI_BYTE, src, kTagResult, ctx.comm, MPI_STATUS_IGNORE),
                   "MPI_Recv result from rank " + std::to_string(src));
          if (m.count > sizing.max_rows) {
            throw RankFailure("rank " + std::to_string(src) + " announced an oversized result");
          }
          rows.resize(static_cast<std::size_t>(m.count * cols));
          const uint64_t per_message = RowsPerMessage(cols);
          for (uint64_t at = 0; at < m.count; at += per_message) {
            const uint64_t n = std::min(per_message, m.count - at);
            CheckMpi(MPI_Recv(rows.data() + at * cols, static_cast<int>(n * cols), MPI_FLOAT, src,
                              kTagRows, ctx.comm, MPI_STATUS_IGNORE),
                     "MPI_Recv rows from rank " + std::to_string(src));
          }
          accept(src, m, rows.data());
        } else if (st.MPI_TAG == kTagFailed) {
          int len = 0;
          MPI_Get_count(&st, MPI_CHAR, &len);
          std::string message(static_cast<std::size_t>(std::max(0, len)), '\0');
          MPI_Recv(message.data(), len, MPI_CHAR, src, kTagFailed, ctx.comm, MPI_STATUS_IGNORE);
          throw RankFailure("rank " + std::to_string(src) + " failed: " + message);
        } else {
          throw RankFailure("unexpected message tag " + std::to_string(st.MPI_TAG) + " from rank " +
                            std::to_string(src));
        }
      }
      commit();

      // A rank that neither answers nor dies (mpirun aborts the job when one dies) must not
      // keep rank 0 waiting forever.
      const double now = Now();
      for (const Slot& s : slots) {
        if (s.stopped || (s.ready && !s.job) || now - s.since <= timeout) continue;
        throw RankFailure("rank " + std::to_string(s.rank) +
                          (s.job ? " has not returned its job (samples " +
                                       std::to_string(s.job->first) + ".." +
                                       std::to_string(s.job->first + s.job->count - 1) + ")"
                                 : std::string(" never reported ready")) +
                          " for " + std::to_string(static_cast<int>(now - s.since)) +
                          " s (--rank-timeout); giving up");
      }
      progress.Advance(0);
      if (!busy) {
        if (local) {
          local->Wait(0.001);
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    }
    progress.Finish();
    rep.jobs_total = rep.jobs_done + rep.jobs_reused;
  }
};

// ---------------------------------------------------------------------- sparse sampling phase

// pwrite/pread/fdatasync on a side file of the run folder; FileIoError names the file.
class SideFile {
 public:
  explicit SideFile(std::string path) : path_(std::move(path)) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw FileIoError(path_, std::string("cannot open: ") + std::strerror(errno));
  }
  ~SideFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  SideFile(const SideFile&) = delete;
  SideFile& operator=(const SideFile&) = delete;

  void Write(const void* data, std::size_t bytes, uint64_t offset) {
    const char* p = static_cast<const char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pwrite(fd_, p, bytes, static_cast<off_t>(offset));
      if (n < 0) {
        if (errno == EINTR) continue;
        throw FileIoError(path_, std::string("write failed: ") + std::strerror(errno));
      }
      p += n;
      bytes -= static_cast<std::size_t>(n);
      offset += static_cast<uint64_t>(n);
    }
    dirty_ = true;
  }
  // False when the file ends before offset + bytes.
  bool Read(void* data, std::size_t bytes, uint64_t offset) const {
    char* p = static_cast<char*>(data);
    while (bytes > 0) {
      const ssize_t n = ::pread(fd_, p, bytes, static_cast<off_t>(offset));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) throw FileIoError(path_, std::string("read failed: ") + std::strerror(errno));
      if (n == 0) return false;
      p += n;
      bytes -= static_cast<std::size_t>(n);
      offset += static_cast<uint64_t>(n);
    }
    return true;
  }
  void Sync() {
    if (!dirty_) return;
    if (::fdatasync(fd_) != 0)
      throw FileIoError(path_, std::string("fdatasync failed: ") + std::strerror(errno));
    dirty_ = false;
  }

 private:
  std::string path_;
  int fd_ = -1;
  bool dirty_ = false;
};

// Rank 0's own worker thread for the sparse method: serialised jobs in, serialised results out.
struct SparseLocalResult {
  std::string bytes;
  std::exception_ptr error;
};
using SparseLocalWorker = LocalWorker<std::string, SparseLocalResult>;

// The sparse method (Huang & Ramamoorthi 2010 §4–5) on the job queue; docs/farm.md, "Sparse
// method". Rank 0 plans every sub-phase deterministically from the seed and the previous
// sub-phases' durable results, exactly as RunSparsePrecomputation does in one process, so the
// transport file is bit-identical to it for any number of ranks and after any resume:
//   dense-initial   InitialDenseSet                          jobs: chunks of sample ids
//   rank-k          candidates of round k (NeighborIndex over the dense positions, built once)
//                                                            jobs: chunks of candidates
//   dense-rank-k    WeightedSampleWithoutReplacement(weight = rank), on rank 0 only
//   sparse-reconstruct  non-dense samples in Morton order     jobs: chunks of that order
//   dense-fallback  the vertices whose reconstruction fell back
// Dense T rows and reconstructed rows go into transport.prtt.partial as they arrive; dense
// visibility and feature rows into run/sparse/dense_aux.bin (5·texels bytes per sample, at the
// sample's offset: a sparse file), candidate weights into run/sparse/rank-k.bin (int32 per
// candidate), sparse outcomes into run/sparse/sparse_outcome.bin (a byte per Morton position).
// Every job is journaled after its results are durable ("sjob <phase> …").
class SparseSamplingPhase : public FarmPhase {
 public:
  const char* name() const override { return "sparse"; }

  void Run(FarmContext& ctx) override {
    if (ctx.rank == 0) {
      Coordinator(ctx).Run();
    } else {
      RunWorker(ctx);
    }
  }

 private:
  static void RunWorker(FarmContext& ctx) {
    ReadyMsg ready;
    ready.threads = ctx.threads;
    std::snprintf(ready.host, sizeof ready.host, "%s", ctx.host.c_str());
    CheckMpi(MPI_Send(&ready, sizeof ready, MPI_BYTE, 0, kTagReady, ctx.comm), "MPI_Send ready");
    int jobs = 0;
    std::string job;
    BackgroundSends sending;  // results on their way
    for (;;) {
      sending.Retire();
      MPI_Status st;
      CheckMpi(ProbeFromRankZero(ctx.comm, &st), "MPI_Iprobe from rank 0");
      if (st.MPI_TAG == kTagStop) {
        // Rank 0 stops a worker only once it has every result, so these have left.
        sending.WaitAll();
        CheckMpi(MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE),
                 "MPI_Recv stop");
        return;
      }
      int len = 0;
      MPI_Get_count(&st, MPI_BYTE, &len);
      job.resize(static_cast<std::size_t>(std::max(0, len)));
      CheckMpi(MPI_Recv(job.data(), len, MPI_BYTE, 0, kTagSparseJob, ctx.comm, MPI_STATUS_IGNORE),
               "MPI_Recv sparse job");
      if (FailureDue(ctx, jobs)) InjectFailure(ctx, jobs);
      std::string result;
      try {
        result = ComputeSparseJob(*ctx.sampler, ctx.samples, ctx.plan, job);
      } catch (const std::exception& e) {
        const std::string message = e.what();
        spdlog::error("rank {}: {}", ctx.rank, message);
        MPI_Send(message.data(), static_cast<int>(message.size()), MPI_CHAR, 0, kTagFailed,
                 ctx.comm);
        MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE);
        throw CollectiveStop{kExitRankFailed};
      }
      // Sent in the background while the next job is received and computed: a blocking send
      // of a large result spins until rank 0 gets round to receiving it, on a core rank 0's
      // threads may need.
      sending.Send(std::move(result), 0, kTagSparseResult, ctx.comm, "MPI_Isend sparse result");
      ++jobs;
    }
  }

  struct Slot {
    int rank = 0;
    bool local = false;
    bool ready = false;
    std::deque<SparseJobHeader> jobs;  // given to the rank and not returned, oldest first
    double since = 0;                  // when the oldest began (or the slot opened)
    BackgroundSends sends;             // remote ranks: the encoded jobs on their way
  };
  // Jobs a rank holds at once: the one it computes and the next, encoded and sent while it
  // computes, so that it never waits for rank 0 to read its neighbours' rows (a 2-rank run's
  // sparse-reconstruct workers were idle 45 % of the time; docs/farm.md).
  static constexpr std::size_t kJobsAhead = 2;

  // One sub-phase's jobs: items [0, items) of a deterministic list, cut by a JobPlanner.
  struct PhaseJobs {
    std::string name;
    SparseJobKind kind = SparseJobKind::kDense;
    uint64_t items = 0;
    std::string unit = "samples";
    uint64_t max_items = 0;  // per job (0: the default sizing)
    // Verifies a journaled job against the files and applies it to rank 0's state.
    std::function<bool(const JournalEntry&)> reuse;
    // Encodes the job for items [h.first, h.first + h.count); may lower h.count (too many bytes).
    std::function<std::string(SparseJobHeader&)> make_job;
    // Writes a result into the files and rank 0's state; returns its durable checksum and
    // the number of transport rows it wrote.
    std::function<uint64_t(const SparseJobResult&, uint64_t& rows_written)> accept;
    std::function<void()> sync;  // makes what accept wrote durable
  };

  class Coordinator {
   public:
    explicit Coordinator(FarmContext& ctx)
        : ctx_(ctx),
          N_(ctx.samples.size()),
          T_(6ull * ctx.params.cubemap_n * ctx.params.cubemap_n),
          n_(ctx.params.cubemap_n),
          m_(SparseRankResolution(ctx.plan, ctx.params.cubemap_n)),
          Tm_(static_cast<std::size_t>(6) * m_ * m_) {}

    void Run() {
      FarmReport& rep = ctx_.report;
      rep.sparse.enabled = true;
      fs::create_directories(SparseDir(ctx_.folder));
      aux_ =
          std::make_unique<SideFile>((fs::path(SparseDir(ctx_.folder)) / "dense_aux.bin").string());
      timeout_ = ctx_.options.rank_timeout_s > 0 ? ctx_.options.rank_timeout_s
                                                 : std::max(300.0, 50.0 * ctx_.options.job_seconds);
      const double start = Now();
      for (int r = 1; r < ctx_.size; ++r) slots_.push_back({r, false, false, {}, start, {}});
      if (ctx_.computes_here()) {
        slots_.push_back({0, true, true, {}, start, {}});
        local_ =
            std::make_unique<SparseLocalWorker>([this](std::string& job, SparseLocalResult& r) {
              r.bytes = ComputeSparseJob(*ctx_.sampler, ctx_.samples, ctx_.plan, job);
            });
      }
      rep.rank_reports[0].threads = ctx_.threads;
      rep.rank_reports[0].host = ctx_.host;
      rep.rank_reports[0].computes = ctx_.computes_here();
      is_dense_.assign(N_, 0);
      low_.assign(N_, {});
      if (FailureDue(ctx_, 0)) InjectFailure(ctx_, 0);

      // §4.1: the initial random dense set, then rank-weighted rounds.
      const std::size_t budget = SparseDenseBudget(N_, ctx_.plan);
      std::vector<uint32_t> dense =
          InitialDenseSet(N_, SparseInitialDenseCount(N_, ctx_.plan), ctx_.plan.seed);
      rep.sparse.dense_initial = dense.size();
      DensePhase("dense-initial", dense);
      const int rounds = SparseRounds(ctx_.plan);
      for (int it = 0; it < rounds && dense.size() < budget; ++it) {
        const std::size_t picks = SparsePicksForRound(budget, dense.size(), rounds, it);
        const std::vector<uint32_t> cand = SparseRankCandidates(is_dense_, picks, ctx_.plan, it);
        const std::vector<double> weight = RankPhase(it, dense, cand);
        const std::vector<uint32_t> next = SparsePickByRank(cand, weight, picks, ctx_.plan, it);
        rep.sparse.candidates_ranked += cand.size();
        rep.sparse.dense_by_rank += next.size();
        DensePhase("dense-rank-" + std::to_string(it + 1), next);
        dense.insert(dense.end(), next.begin(), next.end());
      }

      // §5: every other vertex from its dense neighbours; fallbacks become dense.
      std::sort(dense.begin(), dense.end());
      const std::vector<uint32_t> fallback = SparsePhase(dense);
      rep.sparse.dense_fallback = fallback.size();
      DensePhase("dense-fallback", fallback);

      // Release the workers (drain the READY of a worker that never got a job).
      for (Slot& s : slots_) {
        if (s.local) continue;
        if (!s.ready) {
          ReadyMsg ready;
          CheckMpi(MPI_Recv(&ready, sizeof ready, MPI_BYTE, s.rank, kTagReady, ctx_.comm,
                            MPI_STATUS_IGNORE),
                   "MPI_Recv ready");
          ready.host[sizeof ready.host - 1] = '\0';
          rep.rank_reports[s.rank].threads = ready.threads;
          rep.rank_reports[s.rank].host = ready.host;
        }
        CheckMpi(MPI_Send(nullptr, 0, MPI_BYTE, s.rank, kTagStop, ctx_.comm),
                 "MPI_Send stop to rank " + std::to_string(s.rank));
      }
      local_.reset();
      rep.jobs_total = rep.jobs_done + rep.jobs_reused;
    }

   private:
    // ---- dense rows (§4.2): T into the transport file, visibility + features into dense_aux.bin
    void DensePhase(const std::string& name, const std::vector<uint32_t>& ids) {
      PhaseJobs p;
      p.name = name;
      p.kind = SparseJobKind::kDense;
      p.items = ids.size();
      const uint64_t aux_row = 5 * T_;
      auto apply = [&](uint32_t s, const float* row) {
        is_dense_[s] = 1;
        low_[s].resize(Tm_);
        DownsampleRow(row, n_, m_, low_[s].data());
      };
      p.reuse = [&, aux_row](const JournalEntry& e) {
        const std::size_t c = static_cast<std::size_t>(e.rows.count);
        std::vector<float> tr(c * T_), vis(c * T_);
        std::vector<uint8_t> feat(c * T_);
        std::vector<char> buf(aux_row);
        for (std::size_t i = 0; i < c; ++i) {
          const uint32_t s = ids[e.rows.first + i];
          ctx_.writer->ReadRows(s, 1, tr.data() + i * T_);
          if (!aux_->Read(buf.data(), aux_row, s * aux_row)) return false;
          std::memcpy(vis.data() + i * T_, buf.data(), T_ * sizeof(float));
          std::memcpy(feat.data() + i * T_, buf.data() + T_ * sizeof(float), T_);
        }
        if (DenseResultChecksum(c, T_, tr.data(), vis.data(), feat.data()) != e.rows_checksum)
          return false;
        for (std::size_t i = 0; i < c; ++i) apply(ids[e.rows.first + i], tr.data() + i * T_);
        return true;
      };
      p.make_job = [&](SparseJobHeader& h) {
        DenseJob job;
        job.ids.assign(ids.begin() + static_cast<std::ptrdiff_t>(h.first),
                       ids.begin() + static_cast<std::ptrdiff_t>(h.first + h.count));
        return EncodeDenseJob(h, job);
      };
      p.accept = [&, aux_row](const SparseJobResult& r, uint64_t& rows_written) {
        const std::size_t c = static_cast<std::size_t>(r.header.count);
        if (r.transport.size() != c * T_ || r.visibility.size() != c * T_ ||
            r.feature.size() != c * T_)
          throw RankFailure("a dense job came back with the wrong number of rows");
        std::vector<char> buf(aux_row);
        for (std::size_t i = 0; i < c; ++i) {
          const uint32_t s = ids[r.header.first + i];
          ctx_.writer->WriteRows(s, 1, r.transport.data() + i * T_);
          std::memcpy(buf.data(), r.visibility.data() + i * T_, T_ * sizeof(float));
          std::memcpy(buf.data() + T_ * sizeof(float), r.feature.data() + i * T_, T_);
          aux_->Write(buf.data(), aux_row, s * aux_row);
          apply(s, r.transport.data() + i * T_);
        }
        rows_written = c;
        return DenseResultChecksum(c, T_, r.transport.data(), r.visibility.data(),
                                   r.feature.data());
      };
      p.sync = [&] {
        ctx_.writer->Sync();
        aux_->Sync();
      };
      RunJobs(p);
    }

    // ---- local rank of candidates (§4.1)
    std::vector<double> RankPhase(int it, const std::vector<uint32_t>& dense,
                                  const std::vector<uint32_t>& cand) {
      const double t0 = Now();
      // Built once per phase over the dense positions, in the order the reference uses.
      std::vector<Vec3> pts;
      pts.reserve(dense.size());
      for (uint32_t d : dense) pts.push_back(ctx_.samples[d].position);
      const NeighborIndex index(pts, dense);
      index_seconds_ += Now() - t0;
      SideFile file((fs::path(SparseDir(ctx_.folder)) / ("rank-" + std::to_string(it + 1) + ".bin"))
                        .string());
      std::vector<double> weight(cand.size(), 0.0);
      PhaseJobs p;
      p.name = "rank-" + std::to_string(it + 1);
      p.kind = SparseJobKind::kRank;
      p.items = cand.size();
      p.unit = "candidates";
      p.reuse = [&](const JournalEntry& e) {
        std::vector<int32_t> w(static_cast<std::size_t>(e.rows.count));
        if (!file.Read(w.data(), w.size() * sizeof(int32_t), e.rows.first * sizeof(int32_t)) ||
            Checksum64(w.data(), w.size() * sizeof(int32_t)) != e.rows_checksum)
          return false;
        for (std::size_t i = 0; i < w.size(); ++i) weight[e.rows.first + i] = w[i];
        return true;
      };
      p.make_job = [&](SparseJobHeader& h) {
        RankJob job;
        job.low_dim = static_cast<uint32_t>(Tm_);
        std::unordered_map<uint32_t, uint32_t> local;
        job.offsets.push_back(0);
        for (uint64_t i = h.first; i < h.first + h.count; ++i) {
          for (uint32_t d : index.RadiusSearch(ctx_.samples[cand[i]].position, ctx_.plan.radius,
                                               ctx_.plan.max_neighbors)) {
            auto [at, added] = local.emplace(d, static_cast<uint32_t>(local.size()));
            if (added) job.low_rows.insert(job.low_rows.end(), low_[d].begin(), low_[d].end());
            job.neighbors.push_back(at->second);
          }
          job.offsets.push_back(static_cast<uint32_t>(job.neighbors.size()));
        }
        return EncodeRankJob(h, job);
      };
      p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
        if (r.weights.size() != r.header.count)
          throw RankFailure("a rank job came back with the wrong number of weights");
        file.Write(r.weights.data(), r.weights.size() * sizeof(int32_t),
                   r.header.first * sizeof(int32_t));
        for (std::size_t i = 0; i < r.weights.size(); ++i)
          weight[r.header.first + i] = r.weights[i];
        rows_written = 0;
        return Checksum64(r.weights.data(), r.weights.size() * sizeof(int32_t));
      };
      p.sync = [&] { file.Sync(); };
      RunJobs(p, t0);
      return weight;
    }

    // ---- sparse vertices (§5); returns the fallbacks, sorted
    std::vector<uint32_t> SparsePhase(const std::vector<uint32_t>& dense) {
      const double t0 = Now();
      std::vector<Vec3> pts;
      pts.reserve(dense.size());
      for (uint32_t d : dense) pts.push_back(ctx_.samples[d].position);
      const NeighborIndex index(pts, dense);
      index_seconds_ += Now() - t0;
      // Spatially coherent order: a job's vertices share most of their neighbours.
      std::vector<std::pair<uint32_t, uint32_t>> keyed;
      for (uint32_t s = 0; s < N_; ++s) {
        if (!is_dense_[s]) {
          keyed.push_back({MortonKey(ctx_.samples[s].position, ctx_.geometry.bounds_min,
                                     ctx_.geometry.bounds_max),
                           s});
        }
      }
      std::sort(keyed.begin(), keyed.end());
      std::vector<uint32_t> order;
      for (const auto& k : keyed) order.push_back(k.second);
      std::vector<uint8_t> outcome(order.size(), 0xff);
      SideFile file((fs::path(SparseDir(ctx_.folder)) / "sparse_outcome.bin").string());
      const uint8_t ok = static_cast<uint8_t>(SparseOutcome::kReconstructed);

      PhaseJobs p;
      p.name = "sparse-reconstruct";
      p.kind = SparseJobKind::kSparse;
      p.items = order.size();
      p.reuse = [&](const JournalEntry& e) {
        std::vector<uint8_t> o(static_cast<std::size_t>(e.rows.count));
        if (!file.Read(o.data(), o.size(), e.rows.first)) return false;
        std::vector<float> rows;
        for (std::size_t i = 0; i < o.size(); ++i) {
          if (o[i] != ok) continue;
          rows.resize(rows.size() + T_);
          ctx_.writer->ReadRows(order[e.rows.first + i], 1, rows.data() + rows.size() - T_);
        }
        if (SparseResultChecksum(o, rows) != e.rows_checksum) return false;
        std::copy(o.begin(), o.end(), outcome.begin() + static_cast<std::ptrdiff_t>(e.rows.first));
        return true;
      };
      p.make_job = [&](SparseJobHeader& h) {
        SparseJob job;
        job.texels = static_cast<uint32_t>(T_);
        std::unordered_map<uint32_t, uint32_t> local;
        std::vector<uint32_t> union_ids;
        job.offsets.push_back(0);
        std::vector<uint32_t> nbs;
        for (uint64_t i = h.first; i < h.first + h.count; ++i) {
          nbs = index.RadiusSearch(ctx_.samples[order[i]].position, ctx_.plan.radius,
                                   ctx_.plan.max_neighbors);
          std::size_t added = 0;
          for (uint32_t d : nbs) added += local.count(d) ? 0 : 1;
          // A job's rows stay within the job byte limit (at least one vertex per job).
          if (i > h.first && (union_ids.size() + added) * 9 * T_ > kMaxSparseJobBytes) {
            h.count = i - h.first;
            break;
          }
          job.vertices.push_back(order[i]);
          for (uint32_t d : nbs) {
            auto [at, is_new] = local.emplace(d, static_cast<uint32_t>(union_ids.size()));
            if (is_new) union_ids.push_back(d);
            job.neighbors.push_back(at->second);
          }
          job.offsets.push_back(static_cast<uint32_t>(job.neighbors.size()));
        }
        // The dense neighbours' rows, read back from the run folder.
        const std::size_t u = union_ids.size();
        job.transport.resize(u * T_);
        job.visibility.resize(u * T_);
        job.feature.resize(u * T_);
        std::vector<char> buf(5 * T_);
        for (std::size_t k = 0; k < u; ++k) {
          const uint32_t d = union_ids[k];
          ctx_.writer->ReadRows(d, 1, job.transport.data() + k * T_);
          if (!aux_->Read(buf.data(), buf.size(), d * 5 * T_))
            throw FileIoError(SparseDir(ctx_.folder),
                              "dense_aux.bin lacks dense sample " + std::to_string(d));
          std::memcpy(job.visibility.data() + k * T_, buf.data(), T_ * sizeof(float));
          std::memcpy(job.feature.data() + k * T_, buf.data() + T_ * sizeof(float), T_);
        }
        rows_shipped_ += u;
        job.union_ids = std::move(union_ids);
        return EncodeSparseJob(h, job);
      };
      p.accept = [&](const SparseJobResult& r, uint64_t& rows_written) {
        const std::size_t c = static_cast<std::size_t>(r.header.count);
        if (r.outcomes.size() != c) throw RankFailure("a sparse job came back incomplete");
        std::size_t k = 0;
        for (std::size_t i = 0; i < c; ++i) {
          if (r.outcomes[i] != ok) continue;
          if ((k + 1) * T_ > r.transport.size())
            throw RankFailure("a sparse job came back with too few rows");
          ctx_.writer->WriteRows(order[r.header.first + i], 1, r.transport.data() + k * T_);
          ++k;
        }
        if (k * T_ != r.transport.size())
          throw RankFailure("a sparse job came back with too many rows");
        file.Write(r.outcomes.data(), c, r.header.first);
        std::copy(r.outcomes.begin(), r.outcomes.end(),
                  outcome.begin() + static_cast<std::ptrdiff_t>(r.header.first));
        rows_written = k;
        return SparseResultChecksum(r.outcomes, r.transport);
      };
      p.sync = [&] {
        ctx_.writer->Sync();
        file.Sync();
      };
      RunJobs(p, t0);
      ctx_.report.sparse.dense_rows_shipped = rows_shipped_;
      ctx_.report.sparse.index_seconds = index_seconds_;
      std::vector<uint32_t> fb;
      for (std::size_t i = 0; i < order.size(); ++i)
        if (outcome[i] != ok) fb.push_back(order[i]);
      std::sort(fb.begin(), fb.end());
      return fb;
    }

    void Count(const SparseJobCounters& c, bool this_run) {
      FarmReport& rep = ctx_.report;
      rep.sparse.counters += c;
      rep.rays_traced_all += c.rays_traced;
      rep.texels_below_horizon_all += c.texels_below_horizon;
      if (this_run) {
        rep.rays_traced += c.rays_traced;
        rep.texels_traced += c.texels_traced;
        rep.texels_below_horizon += c.texels_below_horizon;
        rep.rays_below_horizon += c.rays_below_horizon;
      }
    }

    // The job queue of one sub-phase (dynamic, adaptive sizes, journaled; as the brute phase).
    void RunJobs(PhaseJobs& p, double t0 = -1) {
      if (t0 < 0) t0 = Now();
      FarmReport& rep = ctx_.report;
      // Journaled jobs of this phase that still verify are not redone.
      std::vector<RowRange> done;
      uint64_t reused_jobs = 0;
      for (const JournalEntry& e : ctx_.sparse_entries) {
        if (e.phase != p.name || e.rows.end() > p.items) continue;
        const bool overlaps = std::any_of(done.begin(), done.end(), [&](const RowRange& d) {
          return e.rows.first < d.end() && d.first < e.rows.end();
        });
        if (overlaps) continue;
        if (!p.reuse(e)) {
          ++rep.checkpoints_rejected;
          continue;
        }
        done.push_back(e.rows);
        ++reused_jobs;
        ++rep.jobs_reused;
        if (p.kind != SparseJobKind::kRank) {
          rep.rows_reused += p.kind == SparseJobKind::kDense
                                 ? e.rows.count
                                 : SparseJobCounters::FromVector(e.counters).reconstructed;
        }
        Count(SparseJobCounters::FromVector(e.counters), false);
      }
      if (reused_jobs > 0) {
        spdlog::info("[{}] {} job(s) re-used from checkpoints", p.name, reused_jobs);
      }

      JobSizing sizing;
      sizing.job_seconds = ctx_.options.job_seconds;
      sizing.workers = ctx_.computing_ranks();
      const uint64_t per_item_bytes = p.kind == SparseJobKind::kRank ? 64 : 9 * T_;
      sizing.max_rows = ctx_.options.max_job_rows > 0
                            ? ctx_.options.max_job_rows
                            : std::max<uint64_t>(1, kMaxSparseJobBytes / per_item_bytes);
      sizing.initial_rows = ctx_.options.initial_job_rows > 0
                                ? ctx_.options.initial_job_rows
                                : 4 * static_cast<uint64_t>(ctx_.threads);
      JobPlanner planner(p.items, done, sizing);

      ProgressOptions po;
      po.unit = p.unit;
      po.rate_unit = p.kind == SparseJobKind::kRank ? "" : "rays";
      po.log_interval_s = ctx_.options.log_interval_s;
      po.log = !ctx_.options.quiet;
      po.already_done = planner.done_before_rows();
      Progress progress(p.name, p.items, po);

      double last_commit = Now();
      std::vector<JournalEntry> pending;
      std::string bytes;
      auto slot_of = [&](int rank) -> Slot& {
        for (Slot& s : slots_)
          if (s.rank == rank) return s;
        throw std::logic_error("no slot for rank " + std::to_string(rank));
      };
      auto accept = [&](int rank, const std::string& result_bytes) {
        Slot& s = slot_of(rank);
        SparseJobResult r;
        try {
          r = DecodeSparseJobResult(result_bytes);
        } catch (const std::exception& e) {
          throw RankFailure("rank " + std::to_string(rank) + ": " + e.what());
        }
        if (s.jobs.empty() || s.jobs.front().first != r.header.first ||
            s.jobs.front().count != r.header.count || r.header.phase != phase_number_) {
          throw RankFailure("rank " + std::to_string(rank) + " returned a job it was not given");
        }
        uint64_t rows_written = 0;
        JournalEntry e;
        e.phase = p.name;
        e.rows = {r.header.first, r.header.count};
        e.rows_checksum = p.accept(r, rows_written);
        e.rank = rank;
        e.busy_seconds = r.busy_seconds;
        e.counters = r.counters.ToVector();
        e.rays_traced = r.counters.rays_traced;
        e.texels_traced = r.counters.texels_traced;
        e.texels_below_horizon = rows_written;  // (rows written; not journaled for sjob lines)
        pending.push_back(e);
        planner.Measured(rank, r.header.count, r.busy_seconds);
        s.jobs.pop_front();
        s.since = Now();
      };
      auto commit = [&] {
        if (pending.empty()) return;
        KeepJobsBeforeFailure(ctx_, jobs_this_run_, pending);
        p.sync();                       // results durable first,
        ctx_.journal->Append(pending);  // then the journal lines that count them
        for (const JournalEntry& e : pending) {
          RankReport& rr = rep.rank_reports[e.rank];
          ++rr.jobs;
          rr.rows += e.rows.count;
          rr.rays_traced += e.rays_traced;
          rr.busy_seconds += e.busy_seconds;
          ++rep.jobs_done;
          rep.rows_done += e.texels_below_horizon;
          Count(SparseJobCounters::FromVector(e.counters), true);
          progress.Advance(e.rows.count, e.rays_traced);
          ++jobs_this_run_;
        }
        pending.clear();
        if (FailureDue(ctx_, jobs_this_run_)) InjectFailure(ctx_, jobs_this_run_);
      };

      for (;;) {
        for (Slot& s : slots_) {
          s.sends.Retire();
          while (s.ready && s.jobs.size() < kJobsAhead) {
            std::optional<RowRange> next = planner.Next(s.rank);
            if (!next) break;
            SparseJobHeader h;
            h.kind = static_cast<uint32_t>(p.kind);
            h.phase = phase_number_;
            h.first = next->first;
            h.count = next->count;
            std::string job = p.make_job(h);
            if (h.count < next->count) planner.Return({h.first + h.count, next->count - h.count});
            if (s.jobs.empty()) s.since = Now();
            s.jobs.push_back(h);
            if (s.local) {
              local_->Give(std::move(job));
            } else {
              s.sends.Send(std::move(job), s.rank, kTagSparseJob, ctx_.comm,
                           "MPI_Isend job to rank " + std::to_string(s.rank));
            }
          }
        }
        const bool idle = std::none_of(slots_.begin(), slots_.end(),
                                       [](const Slot& s) { return !s.jobs.empty(); });
        if (idle && pending.empty() && planner.unassigned_rows() == 0) {
          // Every job came back, so every send has left; complete the requests.
          for (Slot& s : slots_) s.sends.WaitAll();
          break;
        }

        bool busy = false;
        if (local_) {
          while (std::optional<SparseLocalResult> r = local_->Poll()) {
            if (r->error) std::rethrow_exception(r->error);
            accept(0, r->bytes);
            busy = true;
          }
        }
        for (;;) {
          int flag = 0;
          MPI_Status st;
          CheckMpi(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, ctx_.comm, &flag, &st), "MPI_Iprobe");
          if (!flag) break;
          busy = true;
          const int src = st.MPI_SOURCE;
          if (st.MPI_TAG == kTagReady) {
            ReadyMsg ready;
            CheckMpi(MPI_Recv(&ready, sizeof ready, MPI_BYTE, src, kTagReady, ctx_.comm,
                              MPI_STATUS_IGNORE),
                     "MPI_Recv ready");
            ready.host[sizeof ready.host - 1] = '\0';
            rep.rank_reports[src].threads = ready.threads;
            rep.rank_reports[src].host = ready.host;
            slot_of(src).ready = true;
          } else if (st.MPI_TAG == kTagSparseResult) {
            int len = 0;
            MPI_Get_count(&st, MPI_BYTE, &len);
            bytes.resize(static_cast<std::size_t>(std::max(0, len)));
            CheckMpi(MPI_Recv(bytes.data(), len, MPI_BYTE, src, kTagSparseResult, ctx_.comm,
                              MPI_STATUS_IGNORE),
                     "MPI_Recv result from rank " + std::to_string(src));
            accept(src, bytes);
          } else if (st.MPI_TAG == kTagFailed) {
            int len = 0;
            MPI_Get_count(&st, MPI_CHAR, &len);
            std::string message(static_cast<std::size_t>(std::max(0, len)), '\0');
            MPI_Recv(message.data(), len, MPI_CHAR, src, kTagFailed, ctx_.comm, MPI_STATUS_IGNORE);
            throw RankFailure("rank " + std::to_string(src) + " failed: " + message);
          } else {
            throw RankFailure("unexpected message tag " + std::to_string(st.MPI_TAG) +
                              " from rank " + std::to_string(src));
          }
        }
        // Results become durable (rows fdatasync'ed, then their journal lines) every 0.5 s and
        // when no job is out: an fdatasync per result cost 2 s of a 27 s 2-rank run. A
        // failure-injection run commits every result, as its resume tests count on.
        const bool outstanding = std::any_of(slots_.begin(), slots_.end(),
                                             [](const Slot& s) { return !s.jobs.empty(); });
        if (!outstanding || ctx_.options.fail_after_jobs >= 0 || Now() - last_commit >= 0.5) {
          commit();
          last_commit = Now();
        }

        const double now = Now();
        for (const Slot& s : slots_) {
          if (s.jobs.empty() || now - s.since <= timeout_) continue;
          const SparseJobHeader& oldest = s.jobs.front();
          throw RankFailure("rank " + std::to_string(s.rank) + " has not returned its job (" +
                            p.name + " items " + std::to_string(oldest.first) + ".." +
                            std::to_string(oldest.first + oldest.count - 1) + ") for " +
                            std::to_string(static_cast<int>(now - s.since)) +
                            " s (--rank-timeout); giving up");
        }
        progress.Advance(0);
        if (!busy) {
          if (local_) {
            local_->Wait(0.001);
          } else {
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
          }
        }
      }
      progress.Finish();
      ++phase_number_;
      rep.sparse.phases.push_back({p.name, Now() - t0, p.items, reused_jobs});
    }

    FarmContext& ctx_;
    const std::size_t N_;
    const std::size_t T_;
    const int n_;
    const int m_;
    const std::size_t Tm_;
    std::vector<Slot> slots_;
    std::unique_ptr<SparseLocalWorker> local_;
    std::unique_ptr<SideFile> aux_;
    double timeout_ = 300;
    std::vector<uint8_t> is_dense_;
    std::vector<std::vector<float>> low_;  // downsampled rows of the dense vertices
    uint32_t phase_number_ = 0;
    int jobs_this_run_ = 0;
    uint64_t rows_shipped_ = 0;
    double index_seconds_ = 0;
  };
};

// ------------------------------------------------------------------------- visibility phase

struct VisibilityLocalResult {
  std::vector<uint8_t> bytes;
  std::exception_ptr error;
};
using VisibilityLocalWorker = LocalWorker<JobMsg, VisibilityLocalResult>;

std::string VisibilityChunksPath(const RunFolder& f) {
  return (fs::path(f.dir) / kVisibilityChunksFileName).string();
}

// The visibility job (docs/farm.md, "Visibility job"): the brute phase's queue of contiguous
// sample ranges, each job's result the block-differential encoding of its samples' visibility
// maps (farm/visibility_jobs.h) in one message. Rank 0 appends a result to visibility.chunks,
// fdatasyncs, then journals it ("sjob visibility …"); the finalize phase assembles the chunks in
// sample order. A job is re-used after --resume when its chunk still hashes to its journal line.
class VisibilityPhase : public FarmPhase {
 public:
  const char* name() const override { return kVisibilityPhaseName; }

  void Run(FarmContext& ctx) override {
    if (ctx.rank == 0) {
      RunCoordinator(ctx);
    } else {
      RunWorker(ctx);
    }
  }

 private:
  static std::vector<uint8_t> Compute(const FarmContext& ctx, const JobMsg& job) {
    return EncodeVisibilityJobResult(
        ComputeVisibilityJob(*ctx.visibility_sampler, ctx.samples, job.first, job.count));
  }

  static void RunWorker(FarmContext& ctx) {
    ReadyMsg ready;
    ready.threads = ctx.threads;
    std::snprintf(ready.host, sizeof ready.host, "%s", ctx.host.c_str());
    CheckMpi(MPI_Send(&ready, sizeof ready, MPI_BYTE, 0, kTagReady, ctx.comm), "MPI_Send ready");
    int jobs = 0;
    for (;;) {
      MPI_Status st;
      CheckMpi(ProbeFromRankZero(ctx.comm, &st), "MPI_Iprobe from rank 0");
      if (st.MPI_TAG == kTagStop) {
        CheckMpi(MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE),
                 "MPI_Recv stop");
        return;
      }
      JobMsg job;
      CheckMpi(MPI_Recv(&job, sizeof job, MPI_BYTE, 0, kTagJob, ctx.comm, MPI_STATUS_IGNORE),
               "MPI_Recv job");
      if (FailureDue(ctx, jobs)) InjectFailure(ctx, jobs);
      std::vector<uint8_t> result;
      try {
        result = Compute(ctx, job);
      } catch (const std::exception& e) {
        const std::string message = e.what();
        spdlog::error("rank {}: {}", ctx.rank, message);
        MPI_Send(message.data(), static_cast<int>(message.size()), MPI_CHAR, 0, kTagFailed,
                 ctx.comm);
        MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE);
        throw CollectiveStop{kExitRankFailed};
      }
      if (result.size() > static_cast<std::size_t>(INT32_MAX)) {
        throw RankFailure("a visibility job result exceeds 2 GiB; lower --job-seconds");
      }
      CheckMpi(MPI_Send(result.data(), static_cast<int>(result.size()), MPI_BYTE, 0,
                        kTagVisibilityResult, ctx.comm),
               "MPI_Send visibility result");
      ++jobs;
    }
  }

  struct Slot {
    int rank = 0;
    bool local = false;
    bool ready = false;
    bool stopped = false;
    std::optional<JobMsg> job;
    double since = 0;
  };

  static void RunCoordinator(FarmContext& ctx) {
    const uint64_t total = ctx.params.rows;
    FarmReport& rep = ctx.report;
    const std::string path = VisibilityChunksPath(ctx.folder);
    SideFile chunks(path);
    std::error_code ec;
    uint64_t append_at = fs::file_size(path, ec);
    if (ec) append_at = 0;

    // Journaled chunks that still verify are re-used (overlapping lines: the first wins).
    std::vector<RowRange> done;
    std::vector<uint8_t> buffer;
    for (const JournalEntry& e : ctx.sparse_entries) {
      VisibilityChunkRef ref;
      const bool overlaps = std::any_of(done.begin(), done.end(), [&](const RowRange& d) {
        return e.rows.first < d.end() && d.first < e.rows.end();
      });
      bool ok = ChunkOfJournalEntry(e, ref) && !overlaps && e.rows.count > 0 &&
                e.rows.end() <= total && ref.length <= kMaxJobBytes * 4;
      if (ok) {
        buffer.resize(static_cast<std::size_t>(ref.length));
        ok = chunks.Read(buffer.data(), buffer.size(), ref.offset) &&
             Checksum64(buffer.data(), buffer.size()) == ref.checksum;
      }
      if (!ok) {
        ++rep.checkpoints_rejected;
        continue;
      }
      done.push_back(e.rows);
      ctx.visibility_chunks.push_back(ref);
      rep.rows_reused += e.rows.count;
      rep.rays_traced_all += ref.rays_traced;
      rep.texels_below_horizon_all += ref.texels_below_horizon;
      ++rep.jobs_reused;
    }
    if (!ctx.sparse_entries.empty()) {
      spdlog::info("--resume: {} visibility job(s) re-used, {} rejected", rep.jobs_reused,
                   rep.checkpoints_rejected);
    }

    JobSizing sizing;
    sizing.job_seconds = ctx.options.job_seconds;
    sizing.workers = ctx.computing_ranks();
    // A map costs at most ~2 bytes per texel encoded (all positions changing): bound the job.
    const uint64_t map_bytes = 2 * 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n;
    sizing.max_rows = ctx.options.max_job_rows > 0
                          ? ctx.options.max_job_rows
                          : std::max<uint64_t>(1, kMaxJobBytes / map_bytes);
    sizing.initial_rows = ctx.options.initial_job_rows > 0 ? ctx.options.initial_job_rows
                                                           : 4 * static_cast<uint64_t>(ctx.threads);
    JobPlanner planner(total, done, sizing);

    ProgressOptions po;
    po.unit = "samples";
    po.rate_unit = "rays";
    po.log_interval_s = ctx.options.log_interval_s;
    po.log = !ctx.options.quiet;
    po.already_done = planner.done_before_rows();
    Progress progress(kVisibilityPhaseName, total, po);

    const double timeout = ctx.options.rank_timeout_s > 0
                               ? ctx.options.rank_timeout_s
                               : std::max(300.0, 50.0 * ctx.options.job_seconds);
    const double start = Now();
    std::vector<Slot> slots;
    for (int r = 1; r < ctx.size; ++r) slots.push_back({r, false, false, false, {}, start});
    std::unique_ptr<VisibilityLocalWorker> local;
    if (ctx.computes_here()) {
      slots.push_back({0, true, true, false, {}, start});
      local = std::make_unique<VisibilityLocalWorker>(
          [&ctx](JobMsg& job, VisibilityLocalResult& r) { r.bytes = Compute(ctx, job); });
    }
    auto slot_of = [&](int rank) -> Slot& {
      for (Slot& s : slots) {
        if (s.rank == rank) return s;
      }
      throw std::logic_error("no slot for rank " + std::to_string(rank));
    };
    rep.rank_reports[0].threads = ctx.threads;
    rep.rank_reports[0].host = ctx.host;
    rep.rank_reports[0].computes = ctx.computes_here();

    std::vector<JournalEntry> pending;
    std::vector<uint8_t> bytes;
    int jobs_this_run = 0;

    auto accept = [&](int rank, std::span<const uint8_t> message) {
      Slot& s = slot_of(rank);
      VisibilityJobResult r;
      try {
        r = DecodeVisibilityJobResult(message);
      } catch (const std::exception& e) {
        throw RankFailure("rank " + std::to_string(rank) + ": " + e.what());
      }
      if (!s.job || s.job->first != r.first || s.job->count != r.count) {
        throw RankFailure("rank " + std::to_string(rank) + " returned visibility of samples " +
                          std::to_string(r.first) + "+" + std::to_string(r.count) +
                          " it was not given");
      }
      const uint64_t sum = Checksum64(r.chunk.data(), r.chunk.size());
      chunks.Write(r.chunk.data(), r.chunk.size(), append_at);
      pending.push_back(VisibilityJournalEntry(r, rank, append_at, sum));
      append_at += r.chunk.size();
      planner.Measured(rank, r.count, r.busy_seconds);
      s.job.reset();
    };

    auto commit = [&] {
      if (pending.empty()) return;
      KeepJobsBeforeFailure(ctx, jobs_this_run, pending);
      chunks.Sync();                 // chunks durable first,
      ctx.journal->Append(pending);  // then the journal lines that count them
      for (const JournalEntry& e : pending) {
        VisibilityChunkRef ref;
        ChunkOfJournalEntry(e, ref);
        ctx.visibility_chunks.push_back(ref);
        RankReport& rr = rep.rank_reports[e.rank];
        ++rr.jobs;
        rr.rows += e.rows.count;
        rr.rays_traced += e.rays_traced;
        rr.busy_seconds += e.busy_seconds;
        ++rep.jobs_done;
        rep.rows_done += e.rows.count;
        rep.rays_traced += e.rays_traced;
        rep.texels_traced += 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n * e.rows.count -
                             e.texels_below_horizon;
        rep.texels_below_horizon += e.texels_below_horizon;
        rep.rays_traced_all += e.rays_traced;
        rep.texels_below_horizon_all += e.texels_below_horizon;
        progress.Advance(e.rows.count, e.rays_traced);
        ++jobs_this_run;
      }
      pending.clear();
      if (FailureDue(ctx, jobs_this_run)) InjectFailure(ctx, jobs_this_run);
    };

    if (FailureDue(ctx, 0)) InjectFailure(ctx, 0);
    for (;;) {
      for (Slot& s : slots) {
        if (s.stopped || s.job || !s.ready) continue;
        const std::optional<RowRange> next = planner.Next(s.rank);
        if (next) {
          s.job = JobMsg{next->first, next->count};
          s.since = Now();
          if (s.local) {
            local->Give(*s.job);
          } else {
            CheckMpi(MPI_Send(&*s.job, sizeof(JobMsg), MPI_BYTE, s.rank, kTagJob, ctx.comm),
                     "MPI_Send job to rank " + std::to_string(s.rank));
          }
        } else {
          s.stopped = true;
          if (!s.local) {
            CheckMpi(MPI_Send(nullptr, 0, MPI_BYTE, s.rank, kTagStop, ctx.comm),
                     "MPI_Send stop to rank " + std::to_string(s.rank));
          }
        }
      }
      if (std::all_of(slots.begin(), slots.end(), [](const Slot& s) { return s.stopped; }) &&
          pending.empty()) {
        break;
      }

      bool busy = false;
      if (local) {
        while (std::optional<VisibilityLocalResult> r = local->Poll()) {
          if (r->error) std::rethrow_exception(r->error);
          accept(0, r->bytes);
          busy = true;
        }
      }
      for (;;) {
        int flag = 0;
        MPI_Status st;
        CheckMpi(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, ctx.comm, &flag, &st), "MPI_Iprobe");
        if (!flag) break;
        busy = true;
        const int src = st.MPI_SOURCE;
        if (st.MPI_TAG == kTagReady) {
          ReadyMsg ready;
          CheckMpi(
              MPI_Recv(&ready, sizeof ready, MPI_BYTE, src, kTagReady, ctx.comm, MPI_STATUS_IGNORE),
              "MPI_Recv ready");
          ready.host[sizeof ready.host - 1] = '\0';
          rep.rank_reports[src].threads = ready.threads;
          rep.rank_reports[src].host = ready.host;
          slot_of(src).ready = true;
        } else if (st.MPI_TAG == kTagVisibilityResult) {
          int len = 0;
          MPI_Get_count(&st, MPI_BYTE, &len);
          bytes.resize(static_cast<std::size_t>(std::max(0, len)));
          CheckMpi(MPI_Recv(bytes.data(), len, MPI_BYTE, src, kTagVisibilityResult, ctx.comm,
                            MPI_STATUS_IGNORE),
                   "MPI_Recv visibility result from rank " + std::to_string(src));
          accept(src, bytes);
        } else if (st.MPI_TAG == kTagFailed) {
          int len = 0;
          MPI_Get_count(&st, MPI_CHAR, &len);
          std::string message(static_cast<std::size_t>(std::max(0, len)), '\0');
          MPI_Recv(message.data(), len, MPI_CHAR, src, kTagFailed, ctx.comm, MPI_STATUS_IGNORE);
          throw RankFailure("rank " + std::to_string(src) + " failed: " + message);
        } else {
          throw RankFailure("unexpected message tag " + std::to_string(st.MPI_TAG) + " from rank " +
                            std::to_string(src));
        }
      }
      commit();

      const double now = Now();
      for (const Slot& s : slots) {
        if (s.stopped || (s.ready && !s.job) || now - s.since <= timeout) continue;
        throw RankFailure("rank " + std::to_string(s.rank) +
                          (s.job ? " has not returned its job (samples " +
                                       std::to_string(s.job->first) + ".." +
                                       std::to_string(s.job->first + s.job->count - 1) + ")"
                                 : std::string(" never reported ready")) +
                          " for " + std::to_string(static_cast<int>(now - s.since)) +
                          " s (--rank-timeout); giving up");
      }
      progress.Advance(0);
      if (!busy) {
        if (local) {
          local->Wait(0.001);
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    }
    progress.Finish();
    rep.jobs_total = rep.jobs_done + rep.jobs_reused;
  }
};

// Rank 0 assembles visibility.prtv from the journaled chunks (in sample order, so the file does
// not depend on ranks or job boundaries) and writes it durably. visibility.chunks is kept, so
// that --resume of a finished run re-uses every job.
class VisibilityFinalizePhase : public FarmPhase {
 public:
  const char* name() const override { return "visibility-finalize"; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    const std::string path = VisibilityChunksPath(ctx.folder);
    SideFile chunks(path);
    std::vector<std::vector<uint8_t>> data(ctx.visibility_chunks.size());
    std::vector<VisibilityChunk> parts;
    for (std::size_t i = 0; i < data.size(); ++i) {
      const VisibilityChunkRef& ref = ctx.visibility_chunks[i];
      data[i].resize(static_cast<std::size_t>(ref.length));
      if (!chunks.Read(data[i].data(), data[i].size(), ref.offset) ||
          Checksum64(data[i].data(), data[i].size()) != ref.checksum) {
        throw FileIoError(path, "chunk of samples " + std::to_string(ref.first) + "+" +
                                    std::to_string(ref.count) + " changed on disk");
      }
      parts.push_back({ref.first, ref.count, data[i]});
    }
    VisibilityBlockCounts counts;
    const std::vector<uint8_t> file =
        AssembleVisibilityChunks(std::move(parts), ctx.params.rows, ctx.params.cubemap_n,
                                 ctx.params.visibility_bits, path, &counts);
    const std::string out = (fs::path(ctx.folder.dir) / kVisibilityFileName).string();
    WriteFileDurably(out,
                     std::string_view(reinterpret_cast<const char*>(file.data()), file.size()));
    VisibilityFarmReport& v = ctx.report.visibility;
    v.raw_bytes = ctx.params.rows * 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n *
                  static_cast<uint64_t>(ctx.params.visibility_bits) / 8;
    v.encoded_bytes = file.size();
    v.blocks_zero = counts.zero;
    v.blocks_one = counts.one;
    v.blocks_mixed = counts.mixed;
    v.changes = counts.changes;
    spdlog::info(
        "wrote {} ({} maps at n = {}: {} bytes, {:.1f} per vertex; {:.1f}x smaller than "
        "bitmaps)",
        out, ctx.params.rows, ctx.params.cubemap_n, file.size(),
        double(file.size()) / double(ctx.params.rows),
        file.empty() ? 0.0 : double(v.raw_bytes) / double(file.size()));
  }
};

// ------------------------------------------------------------------------------ finalize phase

class FinalizePhase : public FarmPhase {
 public:
  const char* name() const override { return "finalize"; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    ctx.writer->Finalize();
    ctx.writer.reset();
    if (ctx.options.fail_in == "finalize" && ctx.options.fail_rank == 0) {
      spdlog::warn("debug: rank 0 exits abruptly before renaming {} (--fail-in finalize)",
                   ctx.folder.partial);
      spdlog::default_logger()->flush();
      std::_Exit(kExitRankFailed);
    }
    fs::rename(ctx.folder.partial, ctx.folder.transport);
    SyncDirectory(ctx.folder.dir);
    spdlog::info("wrote {} ({} rows x {} texels, {} blocks of {} rows)", ctx.folder.transport,
                 ctx.params.rows, 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n,
                 (ctx.params.rows + ctx.options.rows_per_block - 1) / ctx.options.rows_per_block,
                 ctx.options.rows_per_block);
  }
};

void WriteReport(FarmContext& ctx) {
  if (ctx.rank != 0 || !ctx.folder_ready) return;
  try {
    WriteFileDurably(ctx.folder.report, ctx.report.ToJsonText());
  } catch (const std::exception& e) {
    spdlog::error("cannot write the report: {}", e.what());
  }
}

void ConfigureLogging(const FarmContext& ctx) {
  auto logger = spdlog::stderr_color_mt("prt-farm-rank" + std::to_string(ctx.rank));
  spdlog::set_default_logger(logger);
  if (ctx.size > 1) {
    spdlog::set_pattern("[%H:%M:%S.%e] [rank " + std::to_string(ctx.rank) + "] [%^%l%$] %v");
  } else {
    spdlog::set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
  }
  const bool chatty = ctx.rank == 0 && !ctx.options.quiet;
  spdlog::set_level(chatty ? spdlog::level::info : spdlog::level::warn);
}

}  // namespace

int RunFarm(const FarmOptions& options, bool* transport_job) {
  FarmContext ctx;
  ctx.options = options;
  ctx.folder = RunFolder(options.out_dir);
  MPI_Comm_set_errhandler(ctx.comm, MPI_ERRORS_RETURN);
  MPI_Comm_rank(ctx.comm, &ctx.rank);
  MPI_Comm_size(ctx.comm, &ctx.size);
  ConfigureLogging(ctx);
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  ctx.host = host;
  ctx.threads = options.threads > 0 ? options.threads : AutoThreads(ctx.comm);
  const int allowed = AllowedCpus();
  if (allowed > 0 && ctx.threads > allowed) {
    spdlog::warn(
        "rank {} uses {} threads but may only run on {} CPU(s): start mpirun with "
        "--bind-to none (or srun --cpu-bind=none), see cluster-configs/README.md",
        ctx.rank, ctx.threads, allowed);
  }
  tbb::global_control threads_limit(tbb::global_control::max_allowed_parallelism,
                                    static_cast<std::size_t>(ctx.threads));

  FarmReport& rep = ctx.report;
  rep.version = FarmVersion();
  rep.ranks = ctx.size;
  rep.rank_reports.resize(static_cast<std::size_t>(ctx.size));
  for (int r = 0; r < ctx.size; ++r) rep.rank_reports[r].rank = r;
  if (ctx.rank == 0) {
    spdlog::info("prt-farm {}: {} rank(s), {} thread(s) per rank on rank 0, run folder {}",
                 rep.version, ctx.size, ctx.threads, ctx.folder.dir);
  }

  std::vector<std::unique_ptr<FarmPhase>> phases;
  phases.push_back(std::make_unique<SetupPhase>());

  const double start = Now();
  int exit_code = kExitOk;
  for (std::size_t i = 0; i < phases.size(); ++i) {
    FarmPhase* phase = phases[i].get();
    const double t0 = Now();
    try {
      phase->Run(ctx);
    } catch (const CollectiveStop& stop) {
      exit_code = stop.exit_code;
    } catch (...) {
      std::string message;
      exit_code = ExitCodeOf(std::current_exception(), message);
      spdlog::error("{}", message);
      if (ctx.rank == 0) {
        rep.error = message;
        rep.status = "failed";
        rep.exit_code = exit_code;
        rep.wall_seconds = Now() - start;
        rep.phases.push_back({phase->name(), Now() - t0});
        rep.jobs_total = rep.jobs_done + rep.jobs_reused;
        WriteReport(ctx);
        spdlog::error(
            "stopping all ranks (exit code {}); finished jobs are kept in {}: rerun "
            "with --resume",
            exit_code, ctx.folder.journal);
      }
      spdlog::default_logger()->flush();
      // The others may be blocked in MPI calls: only an abort releases them.
      MPI_Abort(ctx.comm, exit_code);
      return exit_code;
    }
    rep.phases.push_back({phase->name(), Now() - t0});
    if (std::string(phase->name()) == ctx.method) rep.sampling_seconds = Now() - t0;
    if (exit_code != kExitOk) break;
    if (i == 0 && ctx.params.complete) {
      // Nothing to do: the finished run's report and files stay as they are.
      if (transport_job != nullptr) *transport_job = false;
      return kExitOk;
    }
    if (i == 0) {
      // Setup told every rank the method: its sampling phase, then finalize.
      if (ctx.params.visibility) {
        phases.push_back(std::make_unique<VisibilityPhase>());
        phases.push_back(std::make_unique<VisibilityFinalizePhase>());
      } else {
        if (ctx.params.sparse) {
          phases.push_back(std::make_unique<SparseSamplingPhase>());
        } else {
          phases.push_back(std::make_unique<BruteSamplingPhase>());
        }
        phases.push_back(std::make_unique<FinalizePhase>());
      }
    }
  }
  rep.wall_seconds = Now() - start;
  rep.status = exit_code == kExitOk ? "ok" : "failed";
  rep.exit_code = exit_code;
  rep.cols = 6ull * rep.cubemap_n * rep.cubemap_n;
  if (transport_job != nullptr) *transport_job = ctx.params.visibility == 0;
  WriteReport(ctx);
  if (ctx.rank == 0 && exit_code == kExitOk) {
    spdlog::info(
        "done in {}: {} jobs ({} re-used from checkpoints), {} rays, load imbalance "
        "{:.2f}; report in {}",
        Progress::FormatDuration(rep.wall_seconds), rep.jobs_total, rep.jobs_reused,
        rep.rays_traced, rep.LoadImbalance(), ctx.folder.report);
  }
  spdlog::default_logger()->flush();
  return exit_code;
}

}  // namespace prt
