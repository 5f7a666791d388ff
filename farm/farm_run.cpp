// prt-farm's run: the phase list and what every phase shares (see farm_run.h, farm_context.h).
#include "farm/farm_run.h"

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
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
#include "vocabulary/tbb_parallel.h"

namespace prt {

void AgreeOrStop(FarmContext& ctx, int local_status) {
  const int status = ctx.collectives.AgreeMax(local_status, "agree on the exit status");
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

ProgressOptions FarmProgressOptions(FarmContext& ctx, const std::string& unit, bool whole_step) {
  ProgressOptions po;
  po.unit = unit;
  po.log_interval_s = ctx.options.log_interval_s;
  po.log = ctx.rank == 0 && !ctx.options.quiet;
  RunEta* eta = &ctx.run_eta;
  po.suffix = [eta, whole_step](double step_eta) {
    return eta->Suffix(whole_step ? step_eta : -1.0);
  };
  return po;
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

// Rank 0: report.json's "stages", and the sections of the report of the run this one continued
// for the stages it re-used (their figures describe the files this run keeps).
void ReportStages(FarmContext& ctx, const PhaseList& phases) {
  FarmReport& rep = ctx.report;
  rep.eta.clear();
  for (const RunEtaSample& e : ctx.run_eta.History())
    rep.eta.push_back({e.elapsed_s, e.step, e.predicted_total_s});
  std::error_code size_ec;
  const auto bytes = std::filesystem::file_size(ctx.folder.transport, size_ec);
  rep.transport_bytes = size_ec ? 0 : static_cast<uint64_t>(bytes);
  rep.stages.clear();
  for (const StageDecision& d : ctx.stage_plan.stages) {
    StageReport st{d.name, ToString(d.action), d.reason, 0};
    if (d.name == kStageAssets) st.status = d.action == StageAction::kRun ? "updated" : "unchanged";
    for (std::size_t i = 0; i < rep.phases.size() && i < phases.size(); ++i)
      if (d.name == phases[i]->stage() && d.name != kStageAssets)
        st.wall_seconds += rep.phases[i].wall_seconds;
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
      for (const char* key : {"sparse", "visibility"}) carry(key);
      if (old.is_object()) {
        rep.rays_traced_all = old.value("rays_traced_including_reused", uint64_t{0});
        rep.texels_below_horizon_all =
            old.value("texels_skipped_below_horizon_including_reused", uint64_t{0});
      }
    }
    if (ctx.stage_plan.Has(kStageCompression) &&
        ctx.stage_plan.Get(kStageCompression).action == StageAction::kReuse)
      carry("compression");
    if (ctx.stage_plan.Has(kStageIndirect) &&
        ctx.stage_plan.Get(kStageIndirect).action == StageAction::kReuse)
      carry("interreflection");
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

std::string Megabytes(const std::string& path) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (ec) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f MB", static_cast<double>(bytes) / 1e6);
  return buf;
}

// The lines a person reads at the end of a run (stdout): each stage, what it did, how long it
// took, what it left, and where everything is. report.json has the details.
std::string RunSummary(const FarmContext& ctx) {
  const FarmReport& rep = ctx.report;
  const RunFolder& f = ctx.folder;
  std::string out = "\nprt-farm: " + rep.scene_name + " (" + rep.scene + "), " +
                    std::to_string(rep.rows) + " samples, n = " + std::to_string(rep.cubemap_n) +
                    ", " + rep.method + ", " + std::to_string(rep.ranks) + " rank(s), " +
                    Progress::FormatDuration(rep.wall_seconds) + "\n";
  char line[512];
  for (const StageReport& st : rep.stages) {
    std::string what;
    if (st.name == kStageRows) {
      what = ctx.params.visibility
                 ? "visibility.prtv " + Megabytes(f.visibility)
                 : "transport.prtt " + Megabytes(f.transport) + " (packed rows), " +
                       Progress::FormatCount(static_cast<double>(rep.rays_traced)) + " rays traced";
    } else if (st.name == kStageCompression) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "transport.prtc %s, %.2f%% Frobenius error of T",
                    Megabytes(f.compressed).c_str(),
                    100 * rep.compression.relative_frobenius_error);
      what = st.status == "reused" ? "transport.prtc " + Megabytes(f.compressed) : buf;
    } else if (st.name == kStageIndirect) {
      const std::string section = rep.Section("interreflection");
      const nlohmann::ordered_json ir =
          nlohmann::ordered_json::parse(section.empty() ? "{}" : section, nullptr, false);
      what = "indirect/ " + std::to_string(ctx.params.bounces) + " bounce(s)";
      if (ir.is_object() && ir.contains("indirect_share")) {
        what += ", bounce light";
        for (const auto& s : ir["indirect_share"]) {
          char buf[96];
          std::snprintf(buf, sizeof buf, " %.1f%% %s", 100 * s.value("indirect_share", 0.0),
                        s.value("light", std::string()).c_str());
          what += buf;
        }
        what += " of B";
      }
    } else if (st.name == kStageEstimate) {
      what = "accuracy.json: " +
             AccuracyLine(nlohmann::ordered_json::parse(
                 rep.accuracy_json.empty() ? "{}" : rep.accuracy_json, nullptr, false));
    } else {
      what = "scene.toml, geometry.prtg";
    }
    std::snprintf(line, sizeof line, "  %-12s %-9s %8s  %s\n", st.name.c_str(), st.status.c_str(),
                  st.wall_seconds > 0 ? Progress::FormatDuration(st.wall_seconds).c_str() : "",
                  what.c_str());
    out += line;
    // Why it ran, where that is news: not for a new run, nor for "the rows ran".
    if (!st.reason.empty() && st.status != "reused" && st.reason != "new run" &&
        st.reason.rfind("the rows ", 0) != 0)
      out += "               why: " + st.reason + "\n";
  }
  out += "  run folder: " + f.dir + "   report: " + f.report + "\n";
  return out;
}

}  // namespace

