// prt-farm's brute-force sampling phase (docs/farm.md, "Job queue"): every texel of every spatial
// sample, contiguous ranges of samples per job. Where every rank sees the run folder
// (ctx.rows_in_place) the worker writes its rows into transport.prtt.partial itself, fdatasyncs
// them and returns only their XXH64 and counters; otherwise it returns the rows, rank 0 checks
// them against the XXH64 and writes them. Either way the job loop journals the job once its rows
// are durable (docs/farm.md, "Where the rows go").
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <string>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "formats/transport_variance.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// What a worker returns before the rows (count × cols floats).
struct BruteResultHeader {
  uint64_t rows_checksum = 0;
  uint64_t in_place = 0;  // 1: the worker wrote and synced the rows; they do not follow
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
};

// Traces samples `range` into the result payload: the header, the rows (unless `in_place`: then
// they go into its file, durably, before the result leaves), then their variance sums (an encoded
// TransportVariance).
void ComputeBruteJob(FarmContext& ctx, const RowRange& range, std::string& out,
                     TransportFileWriter* in_place) {
  const uint64_t cols = ctx.sampler->layout().texel_count();
  const std::size_t at = out.size();
  const std::size_t floats = static_cast<std::size_t>(range.count * cols);
  thread_local std::vector<float> own_rows;
  float* rows = nullptr;
  if (in_place) {
    own_rows.resize(floats);
    rows = own_rows.data();
    out.resize(at + sizeof(BruteResultHeader));
  } else {
    out.resize(at + sizeof(BruteResultHeader) + floats * sizeof(float));
    rows = reinterpret_cast<float*>(out.data() + at + sizeof(BruteResultHeader));
  }
  // The rows' per-texel Monte-Carlo variance, summed per mesh (formats/transport_variance.h).
  thread_local std::vector<float> variance;
  const bool with_variance = ctx.sampler->VarianceEstimable();
  if (with_variance) variance.resize(floats);
  const SampleStats stats = ctx.sampler->ComputeRows(
      std::span<const SpatialSample>(ctx.samples.data() + range.first, range.count), range.first,
      rows, with_variance ? variance.data() : nullptr);
  for (std::size_t i = 0; i < floats; ++i) {
    if (!std::isfinite(rows[i])) {
      throw NumericalError("worker returned a non-finite value for sample " +
                           std::to_string(range.first + i / cols) + ", texel " +
                           std::to_string(i % cols));
    }
  }
  BruteResultHeader h;
  h.rows_checksum = Checksum64(rows, floats * sizeof(float));
  h.rays_traced = stats.rays_traced;
  h.texels_traced = stats.texels_traced;
  h.texels_below_horizon = stats.texels_below_horizon;
  h.rays_below_horizon = stats.rays_below_horizon;
  TransportVariance sums = ctx.EmptyVarianceSums();
  if (with_variance) {
    for (uint64_t r = 0; r < range.count; ++r)
      sums.AddRow(range.first + r, variance.data() + r * cols);
  }
  if (in_place) {
    // Rows and variance record durable before the result that lets rank 0 journal them.
    in_place->WriteRows(range.first, range.count, rows);
    RowsStage(ctx).rank_variance->Record(ctx.method, range.first, range.count, sums);
    in_place->Sync();
    RowsStage(ctx).rank_variance->Sync();
    h.in_place = 1;
    std::memcpy(out.data() + at, &h, sizeof h);
    return;
  }
  std::memcpy(out.data() + at, &h, sizeof h);
  out += EncodeTransportVariance(sums);
}

