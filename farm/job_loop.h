// THE job loop of prt-farm (docs/farm.md, "Job queue"; docs/architecture.md): every phase that
// hands out work (brute force, the sparse method's sub-phases, the visibility job) supplies its
// jobs and what to do with a result; this loop owns everything else: the workers' slots, rank 0's
// own worker thread, sends in the background, adaptive job sizes (JobPlanner, in units of the
// batch's item cost), the journal commits, progress with an ETA, --rank-timeout and failure
// injection.
//
// Wire protocol (MPI_COMM_WORLD, tags in job_loop.cpp): a worker sends READY once per phase;
// rank 0 sends jobs, each one message [envelope: batch, first, count, batch items][payload]; the
// worker answers each with one message [envelope: batch, first, count, busy seconds][payload], or
// with a FAILED message naming its error; rank 0 ends the phase with STOP. A worker holds up to
// `jobs_ahead` jobs, so that it never waits for rank 0 to encode its next one.
// A worker computes on a thread of its own while its main thread (the only one calling MPI:
// MPI_THREAD_FUNNELED) sends rank 0 an ALIVE message [envelope: batch, first, count, seconds
// computing so far] every min(5 s, --rank-timeout / 4). --rank-timeout is therefore how long a
// rank with jobs out may stay silent (no READY, result or ALIVE), not how long a job may take: a
// slow job on a loaded machine is told apart from a dead or hung rank. Rank 0's own worker thread
// is never timed out (it is in rank 0's process), and rank 0's progress line keeps ticking every
// --log-interval while jobs are out, naming the longest one.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "farm/checkpoint_journal.h"
#include "farm/farm_context.h"
#include "farm/job_planner.h"

namespace prt {

// A job's result (brute rows, encoded visibility maps) fits in 256 MiB: one MPI message, far below
// the 2 GiB an MPI count can address. Phases size their largest job from it.
inline constexpr uint64_t kMaxJobBytes = uint64_t{256} << 20;

// Computes one job on any computing rank (rank 0's worker thread included): the items `range`
// of the current batch, with the payload rank 0's make_job encoded. Appends the result's payload
// to `out` (which already holds the envelope's bytes). Throws on failure: the worker reports the
// message to rank 0, which stops the run.
using JobCompute =
    std::function<void(const RowRange& range, std::string_view payload, std::string& out)>;

// One batch of jobs: items [0, items) of a deterministic list, cut into jobs by a JobPlanner.
struct JobBatch {
  std::string name;  // progress lines; a phase's journal lines use it too
  uint64_t items = 0;
  std::vector<RowRange> done;      // ranges finished before (verified checkpoints)
  std::string unit = "samples";    // progress: what an item is
  std::string rate_unit = "rays";  // progress: what the rate counts ("" for none)
  uint64_t max_items = 1;          // per job
  std::size_t jobs_ahead = 1;      // jobs a rank holds at once
  // The relative cost of a range of items (farm/job_planner.h, ItemCost): jobs are cut to
  // --job-seconds of cost at each rank's measured seconds per unit, so that cheap items (an image's
  // background pixels) and dear ones (pixels that see the model) make jobs of similar duration.
  // Empty: every item costs 1.
  ItemCost cost;
  // Results become durable (sync, then their journal lines) at most this often while jobs are
  // out, and always when none is (0: after every pass over the incoming messages).
  double commit_interval_s = 0;

  // Rank 0: appends the payload of the job for `range` to `message` (which holds the envelope;
  // an encoder that builds on it copies no byte); may lower range.count (the rest is handed out
  // again). Empty: no payload (the range says it all).
  std::function<void(RowRange& range, std::string& message)> make_job;
  // Rank 0: checks and stores the result of `range` from `rank`, and returns the journal line
  // for it (rows, checksum, counters; the loop fills in rank and busy_seconds). Throws
  // RankFailure for a result that does not fit its job.
  std::function<JournalEntry(int rank, const RowRange& range, std::string_view payload)> accept;
  // Rank 0: makes what accept stored durable, before the journal lines that count it.
  std::function<void()> sync;
  // Rank 0: the phase's report bookkeeping for a job once its journal line is durable.
  std::function<void(const JournalEntry&)> committed;
};

// Rank 0's side of a phase's jobs: the slots of the worker ranks and of its own worker thread.
class JobLoop {
 public:
  JobLoop(FarmContext& ctx, JobCompute compute);
  ~JobLoop();
  JobLoop(const JobLoop&) = delete;
  JobLoop& operator=(const JobLoop&) = delete;

  // Runs every job of the batch; returns when all are journaled.
  void Run(JobBatch& batch);
  // Ends the phase: every worker gets STOP (its READY is received first if it never got a job).
  void Finish();

 private:
  struct State;
  class BatchRun;  // one Run(batch): farm/job_loop.cpp
  std::unique_ptr<State> s_;
};

// A phase's jobs on every rank: rank 0 runs `coordinate` on a JobLoop (which it then finishes),
// every other rank computes the jobs it is sent until STOP.
void RunJobPhase(FarmContext& ctx, const JobCompute& compute,
                 const std::function<void(JobLoop&)>& coordinate);

// JobBatch::cost for a batch whose items are the run's samples in order (ctx.samples): a
// background pixel of an image run (SpatialSample::background: a zero row, nothing traced) costs
// kBackgroundSampleCost of a sample on a surface, so that the job that reaches the model after
// rows of sky is not sized from the sky's rate (issue 37). Empty (every sample alike) when no
// sample is background.
inline constexpr double kBackgroundSampleCost = 1e-3;
ItemCost SampleCost(const FarmContext& ctx);

// The JobSizing of a batch: --job-seconds, the computing ranks, --max-job-rows or `max_items`,
// --initial-job-rows or 4 per thread.
JobSizing BatchSizing(const FarmContext& ctx, uint64_t max_items);

}  // namespace prt
