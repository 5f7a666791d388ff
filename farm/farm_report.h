// run/report.json (docs/farm.md, "report.json"): what a run did and how long each phase took.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "farm/sparse_jobs.h"

namespace prt {

struct RankReport {
  int rank = 0;
  std::string host;
  int threads = 0;
  bool computes = true;  // false for a coordinator-only rank 0
  uint64_t jobs = 0;
  uint64_t rows = 0;
  uint64_t rays_traced = 0;
  double busy_seconds = 0;      // time inside the worker kernels
  uint64_t peak_rss_bytes = 0;  // the rank's peak resident memory over the whole run
};

// Rank 0's side of one batch of jobs (report.json "coordinator"; docs/farm.md, "Where the rows
// go"): the bytes of the job and result messages it exchanged with the other ranks, and the CPU
// time of its main thread (planning, encoding, accepting, journaling) while the batch ran.
struct CoordinatorReport {
  std::string batch;
  uint64_t items = 0;
  uint64_t jobs = 0;
  uint64_t bytes_in = 0;   // results received from other ranks
  uint64_t bytes_out = 0;  // jobs sent to other ranks
  double cpu_seconds = 0;
  double wall_seconds = 0;
};

struct PhaseReport {
  std::string name;
  double wall_seconds = 0;
};

// One stage of the run (farm/run_manifest.h): what happened to it and why.
struct StageReport {
  std::string name;    // rows, compression, estimate, assets
  std::string status;  // ran, resumed, reused, skipped
  std::string reason;  // why it ran or was skipped ("" when re-used)
  double wall_seconds = 0;
};

// The sparse method's figures (report.json "sparse"; docs/farm.md, "Sparse method").
struct SparsePhaseReport {
  std::string name;  // dense-initial, rank-1, dense-rank-1, …, sparse-reconstruct, dense-fallback
  double wall_seconds = 0;
  uint64_t items = 0;  // samples or candidates of the phase
  uint64_t jobs_reused = 0;
};

struct SparseFarmReport {
  bool enabled = false;
  std::vector<SparsePhaseReport> phases;
  uint64_t dense_initial = 0;
  uint64_t dense_by_rank = 0;
  uint64_t dense_fallback = 0;
  uint64_t candidates_ranked = 0;
  uint64_t dense_rows_shipped = 0;  // dense neighbour rows sent with sparse jobs (this run)
  double index_seconds = 0;         // building the neighbour indices on rank 0
  SparseJobCounters counters;       // over the whole matrix, re-used jobs included
  // The reconstruction's cross-validation (farm/sparse_phase.cpp CrossValidate): vertices
  // reconstructed and rays traced, not part of T.
  SparseJobCounters cross_validation;
  // Traced texels / texels above the horizon (what brute force would evaluate).
  double SampledFraction() const;
};

// The visibility job's figures (report.json "visibility"; docs/farm.md, "Visibility job").
struct VisibilityFarmReport {
  bool enabled = false;
  int n = 0;
  int supersample = 1;
  int bits = 1;
  uint64_t vertices = 0;
  uint64_t raw_bytes = 0;      // the maps as plain bitmaps: vertices · 6n² · bits / 8
  uint64_t encoded_bytes = 0;  // visibility.prtv
  uint64_t blocks_zero = 0, blocks_one = 0, blocks_mixed = 0, changes = 0;
};

// The compression phase's figures (report.json "compression"; docs/farm-compression.md).
struct CompressionFarmReport {
  bool enabled = false;  // the phase ran (not for --no-compress or the visibility job)
  double wall_seconds = 0;
  int ranks = 1;
  std::string scheme, row_wavelet, column_wavelet;
  int bits = 0;
  double keep_fraction = 0;
  uint64_t memory_budget_bytes = 0;
  uint64_t raw_bytes = 0;    // rows × cols × 4
  uint64_t bytes_moved = 0;  // between ranks, all ranks
  // Rank 0's own row traffic: rows it read from transport.prtt and row data it sent to other
  // ranks (the whole T when it reads and scatters; its share when every rank reads its own).
  bool every_rank_reads = false;
  uint64_t rank0_bytes_read = 0, rank0_bytes_sent = 0;
  uint64_t spill_bytes = 0;  // all ranks
  uint64_t spill_runs = 0;
  double transpose_seconds = 0;  // max over ranks of exchange + buffer + merge
  double read_seconds = 0, row_transform_seconds = 0, exchange_seconds = 0, buffer_seconds = 0,
         merge_seconds = 0, compress_seconds = 0, write_seconds = 0;  // max over ranks
  uint64_t compressed_bytes = 0;                                      // transport.prtc
  uint64_t terms = 0;
  uint64_t columns_stored = 0;
  bool raw_kept = true;
  // ‖T − T̃‖_F / ‖T‖_F with T̃ what transport.prtc decodes to: the exact error the compression
  // dropped (in the T̂ basis, equal to the texel basis's by the orthonormal row transform).
  double relative_frobenius_error = 0;
  // --measure-bandwidth (0 when not measured): memcpy and write+fsync in the run folder, MB/s.
  double memory_bandwidth_mb_s = 0;
  double disk_write_bandwidth_mb_s = 0;
  // Scheme cpca (farm/cpca_phase.h): report.json "compression"."cpca".
  struct Cpca {
    bool enabled = false;
    uint32_t clusters = 0, bases = 0;
    std::string method;  // standard | dense-recluster
    uint64_t rows_dense_pass = 0;
    int lbg_iterations = 0;
    uint64_t distance_evaluations = 0;  // all ranks
    uint32_t empty_clusters = 0;
    double seconds_dense = 0, seconds_recluster = 0;  // rank 0's
    uint64_t basis_terms = 0;                         // stored mean and basis terms
  } cpca;