class BrutePhase final : public FarmPhase {
 public:
  const char* name() const override { return "brute"; }
  const char* stage() const override { return kStageRows; }
  // Every texel above the horizon traced rays_per_texel times: ~10 M occlusion rays/s per thread
  // over about half the sphere (the 2-core VM's prior; docs/farm.md, "Progress").
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    steps.push_back({"brute", "row", static_cast<double>(ctx.params.rows), SecondsPerRow(ctx)});
  }

  void Run(FarmContext& ctx) override {
    // This rank's own handle on transport.prtt.partial (rank 0's worker thread has its own, apart
    // from the coordinator's), opened at the first job: setup created the file.
    std::optional<TransportFileWriter> rows_out;
    RunJobPhase(
        ctx,
        [&ctx, &rows_out](const RowRange& range, std::string_view, std::string& out) {
          if (ctx.rows_in_place && !rows_out) {
            rows_out.emplace(TransportFileWriter::OpenRows(ctx.folder.partial, ctx.RowsFileInfo()));
            RowsStage(ctx).rank_variance =
                std::make_unique<RankVarianceLog>(ctx.folder, ctx.rank, ctx.EmptyVarianceSums());
          }
          ComputeBruteJob(ctx, range, out, rows_out ? &*rows_out : nullptr);
        },
        [&ctx](JobLoop& loop) { Coordinate(ctx, loop); });
  }

 private:
  static void Coordinate(FarmContext& ctx, JobLoop& loop) {
    FarmReport& rep = ctx.report;
    const uint64_t cols = 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n;
    const uint64_t row_bytes = cols * sizeof(float);

    // The journaled jobs setup verified against the rows of transport.prtt.partial.
    JobBatch batch;
    uint64_t uncovered = 0;
    for (const JournalEntry& e : RowsStage(ctx).journal_entries) {
      if (!RowsStage(ctx).variance->Reuse(ctx.method, e.rows.first, e.rows.count))
        uncovered += e.rows.count;
      batch.done.push_back(e.rows);
      rep.rows_reused += e.rows.count;
      rep.rays_traced_all += e.rays_traced;
      rep.texels_below_horizon_all += e.texels_below_horizon;
    }
    rep.jobs_reused = RowsStage(ctx).journal_entries.size();
    if (uncovered > 0) {
      spdlog::warn(
          "{} re-used row(s) have no logged variance: the Monte-Carlo estimate leaves "
          "them out",
          uncovered);
    }

    batch.name = ctx.method;
    batch.items = ctx.params.rows;
    batch.max_items = std::max<uint64_t>(1, kMaxJobBytes / row_bytes);
    batch.cost = SampleCost(ctx);  // image runs: background pixels next to free (issue 37)
    batch.accept = [&ctx, row_bytes](int rank, const RowRange& range, std::string_view payload) {
      BruteResultHeader h;
      if (payload.size() >= sizeof h) std::memcpy(&h, payload.data(), sizeof h);
      const uint64_t rows_bytes = h.in_place ? 0 : range.count * row_bytes;
      if (payload.size() < sizeof h + rows_bytes)
        throw RankFailure("rank " + std::to_string(rank) + " returned " +
                          std::to_string(payload.size()) + " bytes for " +
                          std::to_string(range.count) + " rows");
      const char* rows = payload.data() + sizeof h;
      if (!h.in_place && Checksum64(rows, rows_bytes) != h.rows_checksum) {
        throw RankFailure("rows from rank " + std::to_string(rank) +
                          " arrived damaged (checksum mismatch)");
      }
      if (!h.in_place) {
        // The rows and their variance sums came with the result: rank 0 writes both.
        TransportVariance sums;
        try {
          sums = DecodeTransportVariance(payload.substr(sizeof h + rows_bytes),
                                         "variance sums from rank " + std::to_string(rank));
        } catch (const InputError& e) {
          throw RankFailure(e.what());
        }
        RowsStage(ctx).writer->WriteRows(range.first, range.count,
                                         reinterpret_cast<const float*>(rows));
        RowsStage(ctx).variance->Record(ctx.method, range.first, range.count, sums);
      } else if (payload.size() != sizeof h) {
        throw RankFailure("rank " + std::to_string(rank) + " returned " +
                          std::to_string(payload.size()) + " bytes for rows it wrote itself");
      }
      JournalEntry e;
      e.rows = range;
      e.rows_checksum = h.rows_checksum;
      e.rays_traced = h.rays_traced;
      e.texels_traced = h.texels_traced;
      e.texels_below_horizon = h.texels_below_horizon;
      e.rays_below_horizon = h.rays_below_horizon;
      return e;
    };
    batch.sync = [&ctx] {
      RowsStage(ctx).writer->Sync();
      RowsStage(ctx).variance->Sync();
    };
    batch.committed = [&rep](const JournalEntry& e) {
      rep.rows_done += e.rows.count;
      rep.rays_traced += e.rays_traced;
      rep.texels_traced += e.texels_traced;
      rep.texels_below_horizon += e.texels_below_horizon;
      rep.rays_below_horizon += e.rays_below_horizon;
      rep.rays_traced_all += e.rays_traced;
      rep.texels_below_horizon_all += e.texels_below_horizon;
    };
    loop.Run(batch);
    rep.jobs_total = rep.jobs_done + rep.jobs_reused;
  }
};

}  // namespace

// Rows by brute force: a transport run with method "brute" whose rows stage runs.
void AddBrutePhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.visibility || ctx.params.sparse || !ctx.params.run_rows) return;
  phases.push_back(std::make_unique<BrutePhase>());
}

}  // namespace prt
