// The job loop every phase of prt-farm runs its jobs on (see job_loop.h and docs/farm.md).
#include "farm/job_loop.h"

#include <mpi.h>
#include <spdlog/spdlog.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>

#include "farm/mpi_support.h"
#include "farm/progress.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

// CPU seconds of the calling thread (rank 0's main thread: the coordinator's own cost).
double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

enum Tag : int {
  kTagReady = 1,
  kTagJob,
  kTagStop,
  kTagResult,
  kTagFailed,
  kTagAlive,  // a worker's heartbeat while it computes (the envelope of its job)
};

struct ReadyMsg {
  int32_t threads = 0;
  char host[64] = {};
};

// The fixed start of every job, result and heartbeat message (the batch is echoed back, so that a
// result of another batch is recognised).
struct JobEnvelope {
  uint32_t batch = 0;
  uint32_t reserved = 0;
  uint64_t first = 0;
  uint64_t count = 0;
  double busy_seconds = 0;   // results: the worker's time computing the job; ALIVE: so far
  uint64_t batch_items = 0;  // jobs: the batch's items (for --debug-item-cost-skew)
};
static_assert(sizeof(JobEnvelope) == 40, "JobEnvelope travels as bytes");

// `from`: the rank a result came from, or -1 for a job from rank 0; named only on failure.
JobEnvelope PeekEnvelope(const std::string& message, int from) {
  if (message.size() < sizeof(JobEnvelope))
    throw RankFailure((from < 0 ? std::string("a job from rank 0")
                                : "a result from rank " + std::to_string(from)) +
                      " is shorter than its envelope (" + std::to_string(message.size()) +
                      " bytes)");
  JobEnvelope e;
  std::memcpy(&e, message.data(), sizeof e);
  return e;
}

std::string_view PayloadOf(const std::string& message) {
  return std::string_view(message).substr(sizeof(JobEnvelope));
}

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

// Receives the probed message into `into` (resized; its capacity is reused between messages).
void ReceiveBytes(MPI_Comm comm, const MPI_Status& st, std::string& into, const std::string& what) {
  int len = 0;
  MPI_Get_count(&st, MPI_BYTE, &len);
  into.resize(static_cast<std::size_t>(std::max(0, len)));
  CheckMpi(MPI_Recv(into.data(), len, MPI_BYTE, st.MPI_SOURCE, st.MPI_TAG, comm, MPI_STATUS_IGNORE),
           what);
}

