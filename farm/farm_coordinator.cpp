// prt-farm's coordinator (see farm_coordinator.h and docs/farm.md).
#include "farm/farm_coordinator.h"

#include <mpi.h>
#include <sched.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "farm/checkpoint_journal.h"
#include "farm/farm_report.h"
#include "farm/job_planner.h"
#include "farm/run_folder.h"
#include "vocabulary/errors.h"
#include "vocabulary/progress.h"
#include "vocabulary/scene.h"
#include "vocabulary/transport_file.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

#ifndef PRT_DEFAULT_DATA_DIR
#define PRT_DEFAULT_DATA_DIR ""
#endif

namespace prt {

namespace {

namespace fs = std::filesystem;

constexpr const char* kDefaultSceneName = "<default scene>";
constexpr uint64_t kMaxMessageBytes = uint64_t{64} << 20;  // rows travel in ≤ 64 MiB messages
constexpr uint64_t kMaxJobBytes = uint64_t{256} << 20;     // a job's rows fit in 256 MiB
constexpr uint64_t kMaxBroadcastBytes = uint64_t{1} << 30;

enum Tag : int { kTagReady = 1, kTagJob, kTagStop, kTagResult, kTagRows, kTagFailed };

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
};

double Now() {
  using Clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(Clock::now().time_since_epoch()).count();
}

void CheckMpi(int rc, const std::string& what) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, text, &len);
  throw RankFailure(what + ": " + std::string(text, static_cast<std::size_t>(len)));
}

// Exit code of the exception in flight (FarmExitCode).
int ExitCodeOf(std::exception_ptr e, std::string& message) {
  try {
    std::rethrow_exception(e);
  } catch (const UsageError& x) {
    message = x.what();
    return kExitUsage;
  } catch (const InputError& x) {
    message = x.what();
    return kExitBadInput;
  } catch (const FileIoError& x) {
    message = x.what();
    return kExitIoError;
  } catch (const fs::filesystem_error& x) {
    message = x.what();
    return kExitIoError;
  } catch (const RankFailure& x) {
    message = x.what();
    return kExitRankFailed;
  } catch (const std::exception& x) {
    message = std::string("internal error: ") + x.what();
    return kExitRankFailed;
  } catch (...) {
    message = "internal error: unknown exception";
    return kExitRankFailed;
  }
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
      if (ctx.computes_here()) {
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
    if (ctx.method != "brute") {
      throw InputError(scene.file, "method '" + ctx.method +
                                       "' is not available in this prt-farm yet (only brute); "
                                       "pass --method brute");
    }
    if (scene.samples != SpatialSamples::kVertices) {
      throw InputError(scene.file,
                       "samples = \"camera\" (image relighting) is not supported by prt-farm yet");
    }
    const int rays = o.rays_per_texel > 0 ? o.rays_per_texel : scene.sampling.rays_per_texel;
    spdlog::info("scene {} ('{}'): n = {}, {} rays per texel, method {}", ctx.report.scene,
                 scene.name, scene.cubemap_n, rays, ctx.method);
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    geometry_bytes = SerializeSceneGeometry(geometry);
    uint64_t rows = 0;
    for (const SceneMesh& m : geometry.meshes) rows += m.mesh.positions.size();
    if (rows == 0) throw InputError(scene.file, "the scene has no spatial samples");

    ctx.params.rows = rows;
    ctx.params.geometry_bytes = geometry_bytes.size();
    ctx.params.seed = scene.sampling.seed;
    ctx.params.cubemap_n = scene.cubemap_n;
    ctx.params.rays_per_texel = rays;

    RunManifest manifest;
    manifest.method = ctx.method;
    manifest.cubemap_n = scene.cubemap_n;
    manifest.rays_per_texel = rays;
    manifest.seed = scene.sampling.seed;
    manifest.rows = rows;
    manifest.rows_per_block = o.rows_per_block;
    manifest.scene_checksum = Checksum64(scene_text.data(), scene_text.size());
    manifest.geometry_checksum = Checksum64(geometry_bytes.data(), geometry_bytes.size());

    FarmReport& rep = ctx.report;
    rep.scene_name = scene.name;
    rep.method = ctx.method;
    rep.cubemap_n = scene.cubemap_n;
    rep.rays_per_texel = rays;
    rep.seed = scene.sampling.seed;
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

    const bool has_run = fs::exists(f.journal) || fs::exists(f.partial) || fs::exists(f.transport);
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
      for (const std::string& p : {f.transport, f.partial, f.journal, f.manifest, f.report}) {
        fs::remove(p, ec);
      }
    }
    // From here on the folder is this run's: a failure report may replace an older report.
    ctx.folder_ready = true;
    WriteFileDurably(f.scene_copy, scene_text);
    WriteFileDurably(f.geometry, geometry_bytes);
    WriteFileDurably(f.manifest, manifest.ToJsonText());

    std::vector<JournalEntry> reused;
    if (!fresh) {
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
    if (!ctx.writer) ctx.writer.emplace(TransportFileWriter::Create(f.partial, info));
    ctx.journal = std::make_unique<CheckpointJournal>(f.journal, manifest.Key(), reused);
    ctx.reused = std::move(reused);
    if (!fresh) {
      uint64_t rows_reused = 0;
      for (const JournalEntry& e : ctx.reused) rows_reused += e.rows.count;
      spdlog::info("--resume: {} finished job(s) ({} of {} samples) re-used from checkpoints",
                   ctx.reused.size(), rows_reused, manifest.rows);
    }
  }
};

