// prt-farm's brute-force sampling phase (docs/farm.md, "Job queue"): every texel of every spatial
// sample, contiguous ranges of samples per job. A worker returns the rows with their XXH64; rank 0
// checks it, writes the rows in place into transport.prtt.partial, and the job loop fdatasyncs
// and journals them.
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstring>
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
  uint64_t rays_traced = 0;
  uint64_t texels_traced = 0;
  uint64_t texels_below_horizon = 0;
  uint64_t rays_below_horizon = 0;
};

// Zero variance sums over the scene's meshes (every rank has the geometry).
TransportVariance VarianceSumsShape(const FarmContext& ctx) {
  return MakeTransportVariance(static_cast<uint32_t>(ctx.params.cubemap_n),
                               static_cast<uint32_t>(ctx.params.rays_per_texel), ctx.RowGroups());
}

// Traces samples `range` into the result payload: the header, the rows, then their variance
// sums (an encoded TransportVariance).
void ComputeBruteJob(const FarmContext& ctx, const RowRange& range, std::string& out) {
  const uint64_t cols = ctx.sampler->layout().texel_count();
  const std::size_t at = out.size();
  const std::size_t floats = static_cast<std::size_t>(range.count * cols);
  out.resize(at + sizeof(BruteResultHeader) + floats * sizeof(float));
  float* rows = reinterpret_cast<float*>(out.data() + at + sizeof(BruteResultHeader));
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
  std::memcpy(out.data() + at, &h, sizeof h);
  TransportVariance sums = VarianceSumsShape(ctx);
  if (with_variance) {
    for (uint64_t r = 0; r < range.count; ++r)
      sums.AddRow(range.first + r, variance.data() + r * cols);
  }
  out += EncodeTransportVariance(sums);
}

class BrutePhase final : public FarmPhase {
 public:
  const char* name() const override { return "brute"; }

  void Run(FarmContext& ctx) override {
    RunJobPhase(
        ctx,
        [&ctx](const RowRange& range, std::string_view, std::string& out) {
          ComputeBruteJob(ctx, range, out);
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
    for (const JournalEntry& e : ctx.journal_entries) {
      if (!ctx.variance->Reuse(ctx.method, e.rows.first, e.rows.count)) uncovered += e.rows.count;
      batch.done.push_back(e.rows);
      rep.rows_reused += e.rows.count;
      rep.rays_traced_all += e.rays_traced;
      rep.texels_below_horizon_all += e.texels_below_horizon;
    }
    rep.jobs_reused = ctx.journal_entries.size();
    if (uncovered > 0) {
      spdlog::warn(
          "{} re-used row(s) have no logged variance: the Monte-Carlo estimate leaves "
          "them out",
          uncovered);
    }

    batch.name = ctx.method;
    batch.items = ctx.params.rows;
    batch.max_items = std::max<uint64_t>(1, kMaxJobBytes / row_bytes);
    batch.accept = [&ctx, row_bytes](int rank, const RowRange& range, std::string_view payload) {
      BruteResultHeader h;
      if (payload.size() < sizeof h + range.count * row_bytes)
        throw RankFailure("rank " + std::to_string(rank) + " returned " +
                          std::to_string(payload.size()) + " bytes for " +
                          std::to_string(range.count) + " rows");
      std::memcpy(&h, payload.data(), sizeof h);
      const char* rows = payload.data() + sizeof h;
      if (Checksum64(rows, range.count * row_bytes) != h.rows_checksum) {
        throw RankFailure("rows from rank " + std::to_string(rank) +
                          " arrived damaged (checksum mismatch)");
      }
      TransportVariance sums;
      try {
        sums = DecodeTransportVariance(payload.substr(sizeof h + range.count * row_bytes),
                                       "variance sums from rank " + std::to_string(rank));
      } catch (const InputError& e) {
        throw RankFailure(e.what());
      }
      ctx.writer->WriteRows(range.first, range.count, reinterpret_cast<const float*>(rows));
      ctx.variance->Record(ctx.method, range.first, range.count, sums);
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
      ctx.writer->Sync();
      ctx.variance->Sync();
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

std::unique_ptr<FarmPhase> MakeBrutePhase() {
  return std::make_unique<BrutePhase>();
}

}  // namespace prt