  double TransposeMbPerSecond() const;  // raw_bytes / transpose_seconds
  double PhaseMbPerSecond() const;      // raw_bytes / wall_seconds
  double Ratio() const;                 // compressed_bytes / raw_bytes
};

// The whole run's ETA as it was predicted when each step started (farm/run_eta.h).
struct EtaReport {
  double elapsed_seconds = 0;
  std::string step;
  double predicted_total_seconds = 0;
};

// report.json "job_times" (farm/job_loop.cpp; docs/farm.md, "Jobs"): how long this run's jobs
// took against --job-seconds, its slowest job, and the longest a rank with a job out stayed
// silent (no result, no heartbeat) as rank 0 saw it.
struct JobTimesReport {
  double target_seconds = 0;  // --job-seconds
  uint64_t jobs = 0;
  uint64_t over_4x_target = 0;  // jobs whose busy time exceeded 4 × target_seconds
  // Jobs whose busy time exceeded 4 × what the planner expected of them (their items dearer
  // than the cost model said): after one such job a rank's next jobs are cut from its rate.
  uint64_t over_4x_planned = 0;
  double longest_seconds = 0;  // the slowest job's busy time
  std::string longest_batch;
  int longest_rank = -1;
  uint64_t longest_first = 0, longest_count = 0;
  double longest_planned_seconds = -1;  // what the planner expected of it (−1: a first job)
  double longest_silence_seconds = 0;   // the longest gap between messages of a busy rank
  std::vector<double> longest_by_rank;  // each rank's slowest job (seconds)
};

struct FarmReport {
  std::string status = "running";  // ok | failed | running
  int exit_code = 0;
  std::string error;
  std::string version;
  std::string scene;  // the scene file ("<default scene>" for the embedded one)
  std::string scene_name;
  std::string method;
  int ranks = 1;
  int cubemap_n = 0;
  int rays_per_texel = 0;
  uint64_t seed = 0;
  uint64_t rows = 0;
  uint64_t cols = 0;
  uint32_t rows_per_block = 0;
  uint64_t transport_bytes =
      0;  // transport.prtt as kept (packed); 0 when this run did not write it
  std::vector<PhaseReport> phases;
  std::vector<StageReport> stages;
  // Sections a phase writes from its own state (FarmPhase::Report), in the order they were set:
  // report.json key → JSON text ("interreflection" from the bounce phases, "image" from setup
  // on image runs, …).
  std::vector<std::pair<std::string, std::string>> sections;
  std::vector<EtaReport> eta;
  double wall_seconds = 0;
  double sampling_seconds = 0;  // wall time of the sampling phase (for rays/s)

  // This run only (jobs re-used from checkpoints are counted separately).
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
  // Including the re-used jobs' counters, i.e. the whole matrix.
  uint64_t rays_traced_all = 0;
  uint64_t texels_below_horizon_all = 0;

  uint64_t jobs_total = 0;  // done + reused
  uint64_t jobs_done = 0;
  uint64_t jobs_reused = 0;
  uint64_t rows_done = 0;
  uint64_t rows_reused = 0;
  int damaged_journal_lines = 0;
  uint64_t checkpoints_rejected = 0;  // journaled jobs whose rows did not verify

  std::vector<RankReport> rank_reports;
  // Whether the ranks wrote their rows themselves (FarmContext::rows_in_place), and rank 0's
  // traffic per batch of jobs.
  bool rows_in_place = false;
  std::vector<CoordinatorReport> coordinator;
  SparseFarmReport sparse;
  VisibilityFarmReport visibility;
  CompressionFarmReport compression;  // last in report.json
  // Sections of the report of the run this one continued, for the stages it re-used (a JSON
  // object: "compression", "sparse", …): written where this run has no section of its own.
  std::string carried_json;
  // accuracy.json of the estimate stage, as report.json "accuracy" ("" when there is none).
  std::string accuracy_json;
  JobTimesReport job_times;  // report.json "job_times", the last key

  // Sets (or replaces) a phase's section.
  void SetSection(const std::string& key, std::string json_text);
  // A section's JSON text ("" when no phase set it).
  std::string Section(const std::string& key) const;

  // max / mean busy time over the computing ranks (1 = perfect balance; 0 when none computed).
  double LoadImbalance() const;
  std::string ToJsonText() const;
};

}  // namespace prt