// ----------------------------------------------------------------------- brute sampling phase

// Rank 0's own worker thread (when rank 0 computes): takes one job at a time from the
// coordinator's main thread, which alone calls MPI.
class LocalWorker {
 public:
  struct Result {
    ResultMsg msg;
    std::vector<float> rows;
    std::exception_ptr error;
  };

  explicit LocalWorker(const FarmContext& ctx) : ctx_(ctx), thread_([this] { Loop(); }) {}
  ~LocalWorker() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

  void Give(const JobMsg& job) {
    {
      std::lock_guard lock(mutex_);
      job_ = job;
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
      JobMsg job;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [&] { return stop_ || job_.has_value(); });
        if (stop_) return;
        job = *job_;
        job_.reset();
      }
      Result r;
      try {
        r.msg = ComputeJob(ctx_, job, r.rows);
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

  const FarmContext& ctx_;
  std::mutex mutex_;
  std::condition_variable cv_, cv_done_;
  std::optional<JobMsg> job_;
  std::deque<Result> results_;
  bool stop_ = false;
  std::thread thread_;
};

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
      CheckMpi(MPI_Probe(0, MPI_ANY_TAG, ctx.comm, &st), "MPI_Probe from rank 0");
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
    std::unique_ptr<LocalWorker> local;
    if (ctx.computes_here()) {
      slots.push_back({0, true, true, false, {}, start});
      local = std::make_unique<LocalWorker>(ctx);
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
        while (std::optional<LocalWorker::Result> r = local->Poll()) {
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

// ------------------------------------------------------------------------------ finalize phase

class FinalizePhase : public FarmPhase {
 public:
  const char* name() const override { return "finalize"; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    ctx.writer->Finalize();
    ctx.writer.reset();
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

// CPUs this process may run on (mpirun binds each rank to one core by default when there are
// at most 2 ranks, and to a socket otherwise).
int AllowedCpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return 0;
  return CPU_COUNT(&set);
}

// Threads per rank for --threads 0: the CPUs the rank is bound to when mpirun bound it to part
// of the node, else the node's cores divided by the ranks on the node.
int AutoThreads(MPI_Comm comm) {
  MPI_Comm node;
  int local_ranks = 1;
  if (MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node) == MPI_SUCCESS) {
    MPI_Comm_size(node, &local_ranks);
    MPI_Comm_free(&node);
  }
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int allowed = AllowedCpus();
  if (allowed > 0 && allowed < cores) return allowed;
  return std::max(1, cores / std::max(1, local_ranks));
}

}  // namespace

int RunFarm(const FarmOptions& options) {
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
  phases.push_back(std::make_unique<BruteSamplingPhase>());
  phases.push_back(std::make_unique<FinalizePhase>());

  const double start = Now();
  int exit_code = kExitOk;
  for (const auto& phase : phases) {
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
  }
  rep.wall_seconds = Now() - start;
  rep.status = exit_code == kExitOk ? "ok" : "failed";
  rep.exit_code = exit_code;
  rep.cols = 6ull * rep.cubemap_n * rep.cubemap_n;
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
