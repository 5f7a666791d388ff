// The visibility job (docs/farm.md, "Visibility job"): contiguous sample ranges on the job loop,
// each job's result the block-differential encoding of its samples' visibility maps
// (farm/visibility_jobs.h). Rank 0 appends a result to visibility.chunks, and the loop fdatasyncs
// and journals it ("sjob visibility …"); the visibility-finalize phase assembles the chunks in
// sample order into visibility.prtv. A job is re-used after --resume when its chunk still hashes to
// its journal line.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/job_loop.h"
#include "farm/side_file.h"
#include "farm/visibility_jobs.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

namespace fs = std::filesystem;

// The chunks of visibility.chunks that make up the result (verified re-used ones and this
// run's), which the visibility phase finds and the visibility-finalize phase assembles: the
// pair's own state.
using VisibilityChunks = std::vector<VisibilityChunkRef>;

class VisibilityPhase final : public FarmPhase {
 public:
  explicit VisibilityPhase(std::shared_ptr<VisibilityChunks> chunks) : chunks_(std::move(chunks)) {}
  const char* name() const override { return kVisibilityPhaseName; }
  const char* stage() const override { return kStageRows; }
  // About half the sphere's texels traced per map, ~10 M occlusion rays/s per thread (the 2-core
  // VM's prior; docs/farm.md, "Progress").
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double cols = 6.0 * ctx.params.cubemap_n * ctx.params.cubemap_n;
    const double threads = std::max(1, ctx.computing_ranks()) * std::max(1, ctx.threads);
    steps.push_back({kVisibilityPhaseName, "visibility", static_cast<double>(ctx.params.rows),
                     cols * 0.5 / (1e7 * threads)});
  }

  void Run(FarmContext& ctx) override {
    RunJobPhase(
        ctx,
        [&ctx](const RowRange& range, std::string_view, std::string& out) {
          const std::vector<uint8_t> r = EncodeVisibilityJobResult(
              ComputeVisibilityJob(*ctx.visibility_sampler, ctx.samples, range.first, range.count));
          out.append(reinterpret_cast<const char*>(r.data()), r.size());
        },
        [&](JobLoop& loop) { Coordinate(ctx, loop, *chunks_); });
  }

 private:
  static void Coordinate(FarmContext& ctx, JobLoop& loop, VisibilityChunks& made) {
    const uint64_t total = ctx.params.rows;
    FarmReport& rep = ctx.report;
    const std::string& path = ctx.folder.visibility_chunks;
    SideFile chunks(path);
    std::error_code ec;
    uint64_t append_at = fs::file_size(path, ec);
    if (ec) append_at = 0;

    // Journaled chunks that still verify are re-used (overlapping lines: the first wins).
    JobBatch batch;
    std::vector<uint8_t> buffer;
    for (const JournalEntry& e : RowsStage(ctx).journal_entries) {
      VisibilityChunkRef ref;
      const bool overlaps = std::any_of(
          batch.done.begin(), batch.done.end(),
          [&](const RowRange& d) { return e.rows.first < d.end() && d.first < e.rows.end(); });
      bool ok = ChunkOfJournalEntry(e, ref) && !overlaps && e.rows.count > 0 &&
                e.rows.end() <= total && ref.length <= kMaxJobBytes * 4;
      if (ok) {
        buffer.resize(static_cast<std::size_t>(ref.length));
        ok = chunks.Read(buffer.data(), buffer.size(), ref.offset) &&
             Checksum64(buffer.data(), buffer.size()) == ref.checksum;
      }
      if (!ok) {
        ++rep.checkpoints_rejected;
        continue;
      }
      batch.done.push_back(e.rows);
      made.push_back(ref);
      rep.rows_reused += e.rows.count;
      rep.rays_traced_all += ref.rays_traced;
      rep.texels_below_horizon_all += ref.texels_below_horizon;
      ++rep.jobs_reused;
    }
    if (!RowsStage(ctx).journal_entries.empty()) {
      spdlog::info("--resume: {} visibility job(s) re-used, {} rejected", rep.jobs_reused,
                   rep.checkpoints_rejected);
    }

    const uint64_t texels = 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n;
    batch.name = kVisibilityPhaseName;
    batch.items = total;
    // A map costs at most ~2 bytes per texel encoded (all positions changing): bound the job.
    batch.max_items = std::max<uint64_t>(1, kMaxJobBytes / (2 * texels));
    batch.accept = [&](int rank, const RowRange& range, std::string_view payload) {
      VisibilityJobResult r;
      try {
        r = DecodeVisibilityJobResult(std::span<const uint8_t>(
            reinterpret_cast<const uint8_t*>(payload.data()), payload.size()));
      } catch (const std::exception& e) {
        throw RankFailure("rank " + std::to_string(rank) + ": " + e.what());
      }
      if (r.first != range.first || r.count != range.count) {
        throw RankFailure("rank " + std::to_string(rank) + " returned visibility of samples " +
                          std::to_string(r.first) + "+" + std::to_string(r.count) +
                          " it was not given");
      }
      const uint64_t sum = Checksum64(r.chunk.data(), r.chunk.size());
      chunks.Write(r.chunk.data(), r.chunk.size(), append_at);
      JournalEntry e = VisibilityJournalEntry(r, rank, append_at, sum);
      append_at += r.chunk.size();
      return e;
    };
    batch.sync = [&] { chunks.Sync(); };
    batch.committed = [&](const JournalEntry& e) {
      VisibilityChunkRef ref;
      ChunkOfJournalEntry(e, ref);
      made.push_back(ref);
      rep.rows_done += e.rows.count;
      rep.rays_traced += e.rays_traced;
      rep.texels_traced += texels * e.rows.count - e.texels_below_horizon;
      rep.texels_below_horizon += e.texels_below_horizon;
      rep.rays_traced_all += e.rays_traced;
      rep.texels_below_horizon_all += e.texels_below_horizon;
    };
    loop.Run(batch);
    rep.jobs_total = rep.jobs_done + rep.jobs_reused;
  }

  std::shared_ptr<VisibilityChunks> chunks_;
};

