// Options of prt-farm (docs/farm.md) and its documented exit codes. No MPI in this header.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace prt {

// Exit codes of prt-farm (docs/farm.md). mpirun returns the code of the first rank that failed.
enum FarmExitCode : int {
  kExitOk = 0,
  kExitUsage = 1,       // bad command line, or a run folder that needs --resume or --force
  kExitBadInput = 2,    // missing or invalid scene/mesh, checkpoints of a different run
  kExitIoError = 3,     // the run folder cannot be created, written or synced
  kExitRankFailed = 4,  // a rank died, hung past --rank-timeout, or hit an internal error
};

// A command line that is well-formed for CLI11 but cannot be honoured (exit code 1).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A rank that died, hung or reported an error (exit code 4).
class RankFailure : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FarmOptions {
  std::string scene_path;  // empty: the embedded default scene
  std::string out_dir = "run";
  std::vector<std::string> data_dirs;  // extra folders for relative mesh paths
  int threads = 0;                     // TBB threads per rank; 0: cores / ranks on the node
  bool resume = false;                 // continue from run/checkpoints (fresh if none)
  bool force = false;                  // discard an existing run in out_dir
  std::string method;                  // empty: the scene's [sampling] method
  std::string job;                     // empty: the scene's [sampling] job (transport|visibility)
  int rays_per_texel = 0;              // 0: the scene's value
  std::optional<uint64_t> seed;        // unset: the scene's [sampling] seed
  std::optional<int> bounces;          // unset: the scene's [sampling] bounces
  double job_seconds = 4.0;            // target wall time of one job
  uint32_t rows_per_block = 256;       // rows per checksummed block of transport.prtt
  double log_interval_s = 5.0;         // progress line interval on rank 0
  double rank_timeout_s = 0;           // 0: auto (max(300 s, 50 × job_seconds))
  bool coordinator_works = true;       // rank 0 also computes jobs on a worker thread
  // Every row travels to rank 0, which writes it (a run folder only rank 0 can reach). By default
  // the ranks write and read their rows in the run folder themselves when every rank sees it
  // (docs/farm.md, "Where the rows go").
  bool rows_via_rank0 = false;
  bool quiet = false;  // warnings and errors only

  // Hidden, for tests and debugging.
  int fail_after_jobs = -1;  // the rank fail_rank dies after this many jobs
  int fail_rank = 0;
  std::string fail_mode = "exit";  // exit: _Exit(4) abruptly; hang: sleep forever
  // The rank fail_rank exits abruptly (_Exit(4)) at a point after sampling: "finalize" (rank 0,
  // transport.prtt complete but not yet renamed), "transpose" (when its second chunk of rows
  // arrives in the compression's transpose), "write" (rank 0, halfway through writing
  // transport.prtc's temporary file). Empty: never.
  std::string fail_in;
  // Synthetic job costs for the job loop's tests (farm/job_loop.cpp, tests/job_loop_mpi_test.cpp):
  // every job sleeps debug_item_seconds per item on top of its computation; items in the second
  // half of a batch cost debug_item_cost_skew times as much (a cost model wrong by that
  // factor); and the rank debug_slow_rank takes debug_slow_factor times as long for every job
  // (a throttled rank). The sleeps count as the job's busy time.
  double debug_item_seconds = 0;
  double debug_item_cost_skew = 1;
  int debug_slow_rank = -1;
  double debug_slow_factor = 1;
  uint64_t initial_job_rows = 0;  // 0: auto
  uint64_t max_job_rows = 0;      // 0: auto (a job's rows fit in 256 MiB)

  // Compression phase (farm/compression_phase.h, docs/farm-compression.md).
  bool no_compress = false;  // stop after transport.prtt
  // Remove transport.prtt once transport.prtc is written (by default it stays, packed, so that
  // other compression settings or environments need no tracing: docs/farm.md, "Disk").
  bool discard_raw = false;
  uint64_t memory_budget_bytes = 1ull << 30;  // per rank, for the blocked transpose
  std::string compression_scheme;             // empty: the scene's [compression] scheme
  bool measure_bandwidth = false;             // hidden: memcpy and disk bandwidth in the report
};

// Parses argv. Returns the exit code to leave with immediately (0 after --help/--version, 1 on a
// usage error, having printed to `out`/`err`), or -1 when the farm should run.
int ParseFarmCommandLine(int argc, char** argv, FarmOptions& options, std::ostream& out,
                         std::ostream& err);

std::string FarmVersion();

}  // namespace prt
