// The sparse method (Huang & Ramamoorthi 2010 §4–5) on the job loop; docs/farm.md, "Sparse
// method". Its order of steps is the worker's one driver, RunSparseSchedule
// (worker/sparse_precomputation.h), the same the in-process RunSparsePrecomputation runs: here each
// step is a batch of jobs (farm/sparse_jobs.h) on the JobLoop. Rank 0 plans every step
// deterministically from the seed and the previous steps' durable results, so the transport file
// is bit-identical to the in-process one for any number of ranks and after any resume:
//   dense-initial       InitialDenseSet                        jobs: chunks of sample ids
//   rank-k              candidates of round k (NeighborIndex over the dense positions)
//                                                              jobs: chunks of candidates
//   dense-rank-k        SparsePickByRank, on rank 0 only       jobs: chunks of sample ids
//   sparse-reconstruct  non-dense samples in Morton order      jobs: chunks of that order
//   dense-fallback      the vertices whose reconstruction fell back
// Dense T rows and reconstructed rows go into transport.prtt.partial; dense visibility and
// feature rows into run/sparse/dense_aux.bin (5·texels bytes per sample, at the sample's offset:
// a sparse file) — written by the worker that computed them where every rank sees the run folder
// (FarmSparseRowFiles, with the downsampled rows in dense_low.bin and each step's lists in
// lists-<step>.bin; docs/farm.md, "Where the rows go"), else by rank 0 as they arrive. Candidate
// weights go into run/sparse/rank-k.bin (int32 per candidate), sparse outcomes into
// run/sparse/sparse_outcome.bin (a byte per Morton position), by rank 0. Every job is journaled
// after its results are durable ("sjob <step> …").
// This file holds the steps' shared driver (FarmSparseSteps::RunStep: one step as a batch of jobs
// with its checkpoints), the workers' files and the phase; the steps themselves are in
// sparse_dense_steps.cpp, sparse_reconstruct_step.cpp and sparse_cross_validation.cpp
// (farm/sparse_steps.h), the neighbour lists and compact jobs in farm/sparse_step_lists.h.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/side_file.h"
#include "farm/sparse_jobs.h"
#include "farm/sparse_steps.h"
#include "formats/transport_variance.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"
#include "worker/sparse_precomputation.h"

