// prt-farm's run: the phase list and what every phase shares (see farm_run.h, farm_context.h).
#include "farm/farm_run.h"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "farm/farm_context.h"
#include "farm/mpi_support.h"
#include "farm/progress.h"
#include "farm/run_manifest.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt {

void AgreeOrStop(FarmContext& ctx, int local_status) {
  int status = local_status;
  CheckMpi(MPI_Allreduce(&local_status, &status, 1, MPI_INT, MPI_MAX, ctx.comm), "MPI_Allreduce");
  if (status != kExitOk) throw CollectiveStop{status};
}

bool FailureDue(const FarmContext& ctx, int jobs) {
  return ctx.options.fail_after_jobs >= 0 && ctx.rank == ctx.options.fail_rank &&
         jobs >= ctx.options.fail_after_jobs;
}

void InjectFailure(const FarmContext& ctx, int jobs) {
  if (ctx.options.fail_mode == "hang") {
    spdlog::warn("debug: rank {} hangs after {} jobs (--fail-after-jobs)", ctx.rank, jobs);
    for (;;) std::this_thread::sleep_for(std::chrono::seconds(3600));
  }
  spdlog::warn("debug: rank {} exits abruptly after {} jobs (--fail-after-jobs)", ctx.rank, jobs);
  spdlog::default_logger()->flush();
  std::_Exit(kExitRankFailed);
}

void ExitAbruptly(int rank, const std::string& where) {
  spdlog::warn("debug: rank {} exits abruptly {} (--fail-in)", rank, where);
  spdlog::default_logger()->flush();
  std::_Exit(kExitRankFailed);
}

namespace {

// Rank 0, once the folder is this run's: report.json, durably. False when it could not be written.
bool WriteReport(FarmContext& ctx) {
  if (ctx.rank != 0 || !ctx.folder_ready) return false;
  try {
    WriteFileDurably(ctx.folder.report, ctx.report.ToJsonText());
    return true;
  } catch (const std::exception& e) {
    spdlog::error("cannot write the report: {}", e.what());
    return false;
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

// The phases after setup, from what setup told every rank (the stages that run).
std::vector<std::unique_ptr<FarmPhase>> PhasesAfterSetup(const FarmContext& ctx) {
  std::vector<std::unique_ptr<FarmPhase>> phases;
  if (ctx.params.visibility) {
    if (ctx.params.run_rows) {
      phases.push_back(MakeVisibilityPhase());
      phases.push_back(MakeVisibilityFinalizePhase());
    }
    return phases;
  }
  if (ctx.params.run_rows) {
    phases.push_back(ctx.params.sparse ? MakeSparsePhase() : MakeBrutePhase());
    phases.push_back(MakeFinalizePhase());
  }
  if (ctx.params.run_compression) phases.push_back(MakeCompressionPhase());
  if (ctx.params.run_estimate) phases.push_back(MakeEstimatePhase());
  return phases;
}

// The stage a phase belongs to (report.json "stages" adds up their wall times).
const char* StageOfPhase(const std::string& phase) {
  if (phase == "compress") return kStageCompression;
  if (phase == "estimate") return kStageEstimate;
  if (phase == "setup") return kStageAssets;
  return kStageRows;
}

// Rank 0: report.json's "stages", and the sections of the report of the run this one continued
// for the stages it re-used (their figures describe the files this run keeps).
void ReportStages(FarmContext& ctx) {
  FarmReport& rep = ctx.report;
  rep.stages.clear();
  for (const StageDecision& d : ctx.stage_plan.stages) {
    StageReport st{d.name, ToString(d.action), d.reason, 0};
    if (d.name == kStageAssets) st.status = d.action == StageAction::kRun ? "updated" : "unchanged";
    for (const PhaseReport& p : rep.phases)
      if (d.name == StageOfPhase(p.name) && d.name != kStageAssets)
        st.wall_seconds += p.wall_seconds;
    rep.stages.push_back(st);
  }
  if (!ctx.previous_report.empty()) {
    const nlohmann::ordered_json old =
        nlohmann::ordered_json::parse(ctx.previous_report, nullptr, false);
    nlohmann::ordered_json carried = nlohmann::ordered_json::object();
    auto carry = [&](const char* key) {
      if (old.is_object() && old.contains(key)) carried[key] = old[key];
    };
    if (ctx.stage_plan.Has(kStageRows) &&
        ctx.stage_plan.Get(kStageRows).action == StageAction::kReuse) {
      for (const char* key : {"sparse", "visibility", "monte_carlo"}) carry(key);
      if (old.is_object()) {
        rep.rays_traced_all = old.value("rays_traced_including_reused", uint64_t{0});
        rep.texels_below_horizon_all =
            old.value("texels_skipped_below_horizon_including_reused", uint64_t{0});
      }
    }
    if (ctx.stage_plan.Has(kStageCompression) &&
        ctx.stage_plan.Get(kStageCompression).action == StageAction::kReuse)
      carry("compression");
    rep.carried_json = carried.dump();
  }
  std::error_code ec;
  if (std::filesystem::exists(ctx.folder.accuracy, ec)) {
    try {
      rep.accuracy_json = ReadWholeFile(ctx.folder.accuracy);
    } catch (const std::exception&) {
    }
  }
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
  phases.push_back(MakeSetupPhase());

  const double start = FarmNow();
  int exit_code = kExitOk;
  for (std::size_t i = 0; i < phases.size(); ++i) {
    FarmPhase* phase = phases[i].get();
    const double t0 = FarmNow();
    try {
      phase->Run(ctx);
    } catch (const CollectiveStop& stop) {
      exit_code = stop.exit_code;
    } catch (...) {
      std::string message;
      exit_code = ExitCodeOf(std::current_exception(), message);
      spdlog::error("{}", message);
      if (ctx.rank == 0) {
        if (rep.error.empty()) rep.error = message;
        rep.status = "failed";
        rep.exit_code = exit_code;
        rep.wall_seconds = FarmNow() - start;
        rep.phases.push_back({phase->name(), FarmNow() - t0});
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
    rep.phases.push_back({phase->name(), FarmNow() - t0});
    if (std::string(phase->name()) == ctx.method) rep.sampling_seconds = FarmNow() - t0;
    if (exit_code != kExitOk) break;
    if (i == 0) {
      // Nothing to do: the finished run's files stay as they are (complete == 2: its report
      // too; 1: only scene.toml/geometry.prtg changed, the report says so).
      if (ctx.params.complete == 2) return kExitOk;
      if (ctx.params.complete) break;
      for (auto& p : PhasesAfterSetup(ctx)) phases.push_back(std::move(p));
    }
  }
  rep.wall_seconds = FarmNow() - start;
  rep.status = exit_code == kExitOk ? "ok" : "failed";
  rep.exit_code = exit_code;
  rep.cols = 6ull * rep.cubemap_n * rep.cubemap_n;
  if (ctx.rank == 0) ReportStages(ctx);
  const bool reported = WriteReport(ctx);
  // The compressed file and the report being durable, the raw matrix goes if asked to.
  if (ctx.rank == 0 && exit_code == kExitOk && reported && options.discard_raw &&
      std::filesystem::exists(ctx.folder.compressed)) {
    std::filesystem::remove(ctx.folder.transport);
    SyncDirectory(ctx.folder.dir);
  }
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