// Rank 0 assembles visibility.prtv from the journaled chunks (in sample order, so the file does
// not depend on ranks or job boundaries) and writes it durably. visibility.chunks is kept, so
// that --resume of a finished run re-uses every job.
class VisibilityFinalizePhase final : public FarmPhase {
 public:
  explicit VisibilityFinalizePhase(std::shared_ptr<const VisibilityChunks> chunks)
      : chunks_(std::move(chunks)) {}
  const char* name() const override { return "visibility-finalize"; }
  const char* stage() const override { return kStageRows; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    const std::string& path = ctx.folder.visibility_chunks;
    SideFile chunks(path);
    std::vector<std::vector<uint8_t>> data(chunks_->size());
    std::vector<VisibilityChunk> parts;
    for (std::size_t i = 0; i < data.size(); ++i) {
      const VisibilityChunkRef& ref = (*chunks_)[i];
      data[i].resize(static_cast<std::size_t>(ref.length));
      if (!chunks.Read(data[i].data(), data[i].size(), ref.offset) ||
          Checksum64(data[i].data(), data[i].size()) != ref.checksum) {
        throw FileIoError(path, "chunk of samples " + std::to_string(ref.first) + "+" +
                                    std::to_string(ref.count) + " changed on disk");
      }
      parts.push_back({ref.first, ref.count, data[i]});
    }
    VisibilityBlockCounts counts;
    const std::vector<uint8_t> file =
        AssembleVisibilityChunks(std::move(parts), ctx.params.rows, ctx.params.cubemap_n,
                                 ctx.params.visibility_bits, path, &counts);
    const std::string& out = ctx.folder.visibility;
    WriteFileDurably(out,
                     std::string_view(reinterpret_cast<const char*>(file.data()), file.size()));
    VisibilityFarmReport& v = ctx.report.visibility;
    v.raw_bytes = ctx.params.rows * 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n *
                  static_cast<uint64_t>(ctx.params.visibility_bits) / 8;
    v.encoded_bytes = file.size();
    v.blocks_zero = counts.zero;
    v.blocks_one = counts.one;
    v.blocks_mixed = counts.mixed;
    v.changes = counts.changes;
    spdlog::info(
        "wrote {} ({} maps at n = {}: {} bytes, {:.1f} per vertex; {:.1f}x smaller than "
        "bitmaps)",
        out, ctx.params.rows, ctx.params.cubemap_n, file.size(),
        double(file.size()) / double(ctx.params.rows),
        file.empty() ? 0.0 : double(v.raw_bytes) / double(file.size()));
  }

 private:
  std::shared_ptr<const VisibilityChunks> chunks_;
};

}  // namespace

// The visibility job (job = "visibility"), when its rows stage runs: the maps, then the file.
void AddVisibilityPhases(const FarmContext& ctx, PhaseList& phases) {
  if (!ctx.params.visibility || !ctx.params.run_rows) return;
  auto chunks = std::make_shared<VisibilityChunks>();
  phases.push_back(std::make_unique<VisibilityPhase>(chunks));
  phases.push_back(std::make_unique<VisibilityFinalizePhase>(chunks));
}

}  // namespace prt