namespace prt {

namespace {

namespace fs = std::filesystem;

// Jobs a rank holds at once: the one it computes and the next, encoded and sent while it
// computes, so that it never waits for rank 0 to read its neighbours' rows (a 2-rank run's
// sparse-reconstruct workers were idle 45 % of the time; docs/farm.md).
constexpr std::size_t kJobsAhead = 2;
// Results become durable every 0.5 s and when no job is out: an fdatasync per result cost 2 s of
// a 27 s 2-rank run.
constexpr double kCommitIntervalSeconds = 0.5;

// The run's files as a worker's SparseRowFiles (docs/farm.md, "Where the rows go"): T rows in
// transport.prtt.partial, visibility and feature rows in sparse/dense_aux.bin, downsampled rows in
// sparse/dense_low.bin (6·m·m floats per sample at the sample's offset), variance records in the
// rank's own log. Opened by each computing rank at its first job.
class FarmSparseRowFiles final : public SparseRowFiles {
 public:
  explicit FarmSparseRowFiles(FarmContext& ctx)
      : T_(6ull * ctx.params.cubemap_n * ctx.params.cubemap_n),
        m_(SparseRankResolution(ctx.plan, ctx.params.cubemap_n)),
        rows_(TransportFileWriter::OpenRows(ctx.folder.partial, ctx.RowsFileInfo())),
        aux_((fs::path(ctx.folder.sparse) / "dense_aux.bin").string()),
        low_((fs::path(ctx.folder.sparse) / "dense_low.bin").string()),
        cross_path_((fs::path(ctx.folder.sparse) / "cross_validation.bin").string()) {
    if (!RowsStage(ctx).rank_variance) {
      RowsStage(ctx).rank_variance =
          std::make_unique<RankVarianceLog>(ctx.folder, ctx.rank, ctx.EmptyVarianceSums());
    }
    variance_ = RowsStage(ctx).rank_variance.get();
  }
  void ReadDense(uint32_t s, float* transport, float* visibility, uint8_t* feature) override {
    rows_.ReadRows(s, 1, transport);
    std::vector<char> buf(5 * T_);
    if (!aux_.Read(buf.data(), buf.size(), s * 5 * T_))
      throw FileIoError(aux_.path(), "lacks dense sample " + std::to_string(s));
    std::memcpy(visibility, buf.data(), T_ * sizeof(float));
    std::memcpy(feature, buf.data() + T_ * sizeof(float), T_);
  }
  void ReadLow(uint32_t s, float* low) override {
    const std::size_t bytes = LowFloats() * sizeof(float);
    if (!low_.Read(low, bytes, s * bytes))
      throw FileIoError(low_.path(), "lacks dense sample " + std::to_string(s));
  }
  void WriteDense(uint32_t s, const float* transport, const float* visibility,
                  const uint8_t* feature, const float* low) override {
    std::vector<char> buf(5 * T_);
    std::memcpy(buf.data(), visibility, T_ * sizeof(float));
    std::memcpy(buf.data() + T_ * sizeof(float), feature, T_);
    const std::size_t low_bytes = LowFloats() * sizeof(float);
    std::lock_guard lock(mutex_);
    rows_.WriteRows(s, 1, transport);
    aux_.Write(buf.data(), buf.size(), s * 5 * T_);
    low_.Write(low, low_bytes, s * low_bytes);
  }
  void WriteRow(uint32_t s, const float* transport) override {
    std::lock_guard lock(mutex_);
    rows_.WriteRows(s, 1, transport);
  }
  void RecordVariance(const std::string& step, uint64_t first, uint64_t count,
                      const std::string& encoded) override {
    const TransportVariance sums = DecodeTransportVariance(encoded, "a job's variance sums");
    std::lock_guard lock(mutex_);
    variance_->Record(step, first, count, sums);
  }
  uint64_t WriteCrossValidation(uint64_t first, std::span<const uint32_t> vertices,
                                std::span<const uint8_t> outcomes, const float* rows) override {
    std::vector<char> bytes = CrossValidationRecords(
        T_, outcomes, rows,
        [&](std::size_t i, float* traced) { rows_.ReadRows(vertices[i], 1, traced); });
    std::lock_guard lock(mutex_);
    if (!cross_) cross_.emplace(cross_path_);
    cross_->Write(bytes.data(), bytes.size(), first * (4 + 4 * T_));
    return Checksum64(bytes.data(), bytes.size());
  }
  void Sync() override {
    std::lock_guard lock(mutex_);
    if (cross_) cross_->Sync();
    rows_.Sync();
    aux_.Sync();
    low_.Sync();
    variance_->Sync();
  }
  int low_resolution() const override { return m_; }