// Messages sent with MPI_Isend whose buffers must live until the send completes, oldest first
// (a deque keeps its elements in place, so a buffer never moves while MPI holds it).
class BackgroundSends {
 public:
  void Send(std::string bytes, int dest, int tag, MPI_Comm comm, const std::string& what) {
    if (bytes.size() > static_cast<std::size_t>(INT_MAX))
      throw RankFailure(what + ": a message of " + std::to_string(bytes.size()) +
                        " bytes exceeds 2 GiB; lower --job-seconds or --max-job-rows");
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

// One computed job: the whole result message (envelope filled in) or the error.
struct ComputedJob {
  std::string message;
  std::exception_ptr error;
};

// The hidden --debug-item-seconds, --debug-item-cost-skew, --debug-slow-rank/--debug-slow-factor
// (farm/farm_options.h) on this rank: synthetic costs that the tests of the job loop give a
// phase, slept inside the job so that they count as its busy time.
struct DebugCost {
  double item_seconds = 0;
  double skew = 1;
  double slow = 1;

  explicit DebugCost(const FarmContext& ctx)
      : item_seconds(ctx.options.debug_item_seconds),
        skew(ctx.options.debug_item_cost_skew),
        slow(ctx.rank == ctx.options.debug_slow_rank ? ctx.options.debug_slow_factor : 1.0) {}
  // Seconds to sleep after a job of `job` whose computation took `computed` seconds: each item
  // costs its share of `computed` plus item_seconds, items in the batch's second half `skew`
  // times that, and the whole job `slow` times.
  double ExtraSeconds(const JobEnvelope& job, double computed) const {
    if (item_seconds <= 0 && skew == 1 && slow == 1) return 0;
    if (job.count == 0) return 0;
    const double per_item = computed / static_cast<double>(job.count) + item_seconds;
    const uint64_t half = job.batch_items / 2;
    const uint64_t end = job.first + job.count;
    const uint64_t dear = end > half ? end - std::max(job.first, half) : 0;
    const double cost =
        per_item * (static_cast<double>(job.count - dear) + skew * static_cast<double>(dear));
    return std::max(0.0, slow * cost - computed);
  }
};

// Computes a job into a result message: envelope first, then compute's payload.
ComputedJob ComputeJob(const JobCompute& compute, const DebugCost& debug, const JobEnvelope& job,
                       std::string_view payload) {
  ComputedJob r;
  r.message.resize(sizeof(JobEnvelope));
  const double t0 = FarmNow();
  compute({job.first, job.count}, payload, r.message);
  const double extra = debug.ExtraSeconds(job, FarmNow() - t0);
  if (extra > 0) std::this_thread::sleep_for(std::chrono::duration<double>(extra));
  JobEnvelope e = job;
  e.busy_seconds = FarmNow() - t0;
  e.batch_items = 0;
  std::memcpy(r.message.data(), &e, sizeof e);
  return r;
}

// A computing rank's worker thread: takes one job at a time from the rank's main thread, which
// alone calls MPI, computes it (an exception is carried in the result) and queues the result.
// Rank 0's own worker thread (when rank 0 computes), and on every other rank the thread that
// computes while the main thread keeps talking to rank 0 (heartbeats, sends in the background).
class LocalWorker {
 public:
  LocalWorker(JobCompute compute, DebugCost debug)
      : compute_(std::move(compute)), debug_(debug), thread_([this] { Loop(); }) {}
  ~LocalWorker() {
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }

  // Queues a job message (envelope and payload; the worker takes them in order).
  void Give(JobEnvelope job, std::string message) {
    {
      std::lock_guard lock(mutex_);
      jobs_.push_back({job, std::move(message)});
    }
    cv_.notify_all();
  }
  std::optional<ComputedJob> Poll() {
    std::lock_guard lock(mutex_);
    if (results_.empty()) return std::nullopt;
    ComputedJob r = std::move(results_.front());
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
      std::pair<JobEnvelope, std::string> job;
      {
        std::unique_lock lock(mutex_);
        cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      ComputedJob r;
      try {
        r = ComputeJob(compute_, debug_, job.first, PayloadOf(job.second));
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

  JobCompute compute_;
  DebugCost debug_;
  std::mutex mutex_;
  std::condition_variable cv_, cv_done_;
  std::deque<std::pair<JobEnvelope, std::string>> jobs_;
  std::deque<ComputedJob> results_;
  bool stop_ = false;
  std::thread thread_;  // last: starts after every other member exists
};

// --fail-after-jobs K on rank 0: when several finished jobs are committed together, journal only
// those up to the K-th, so that the kill lands after exactly K journaled jobs.
void KeepJobsBeforeFailure(const FarmContext& ctx, int jobs_so_far,
                           std::vector<JournalEntry>& pending) {
  if (ctx.options.fail_after_jobs < 0 || ctx.rank != ctx.options.fail_rank) return;
  const int left = std::max(0, ctx.options.fail_after_jobs - jobs_so_far);
  if (pending.size() > static_cast<std::size_t>(left))
    pending.resize(static_cast<std::size_t>(left));
}

// How often a worker tells rank 0 it is alive while it computes: often enough that rank 0 hears
// from it several times per --rank-timeout, and at least every 5 s.
double HeartbeatSeconds(const FarmContext& ctx) {
  return std::min(5.0, 0.25 * ctx.rank_timeout());
}

// A worker rank (1..N−1): READY, then jobs until STOP. The jobs are computed on a worker thread
// while this (main, MPI) thread sends rank 0 a heartbeat every HeartbeatSeconds and moves the
// background sends along.
void ServeJobs(FarmContext& ctx, const JobCompute& compute) {
  ReadyMsg ready;
  ready.threads = ctx.threads;
  std::snprintf(ready.host, sizeof ready.host, "%s", ctx.host.c_str());
  CheckMpi(MPI_Send(&ready, sizeof ready, MPI_BYTE, 0, kTagReady, ctx.comm), "MPI_Send ready");
  const double beat = HeartbeatSeconds(ctx);
  int jobs = 0;
  std::string message;
  BackgroundSends sending;  // results and heartbeats on their way
  LocalWorker worker(compute, DebugCost(ctx));
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
    if (st.MPI_TAG != kTagJob)
      throw RankFailure("unexpected message tag " + std::to_string(st.MPI_TAG) + " from rank 0");
    ReceiveBytes(ctx.comm, st, message, "MPI_Recv job");
    const JobEnvelope job = PeekEnvelope(message, -1);
    if (FailureDue(ctx, jobs)) InjectFailure(ctx, jobs);
    const double started = FarmNow();
    double last_beat = started;
    worker.Give(job, std::move(message));
    std::optional<ComputedJob> result;
    while (!(result = worker.Poll())) {
      // Wakes at least every 50 ms to move large sends along (MPI progresses only in MPI calls).
      worker.Wait(std::clamp(last_beat + beat - FarmNow(), 0.001, 0.05));
      sending.Retire();
      if (FarmNow() - last_beat >= beat) {
        JobEnvelope alive = job;
        alive.busy_seconds = FarmNow() - started;
        std::string bytes(sizeof alive, '\0');
        std::memcpy(bytes.data(), &alive, sizeof alive);
        sending.Send(std::move(bytes), 0, kTagAlive, ctx.comm, "MPI_Isend heartbeat");
        last_beat = FarmNow();
      }
    }
    if (result->error) {
      std::string what = "unknown error";
      try {
        std::rethrow_exception(result->error);
      } catch (const std::exception& e) {
        what = e.what();
      } catch (...) {
      }
      // Tell rank 0 (which writes the report and aborts the job), then wait to be killed.
      spdlog::error("rank {}: {}", ctx.rank, what);
      MPI_Send(what.data(), static_cast<int>(what.size()), MPI_CHAR, 0, kTagFailed, ctx.comm);
      MPI_Recv(nullptr, 0, MPI_BYTE, 0, kTagStop, ctx.comm, MPI_STATUS_IGNORE);
      throw CollectiveStop{kExitRankFailed};
    }
    // Sent in the background while the next job is received and computed: a blocking send of
    // a large result spins until rank 0 gets round to receiving it, on a core rank 0's threads
    // may need.
    sending.Send(std::move(result->message), 0, kTagResult, ctx.comm, "MPI_Isend result");
    ++jobs;
  }
}

}  // namespace

struct JobLoop::State {
  struct OutJob {
    RowRange range;
    double started = 0;  // when the rank began it (given to an idle rank, or its previous returned)
    double planned = -1;  // seconds the planner expected (−1: the rank's rate not yet measured)
  };
  struct Slot {
    int rank = 0;
    bool local = false;
    bool ready = false;
    std::deque<OutJob> jobs;  // given to the rank and not returned, oldest first
    // When rank 0 last heard from the rank (READY, a result, a heartbeat), or gave it work while
    // it had none: --rank-timeout counts from here.
    double heard = 0;
    BackgroundSends sends;  // remote ranks: the encoded jobs on their way
  };

  FarmContext& ctx;
  std::deque<Slot> slots;  // a deque: a Slot (holding MPI requests) never moves
  std::unique_ptr<LocalWorker> local;
  uint32_t batch_number = 0;
  int jobs_this_run = 0;
  std::string incoming;  // the receive buffer, reused

  explicit State(FarmContext& c) : ctx(c) {}

  Slot& SlotOf(int rank) {
    for (Slot& s : slots)
      if (s.rank == rank) return s;
    throw RankFailure("a message from rank " + std::to_string(rank) + ", which has no slot");
  }

  // A message from `s`'s rank arrived now.
  void Heard(Slot& s, double now) {
    if (!s.jobs.empty()) {
      double& longest = ctx.report.job_times.longest_silence_seconds;
      longest = std::max(longest, now - s.heard);
    }
    s.heard = now;
  }

  void MarkReady(int src, const ReadyMsg& ready_msg) {
    ReadyMsg ready = ready_msg;
    ready.host[sizeof ready.host - 1] = '\0';
    ctx.report.rank_reports[src].threads = ready.threads;
    ctx.report.rank_reports[src].host = ready.host;
  }

  // " | longest job out: rank 1, brute items 40..79 for 12.5s (planned 4.0s)" when a job has been
  // out longer than `at_least` seconds, else "": rank 0's progress line names a slow job while
  // no result comes in.
  std::string LongestOut(const std::string& batch, double now, double at_least) const {
    const Slot* slowest = nullptr;
    for (const Slot& s : slots)
      if (!s.jobs.empty() && (!slowest || s.jobs.front().started < slowest->jobs.front().started))
        slowest = &s;
    if (!slowest || now - slowest->jobs.front().started < at_least) return "";
    const OutJob& j = slowest->jobs.front();
    std::string line = " | longest job out: rank " + std::to_string(slowest->rank) + ", " + batch +
                       " items " + std::to_string(j.range.first) + ".." +
                       std::to_string(j.range.end() - 1) + " for " +
                       Progress::FormatDuration(now - j.started);
    if (j.planned >= 0) line += " (planned " + Progress::FormatDuration(j.planned) + ")";
    if (!slowest->local)
      line += ", heard " + Progress::FormatDuration(now - slowest->heard) + " ago";
    return line;
  }
};

JobLoop::JobLoop(FarmContext& ctx, JobCompute compute) : s_(std::make_unique<State>(ctx)) {
  const double start = FarmNow();
  for (int r = 1; r < ctx.size; ++r) {
    State::Slot& s = s_->slots.emplace_back();
    s.rank = r;
    s.heard = start;
  }
  if (ctx.computes_here()) {
    State::Slot& s = s_->slots.emplace_back();
    s.rank = 0;
    s.local = true;
    s.ready = true;
    s.heard = start;
    s_->local = std::make_unique<LocalWorker>(std::move(compute), DebugCost(ctx));
  }
  RankReport& r0 = ctx.report.rank_reports[0];
  r0.threads = ctx.threads;
  r0.host = ctx.host;
  r0.computes = ctx.computes_here();
  ctx.report.job_times.target_seconds = ctx.options.job_seconds;
  if (FailureDue(ctx, 0)) InjectFailure(ctx, 0);
}

JobLoop::~JobLoop() = default;

// One Run(batch) on rank 0: the batch's planner, progress, pending journal lines and traffic, and
// the steps of its loop (hand out jobs, take results, check silence, commit), each a method.
class JobLoop::BatchRun {
 public:
  BatchRun(State& st, JobBatch& batch)
      : st_(st),
        ctx_(st.ctx),
        batch_(batch),
        planner_(batch.items, batch.done, Sizing(st.ctx, batch)),
        progress_(batch.name, batch.items, ProgressOptionsOf(st, batch, planner_)),
        timeout_(st.ctx.rank_timeout()),
        number_(st.batch_number),
        cpu0_(ThreadCpuSeconds()),
        wall0_(FarmNow()),
        last_commit_(FarmNow()) {
    traffic_.batch = batch.name;
    traffic_.items = batch.items - planner_.done_before_rows();
  }

  // Runs every job of the batch; returns when all are journaled.
  void Loop() {
    for (;;) {
      HandOut();
      if (!Outstanding() && pending_.empty() && planner_.unassigned_rows() == 0) {
        // Every job came back, so every send has left; complete the requests.
        for (State::Slot& s : st_.slots) s.sends.WaitAll();
        return;
      }
      bool busy = PollLocal();
      if (ReceiveMessages()) busy = true;
      CheckSilence();
      // Results become durable (fdatasync'ed, then their journal lines) every commit interval
      // and when no job is out. A failure-injection run commits every result, as its resume
      // tests count on.
      if (!Outstanding() || ctx_.options.fail_after_jobs >= 0 ||
          FarmNow() - last_commit_ >= batch_.commit_interval_s) {
        Commit();
        last_commit_ = FarmNow();
      }
      progress_.Advance(0);  // a line every --log-interval, also while no job finishes
      if (!busy) {
        if (st_.local) {
          st_.local->Wait(0.001);
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    }
  }

  // The batch's last progress line and its traffic in the report.
  void Finish() {
    progress_.Finish();
    ctx_.run_eta.StepFinished(batch_.name);
    traffic_.cpu_seconds = ThreadCpuSeconds() - cpu0_;
    traffic_.wall_seconds = FarmNow() - wall0_;
    if (ctx_.size > 1 && traffic_.jobs > 0) {
      spdlog::info(
          "[{}] rank 0 exchanged {:.1f} B per {} with the other ranks ({:.1f} MB in, {:.1f} MB "
          "out) and spent {:.2f} ms of CPU per job",
          batch_.name,
          static_cast<double>(traffic_.bytes_in + traffic_.bytes_out) /
              static_cast<double>(std::max<uint64_t>(1, traffic_.items)),
          batch_.unit == "samples" ? std::string("row")
          : !batch_.unit.empty() && batch_.unit.back() == 's'
              ? batch_.unit.substr(0, batch_.unit.size() - 1)
              : batch_.unit,
          1e-6 * static_cast<double>(traffic_.bytes_in),
          1e-6 * static_cast<double>(traffic_.bytes_out),
          1e3 * traffic_.cpu_seconds / static_cast<double>(traffic_.jobs));
    }
    ctx_.report.coordinator.push_back(std::move(traffic_));
    ++st_.batch_number;
  }

 private:
  static JobSizing Sizing(const FarmContext& ctx, const JobBatch& batch) {
    JobSizing sizing = BatchSizing(ctx, batch.max_items);
    sizing.cost = batch.cost;
    return sizing;
  }

  // The batch's progress options; also starts its step of the run's ETA. Every line also names
  // the job out longest once it has been out a log interval (the line comes every
  // --log-interval whether or not a job finished: Advance(0) in Loop).
  static ProgressOptions ProgressOptionsOf(State& st, const JobBatch& batch,
                                           const JobPlanner& planner) {
    FarmContext& ctx = st.ctx;
    ProgressOptions po = FarmProgressOptions(ctx, batch.unit);
    po.rate_unit = batch.rate_unit;
    po.already_done = planner.done_before_rows();
    const double log_interval = ctx.options.log_interval_s;
    std::function<std::string(double)> run_suffix = std::move(po.suffix);
    po.suffix = [&st, &batch, log_interval, run_suffix](double eta_s) {
      return (run_suffix ? run_suffix(eta_s) : std::string()) +
             st.LongestOut(batch.name, FarmNow(), std::max(1.0, log_interval));
    };
    ctx.run_eta.StepStarted(batch.name);
    return po;
  }

  bool Outstanding() const {
    return std::any_of(st_.slots.begin(), st_.slots.end(),
                       [](const State::Slot& s) { return !s.jobs.empty(); });
  }

  // Hands out work: every ready rank holds up to jobs_ahead jobs.
  void HandOut() {
    for (State::Slot& s : st_.slots) {
      s.sends.Retire();
      while (s.ready && s.jobs.size() < batch_.jobs_ahead) {
        const std::optional<RowRange> next = planner_.Next(s.rank);
        if (!next) break;
        RowRange range = *next;
        std::string message(sizeof(JobEnvelope), '\0');  // the envelope, filled in below
        if (batch_.make_job) batch_.make_job(range, message);
        if (range.count < next->count) planner_.Return({range.end(), next->count - range.count});
        const double now = FarmNow();
        if (s.jobs.empty()) s.heard = now;  // silence counts from when it has work
        s.jobs.push_back({range, now, planner_.PredictedSeconds(s.rank, range)});
        JobEnvelope e;
        e.batch = number_;
        e.first = range.first;
        e.count = range.count;
        e.batch_items = batch_.items;
        std::memcpy(message.data(), &e, sizeof e);
        ++traffic_.jobs;
        if (s.local) {
          st_.local->Give(e, std::move(message));
        } else {
          traffic_.bytes_out += message.size();
          s.sends.Send(std::move(message), s.rank, kTagJob, ctx_.comm,
                       "MPI_Isend job to rank " + std::to_string(s.rank));
        }
      }
    }
  }

  // Rank 0's own worker thread's finished jobs; true when there was one.
  bool PollLocal() {
    bool any = false;
    if (!st_.local) return any;
    while (std::optional<ComputedJob> r = st_.local->Poll()) {
      if (r->error) std::rethrow_exception(r->error);
      Accept(0, r->message);
      any = true;
    }
    return any;
  }

  // Every message waiting from the other ranks: READY, heartbeats, results, failures; true
  // when there was one.
  bool ReceiveMessages() {
    bool any = false;
    for (;;) {
      int flag = 0;
      MPI_Status ms;
      CheckMpi(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, ctx_.comm, &flag, &ms), "MPI_Iprobe");
      if (!flag) return any;
      any = true;
      const int src = ms.MPI_SOURCE;
      if (ms.MPI_TAG == kTagReady) {
        ReadyMsg ready;
        CheckMpi(
            MPI_Recv(&ready, sizeof ready, MPI_BYTE, src, kTagReady, ctx_.comm, MPI_STATUS_IGNORE),
            "MPI_Recv ready");
        st_.MarkReady(src, ready);
        State::Slot& s = st_.SlotOf(src);
        s.ready = true;
        st_.Heard(s, FarmNow());
      } else if (ms.MPI_TAG == kTagAlive) {
        // A worker still computing: only the silence timer cares (the envelope says which job
        // and for how long, which the progress line's own clock already shows).
        ReceiveBytes(ctx_.comm, ms, st_.incoming,
                     "MPI_Recv heartbeat from rank " + std::to_string(src));
        st_.Heard(st_.SlotOf(src), FarmNow());
      } else if (ms.MPI_TAG == kTagResult) {
        ReceiveBytes(ctx_.comm, ms, st_.incoming,
                     "MPI_Recv result from rank " + std::to_string(src));
        traffic_.bytes_in += st_.incoming.size();
        st_.Heard(st_.SlotOf(src), FarmNow());
        Accept(src, st_.incoming);
      } else if (ms.MPI_TAG == kTagFailed) {
        std::string message;
        ReceiveBytes(ctx_.comm, ms, message, "MPI_Recv failure of rank " + std::to_string(src));
        throw RankFailure("rank " + std::to_string(src) + " failed: " + message);
      } else {
        throw RankFailure("unexpected message tag " + std::to_string(ms.MPI_TAG) + " from rank " +
                          std::to_string(src));
      }
    }
  }

  // A finished job: stored by the phase now, counted once the journal has it (Commit).
  void Accept(int rank, const std::string& message) {
    State::Slot& s = st_.SlotOf(rank);
    const JobEnvelope e = PeekEnvelope(message, rank);
    if (s.jobs.empty() || e.batch != number_ || s.jobs.front().range.first != e.first ||
        s.jobs.front().range.count != e.count) {
      throw RankFailure("rank " + std::to_string(rank) + " returned " + batch_.name + " items " +
                        std::to_string(e.first) + "+" + std::to_string(e.count) +
                        " it was not given");
    }
    const State::OutJob job = s.jobs.front();
    JournalEntry line = batch_.accept(rank, job.range, PayloadOf(message));
    line.rank = rank;
    line.busy_seconds = e.busy_seconds;
    pending_.push_back(std::move(line));
    planner_.Measured(rank, job.range, e.busy_seconds);
    s.jobs.pop_front();
    if (!s.jobs.empty()) s.jobs.front().started = FarmNow();
    RecordJobTime(rank, job, e.busy_seconds);
  }

  // report.json "job_times", and a log line for a job far over its plan.
  void RecordJobTime(int rank, const State::OutJob& job, double busy_seconds) {
    FarmReport& rep = ctx_.report;
    JobTimesReport& times = rep.job_times;
    ++times.jobs;
    if (busy_seconds > 4.0 * ctx_.options.job_seconds) ++times.over_4x_target;
    if (job.planned >= 0 && busy_seconds > 4.0 * job.planned) ++times.over_4x_planned;
    if (times.longest_by_rank.size() < rep.rank_reports.size())
      times.longest_by_rank.resize(rep.rank_reports.size(), 0.0);
    double& longest = times.longest_by_rank[static_cast<std::size_t>(rank)];
    longest = std::max(longest, busy_seconds);
    if (busy_seconds > times.longest_seconds) {
      times.longest_seconds = busy_seconds;
      times.longest_planned_seconds = job.planned;
      times.longest_batch = batch_.name;
      times.longest_rank = rank;
      times.longest_first = job.range.first;
      times.longest_count = job.range.count;
    }
    // Far over its plan: its items were dearer than the batch's cost model says; the planner
    // takes the rank's rate from this job at once, so its next job is small.
    if (job.planned >= 0 && busy_seconds > 4.0 * std::max(job.planned, ctx_.options.job_seconds))
      spdlog::info(
          "[{}] rank {}'s job (items {}..{}) took {}, planned {}; its next jobs are cut "
          "from this rate",
          batch_.name, rank, job.range.first, job.range.end() - 1,
          Progress::FormatDuration(busy_seconds), Progress::FormatDuration(job.planned));
  }

  // The accepted results made durable, then their journal lines, then counted.
  void Commit() {
    if (pending_.empty()) return;
    FarmReport& rep = ctx_.report;
    KeepJobsBeforeFailure(ctx_, st_.jobs_this_run, pending_);
    if (batch_.sync) batch_.sync();  // results durable first,
    ctx_.journal->Append(pending_);  // then the journal lines that count them
    for (const JournalEntry& e : pending_) {
      RankReport& rr = rep.rank_reports[e.rank];
      ++rr.jobs;
      rr.rows += e.rows.count;
      rr.rays_traced += e.rays_traced;
      rr.busy_seconds += e.busy_seconds;
      ++rep.jobs_done;
      if (batch_.committed) batch_.committed(e);
      progress_.Advance(e.rows.count, e.rays_traced);
      ++st_.jobs_this_run;
    }
    pending_.clear();
    if (FailureDue(ctx_, st_.jobs_this_run)) InjectFailure(ctx_, st_.jobs_this_run);
  }

  // A rank that neither answers nor dies (mpirun aborts the job when one dies) must not keep
  // rank 0 waiting forever. Checked right after every waiting message was received, so that
  // time rank 0 itself spent elsewhere (a slow sync) does not count as the rank's silence. A
  // worker computing a long job sends heartbeats: only silence counts, not the job's length.
  // Rank 0's own worker thread is never timed out: it lives in this process, and a slow job
  // there is just slow (issue 37: a 6.7-minute job of rank 0 ended a good run).
  void CheckSilence() const {
    const double now = FarmNow();
    for (const State::Slot& s : st_.slots) {
      if (s.local || (s.ready && s.jobs.empty()) || now - s.heard <= timeout_) continue;
      const std::string what = !s.ready ? std::string(" never reported ready")
                                        : " has not returned its job (" + batch_.name + " items " +
                                              std::to_string(s.jobs.front().range.first) + ".." +
                                              std::to_string(s.jobs.front().range.end() - 1) +
                                              ") and has been silent";
      throw RankFailure("rank " + std::to_string(s.rank) + what + " for " +
                        std::to_string(static_cast<int>(now - s.heard)) +
                        " s (--rank-timeout: no result, no heartbeat); giving up");
    }
  }

  State& st_;
  FarmContext& ctx_;
  JobBatch& batch_;
  JobPlanner planner_;
  Progress progress_;
  const double timeout_;
  const uint32_t number_;
  CoordinatorReport traffic_;
  const double cpu0_, wall0_;
  double last_commit_;
  std::vector<JournalEntry> pending_;
};

void JobLoop::Run(JobBatch& batch) {
  BatchRun run(*s_, batch);
  run.Loop();
  run.Finish();
}

void JobLoop::Finish() {
  State& st = *s_;
  for (State::Slot& s : st.slots) {
    if (s.local) continue;
    if (!s.ready) {
      ReadyMsg ready;
      CheckMpi(MPI_Recv(&ready, sizeof ready, MPI_BYTE, s.rank, kTagReady, st.ctx.comm,
                        MPI_STATUS_IGNORE),
               "MPI_Recv ready");
      st.MarkReady(s.rank, ready);
      s.ready = true;
    }
    s.sends.WaitAll();
    CheckMpi(MPI_Send(nullptr, 0, MPI_BYTE, s.rank, kTagStop, st.ctx.comm),
             "MPI_Send stop to rank " + std::to_string(s.rank));
  }
  st.local.reset();
}

void RunJobPhase(FarmContext& ctx, const JobCompute& compute,
                 const std::function<void(JobLoop&)>& coordinate) {
  if (ctx.rank != 0) {
    ServeJobs(ctx, compute);
    return;
  }
  JobLoop loop(ctx, compute);
  coordinate(loop);
  loop.Finish();
}

ItemCost SampleCost(const FarmContext& ctx) {
  if (std::none_of(ctx.samples.begin(), ctx.samples.end(),
                   [](const SpatialSample& s) { return s.background; }))
    return {};
  std::vector<double> weights(ctx.samples.size());
  for (std::size_t i = 0; i < weights.size(); ++i)
    weights[i] = ctx.samples[i].background ? kBackgroundSampleCost : 1.0;
  return ItemCostOfWeights(weights);
}

JobSizing BatchSizing(const FarmContext& ctx, uint64_t max_items) {
  JobSizing sizing;
  sizing.job_seconds = ctx.options.job_seconds;
  sizing.workers = ctx.computing_ranks();
  sizing.max_rows =
      ctx.options.max_job_rows > 0 ? ctx.options.max_job_rows : std::max<uint64_t>(1, max_items);
  sizing.initial_rows = ctx.options.initial_job_rows > 0 ? ctx.options.initial_job_rows
                                                         : 4 * static_cast<uint64_t>(ctx.threads);
  return sizing;
}

}  // namespace prt
