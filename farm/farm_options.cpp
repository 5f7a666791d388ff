// prt-farm's command line (CLI11). The text of --help is the reference of docs/farm.md.
#include "farm/farm_options.h"

#include <CLI/CLI.hpp>
#include <ostream>

#ifndef PRT_VERSION
#define PRT_VERSION "0.1.0"
#endif

namespace prt {

std::string FarmVersion() {
  return PRT_VERSION;
}

int ParseFarmCommandLine(int argc, char** argv, FarmOptions& o, std::ostream& out,
                         std::ostream& err) {
  CLI::App app(
      "prt-farm: precomputes the light transport matrix T of a scene on a cluster.\n"
      "Run under MPI: mpirun -np N prt-farm [scene.toml] --out run/ (N = 1 works too).\n"
      "Without a scene file it runs the embedded default scene.",
      "prt-farm");
  app.set_version_flag("--version", "prt-farm " + FarmVersion());
  app.footer(
      "Exit codes: 0 ok, 1 usage error (or a run folder that needs --resume/--force),\n"
      "2 bad input (scene, mesh, checkpoints of another run), 3 I/O error in the run folder,\n"
      "4 a rank failed (died, hung past --rank-timeout, internal error). Finished jobs are\n"
      "always kept: rerun with --resume. See docs/farm.md.");
  app.add_option("scene", o.scene_path, "Scene description (TOML, docs/scene-format.md)");
  app.add_option("-o,--out", o.out_dir, "Run folder (created if missing)")->capture_default_str();
  app.add_option("--data-dir", o.data_dirs, "Extra folder to look up relative mesh paths in");
  app.add_option("-t,--threads", o.threads,
                 "TBB threads per rank (0: cores of the node / ranks on the node)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  app.add_flag("--resume", o.resume,
               "Continue the run in --out: re-run only unfinished jobs (starts fresh if the "
               "folder holds no run)");
  app.add_flag("--force", o.force, "Discard a run already in --out and start over");
  app.add_option("--method", o.method,
                 "Sampling method: sparse | brute (default: the scene's; sparse)")
      ->check(CLI::IsMember({"brute", "sparse"}));
  app.add_option("--job", o.job,
                 "What to compute: transport (the matrix T) or visibility (per-vertex visibility "
                 "cubemaps for glossy relighting); default: the scene's [sampling] job")
      ->check(CLI::IsMember({"transport", "visibility"}));
  app.add_option("--rays-per-texel", o.rays_per_texel,
                 "Occlusion rays per cubemap texel (default: the scene's)")
      ->check(CLI::Range(1, 1024));
  app.add_option("--seed", o.seed,
                 "Seed of the occlusion rays' random numbers (default: the scene's), e.g. for an "
                 "independent reference estimate of the same transport");
  app.add_option("--bounces", o.bounces,
                 "Interreflections after the direct light, 0 = direct only (default: the "
                 "scene's [sampling] bounces; docs/interreflection.md)")
      ->check(CLI::Range(0, 8));
  app.add_option("--job-seconds", o.job_seconds, "Target wall time of one job")
      ->check(CLI::Range(0.001, 86400.0))
      ->capture_default_str();
  app.add_option("--rows-per-block", o.rows_per_block,
                 "Rows per checksummed block of transport.prtt")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  app.add_option("--log-interval", o.log_interval_s, "Seconds between progress lines")
      ->check(CLI::Range(0.0, 3600.0))
      ->capture_default_str();
  app.add_option("--rank-timeout", o.rank_timeout_s,
                 "Seconds a rank with jobs out may stay silent (no result, no heartbeat) "
                 "before rank 0 gives up with exit code 4; a worker sends a heartbeat every "
                 "min(5, timeout/4) s while it computes, so a job may take longer than this "
                 "(0: max(300, 50 x --job-seconds))")
      ->check(CLI::Range(0.0, 1e7));
  bool coordinator_only = false;
  app.add_flag("--coordinator-only", coordinator_only,
               "Rank 0 only plans and writes (by default it also computes jobs)");
  app.add_flag("--rows-via-rank0", o.rows_via_rank0,
               "Send every row to rank 0, which alone writes the run folder (for an --out only "
               "rank 0's node can reach; by default each rank writes its own rows when every "
               "rank sees the folder)");
  app.add_flag("-q,--quiet", o.quiet, "Only warnings and errors");
  // Hidden debugging and test options (an empty group hides them from --help).
  app.add_option("--fail-after-jobs", o.fail_after_jobs)->group("");
  app.add_option("--fail-rank", o.fail_rank)->group("");
  app.add_option("--fail-mode", o.fail_mode)->check(CLI::IsMember({"exit", "hang"}))->group("");
  app.add_option("--fail-in", o.fail_in)
      ->check(CLI::IsMember({"finalize", "transpose", "write"}))
      ->group("");
  app.add_option("--debug-item-seconds", o.debug_item_seconds)
      ->check(CLI::Range(0.0, 3600.0))
      ->group("");
  app.add_option("--debug-item-cost-skew", o.debug_item_cost_skew)
      ->check(CLI::Range(1.0, 1e6))
      ->group("");
  app.add_option("--debug-slow-rank", o.debug_slow_rank)->group("");
  app.add_option("--debug-slow-factor", o.debug_slow_factor)
      ->check(CLI::Range(1.0, 1e6))
      ->group("");
  app.add_option("--initial-job-rows", o.initial_job_rows)->group("");
  app.add_option("--max-job-rows", o.max_job_rows)->group("");
  app.add_flag("--no-compress", o.no_compress,
               "Stop after transport.prtt (no compressed transport.prtc)");
  bool keep_raw = false;
  app.add_flag("--keep-raw", keep_raw,
               "Keep transport.prtt (packed, ~1/4 of its float32 size) next to transport.prtc: "
               "the default; accepted for older scripts");
  app.add_flag("--discard-raw", o.discard_raw,
               "Remove transport.prtt once transport.prtc is written (a later change of the "
               "compression settings then traces again)");
  app.add_option("--memory-budget", o.memory_budget_bytes,
                 "Row data each rank buffers in the blocked transpose before spilling to disk "
                 "(bytes; suffixes k, M, G = 2^10, 2^20, 2^30)")
      ->transform(CLI::AsSizeValue(false))
      ->check(CLI::Validator(
          [](const std::string& value) -> std::string {
            // After the size transform: plain bytes. A tiny budget spills every block (the
            // tests force spilling with 2k); zero leaves nothing for the transpose at all.
            return std::stoull(value) == 0 ? "must be at least 1 byte, got 0" : std::string();
          },
          "BYTES>0"))
      ->capture_default_str();
  app.add_option("--compression-scheme", o.compression_scheme,
                 "Override the scene's [compression] scheme")
      ->check(CLI::IsMember({"2d", "4d", "adaptive4d", "cpca"}));
  app.add_flag("--measure-bandwidth", o.measure_bandwidth)->group("");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e, out, err);
    return code == 0 ? kExitOk : kExitUsage;
  }
  o.coordinator_works = !coordinator_only;
  if (keep_raw && o.discard_raw) {
    err << "prt-farm: --keep-raw and --discard-raw contradict each other\n";
    return kExitUsage;
  }
  if (o.resume && o.force) {
    err << "prt-farm: --resume and --force contradict each other\n";
    return kExitUsage;
  }
  return -1;
}

}  // namespace prt