 private:
  std::size_t LowFloats() const { return static_cast<std::size_t>(6 * m_ * m_); }
  const std::size_t T_;
  const int m_;
  TransportFileWriter rows_;
  SideFile aux_, low_;
  std::string cross_path_;
  std::optional<SideFile> cross_;  // opened at the first cross-validation job
  RankVarianceLog* variance_ = nullptr;
  std::mutex mutex_;
};

}  // namespace

FarmSparseSteps::FarmSparseSteps(FarmContext& ctx, JobLoop& loop)
    : ctx_(ctx),
      loop_(loop),
      N_(ctx.samples.size()),
      T_(6ull * ctx.params.cubemap_n * ctx.params.cubemap_n),
      n_(ctx.params.cubemap_n),
      m_(SparseRankResolution(ctx.plan, ctx.params.cubemap_n)),
      Tm_(static_cast<std::size_t>(6) * m_ * m_),
      low_(N_) {
  fs::create_directories(ctx.folder.sparse);
  aux_ = std::make_unique<SideFile>((fs::path(ctx.folder.sparse) / "dense_aux.bin").string());
  if (ctx.rows_in_place)
    low_file_ =
        std::make_unique<SideFile>((fs::path(ctx.folder.sparse) / "dense_low.bin").string());
}

void FarmSparseSteps::Count(const SparseJobCounters& c, bool this_run, bool cross_validation) {
  FarmReport& rep = ctx_.report;
  if (cross_validation) {  // its rays are not T's: report.json "sparse" "cross_validation"
    rep.sparse.cross_validation += c;
    return;
  }
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

void FarmSparseSteps::RunStep(StepJobs& p, double t0) {
  if (t0 < 0) t0 = FarmNow();
  FarmReport& rep = ctx_.report;
  JobBatch batch;
  uint64_t reused_jobs = 0;
  for (const JournalEntry& e : RowsStage(ctx_).journal_entries) {
    if (e.phase != p.name || e.rows.end() > p.items) continue;
    const bool overlaps = std::any_of(batch.done.begin(), batch.done.end(), [&](const RowRange& d) {
      return e.rows.first < d.end() && d.first < e.rows.end();
    });
    if (overlaps) continue;
    if (!p.reuse(e)) {
      ++rep.checkpoints_rejected;
      continue;
    }
    if (p.kind != SparseJobKind::kRank && !p.cross_validation &&
        !RowsStage(ctx_).variance->Reuse(p.name, e.rows.first, e.rows.count))
      ++variance_uncovered_jobs_;
    batch.done.push_back(e.rows);
    ++reused_jobs;
    ++rep.jobs_reused;
    if (p.kind != SparseJobKind::kRank && !p.cross_validation) {
      rep.rows_reused += p.kind == SparseJobKind::kDense
                             ? e.rows.count
                             : SparseJobCounters::FromVector(e.counters).reconstructed;
    }
    Count(SparseJobCounters::FromVector(e.counters), false, p.cross_validation);
  }
  if (reused_jobs > 0) spdlog::info("[{}] {} job(s) re-used from checkpoints", p.name, reused_jobs);

  batch.name = p.name;
  batch.items = p.items;
  batch.unit = p.unit;
  batch.rate_unit = p.kind == SparseJobKind::kRank ? "" : "rays";
  const uint64_t per_item_bytes = p.kind == SparseJobKind::kRank ? 64 : 9 * T_;
  batch.max_items = std::max<uint64_t>(1, kMaxSparseJobBytes / per_item_bytes);
  batch.jobs_ahead = kJobsAhead;
  batch.commit_interval_s = kCommitIntervalSeconds;
  batch.make_job = [&](RowRange& range, std::string& message) {
    SparseJobHeader h;
    h.kind = static_cast<uint32_t>(p.kind);
    h.phase = step_number_;
    h.first = range.first;
    h.count = range.count;
    message = p.make_job(h, std::move(message));
    range.count = h.count;
  };
  batch.accept = [&](int rank, const RowRange& range, std::string_view payload) {
    SparseJobResult r;
    try {
      r = DecodeSparseJobResult(payload);
    } catch (const std::exception& e) {
      throw RankFailure("rank " + std::to_string(rank) + ": " + e.what());
    }
    if (r.header.first != range.first || r.header.count != range.count ||
        r.header.phase != step_number_)
      throw RankFailure("rank " + std::to_string(rank) + " returned a job it was not given");
    uint64_t rows_written = 0;
    JournalEntry e;
    e.phase = p.name;
    e.rows = range;
    e.rows_checksum = p.accept(r, rows_written);
    if (p.kind != SparseJobKind::kRank && !p.cross_validation && !r.in_place) {
      try {
        RowsStage(ctx_).variance->Record(
            p.name, range.first, range.count,
            DecodeTransportVariance(r.variance, "variance sums from rank " + std::to_string(rank)));
      } catch (const InputError& err) {
        throw RankFailure(err.what());
      }
    }
    e.counters = r.counters.ToVector();
    e.rays_traced = r.counters.rays_traced;
    e.texels_traced = r.counters.texels_traced;
    e.texels_below_horizon = rows_written;  // (rows written; not journaled for sjob lines)
    return e;
  };
  batch.sync = [&] {
    p.sync();
    RowsStage(ctx_).variance->Sync();
  };
  batch.committed = [&](const JournalEntry& e) {
    rep.rows_done += e.texels_below_horizon;
    Count(SparseJobCounters::FromVector(e.counters), true, p.cross_validation);
  };
  loop_.Run(batch);
  ++step_number_;
  rep.sparse.phases.push_back({p.name, FarmNow() - t0, p.items, reused_jobs});
}

namespace {

class SparsePhase final : public FarmPhase {
 public:
  const char* name() const override { return "sparse"; }
  const char* stage() const override { return kStageRows; }
  // The method's steps (RunSparseSchedule's order), each as a fraction of a brute-force row:
  // dense 0.75, rank 0.08, reconstruct 0.6 (docs/sparse-precomputation.md).
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double row = SecondsPerRow(ctx);
    const std::size_t N = ctx.params.rows;
    const SparsePlan& plan = ctx.plan;
    const std::size_t budget = SparseDenseBudget(N, plan);
    std::size_t dense = SparseInitialDenseCount(N, plan);
    steps.push_back({"dense-initial", "dense", double(dense), 0.75 * row});
    const int rounds = SparseRounds(plan);
    for (int it = 0; it < rounds && dense < budget; ++it) {
      const std::size_t picks = SparsePicksForRound(budget, dense, rounds, it);
      const std::string k = std::to_string(it + 1);
      const double cand = std::min<double>(double(N - dense),
                                           double(picks) * std::max(1, plan.candidates_per_pick));
      steps.push_back({"rank-" + k, "rank", cand, 0.08 * row});
      steps.push_back({"dense-rank-" + k, "dense", double(picks), 0.75 * row});
      dense += picks;
    }
    const double sparse = double(N - std::min(N, dense));
    steps.push_back({"sparse-reconstruct", "sparse", sparse, 0.6 * row});
    steps.push_back({"cross-validate", "sparse",
                     double(std::min(kSparseCrossValidated, SparseInitialDenseCount(N, plan))),
                     0.6 * row});
    steps.push_back({"dense-fallback", "dense", 0.04 * sparse, 0.75 * row});
  }

  void Run(FarmContext& ctx) override {
    // This rank's handles on the run's files (rows in place), opened at its first job: rank 0
    // created them before it sends one.
    std::unique_ptr<FarmSparseRowFiles> files;
    CompactJobExpander expander;
    RunJobPhase(
        ctx,
        [&ctx, &files, &expander, variance_shape = ctx.EmptyVarianceSums()](
            const RowRange&, std::string_view payload, std::string& out) {
          if (ctx.rows_in_place && !files) files = std::make_unique<FarmSparseRowFiles>(ctx);
          std::string expanded;
          if (CompactJobExpander::IsCompact(payload)) {
            expanded = expander.Expand(ctx, payload);
            payload = expanded;
          }
          out = ComputeSparseJob(*ctx.sampler, ctx.samples, ctx.plan, payload, std::move(out),
                                 &variance_shape, files.get());
        },
        [&ctx](JobLoop& loop) {
          FarmReport& rep = ctx.report;
          rep.sparse.enabled = true;
          FarmSparseSteps steps(ctx, loop);
          // An image's background pixels take no part (their rows stay the zeros the partial
          // file was created with).
          const SparseScheduleCounts c =
              RunSparseSchedule(ctx.samples.size(), ctx.plan, steps, SparseSkipOf(ctx.samples));
          rep.sparse.dense_initial = c.dense_initial;
          rep.sparse.candidates_ranked += c.candidates_ranked;
          rep.sparse.dense_by_rank += c.dense_by_rank;
          rep.sparse.dense_fallback = c.dense_fallback;
          // The combinations the bounces reuse (farm/bounce/driver.cpp; a fallback's is empty).
          if (!steps.combination_.empty())
            WriteFileDurably(ctx.folder.SparseCombinationFile(),
                             EncodeCombinationFile(ctx.samples.size(), CombinationSlots(ctx.plan),
                                                   steps.combination_));
          RemoveSparseScratch(ctx.folder);
          if (steps.variance_uncovered_jobs_ > 0)
            spdlog::warn(
                "{} re-used job(s) have no logged variance: the Monte-Carlo estimate "
                "leaves their rows out",
                steps.variance_uncovered_jobs_);
          rep.jobs_total = rep.jobs_done + rep.jobs_reused;
        });
  }
};

}  // namespace

// Rows by the sparse method: a transport run with method "sparse" whose rows stage runs.
void AddSparsePhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.visibility || !ctx.params.sparse || !ctx.params.run_rows) return;
  phases.push_back(std::make_unique<SparsePhase>());
}

}  // namespace prt