int RunFarm(const FarmOptions& options) {
  UseTbbParallelism();  // the core vocabulary's loops (resampling) on TBB
  FarmContext ctx;
  ctx.options = options;
  ctx.folder = RunFolder(options.out_dir);
  ctx.rank = ctx.collectives.rank();
  ctx.size = ctx.collectives.size();
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

  // The list's first entry (setup) decides what the run is; the others are asked once it has.
  const std::vector<PhaseFactory>& list = FarmPhaseList();
  PhaseList phases;
  if (!list.empty()) list.front()(ctx, phases);
  // Rank 0: every phase writes its section of the report (also when the run fails).
  auto report_phases = [&] {
    if (ctx.rank == 0)
      for (const auto& p : phases) p->Report(rep);
  };

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
        report_phases();
        WriteReport(ctx);
        spdlog::error(
            "stopping all ranks (exit code {}); finished jobs are kept in {}: rerun "
            "with --resume",
            exit_code, ctx.folder.journal);
      }
      spdlog::default_logger()->flush();
      // The others may be blocked in MPI calls: only an abort releases them.
      ctx.collectives.AbortEveryRank(exit_code);
    }
    rep.phases.push_back({phase->name(), FarmNow() - t0});
    if (std::string(phase->name()) == ctx.method) rep.sampling_seconds = FarmNow() - t0;
    if (exit_code != kExitOk) break;
    if (i == 0) {
      // Nothing to do: the finished run's files stay as they are (complete == 2: its report
      // too; 1: only scene.toml/geometry.prtg changed, the report says so).
      if (ctx.params.complete == 2) return kExitOk;
      if (ctx.params.complete) break;
      for (std::size_t f = 1; f < list.size(); ++f) list[f](ctx, phases);
      if (ctx.rank == 0) {
        // The whole run's ETA: every phase's own cost model.
        std::vector<RunStep> steps;
        for (std::size_t p = 1; p < phases.size(); ++p) phases[p]->PredictSteps(ctx, steps);
        ctx.run_eta.SetSteps(std::move(steps));
      }
    }
  }
  report_phases();
  rep.wall_seconds = FarmNow() - start;
  rep.status = exit_code == kExitOk ? "ok" : "failed";
  rep.exit_code = exit_code;
  rep.cols = 6ull * rep.cubemap_n * rep.cubemap_n;
  {
    // Every rank's peak resident memory (docs/farm.md, "Memory"), for the report.
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    const uint64_t peak = static_cast<uint64_t>(usage.ru_maxrss) * 1024;  // Linux: KiB
    const std::vector<uint64_t> peaks =
        ctx.collectives.GatherOnRank0(std::span<const uint64_t>(&peak, 1), "gather peak memory");
    if (ctx.rank == 0)
      for (int r = 0; r < ctx.size; ++r) rep.rank_reports[r].peak_rss_bytes = peaks[r];
  }
  if (ctx.rank == 0) ReportStages(ctx, phases);
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
    spdlog::default_logger()->flush();
    if (!options.quiet) std::fputs(RunSummary(ctx).c_str(), stdout);
  }
  spdlog::default_logger()->flush();
  return exit_code;
}

}  // namespace prt
