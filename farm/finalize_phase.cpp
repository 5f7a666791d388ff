// prt-farm's finalize phase (docs/farm.md, "Phases"): rank 0 makes the sampled rows the run's
// transport.prtt. It reads every block of transport.prtt.partial once, checksums it and
// compresses it (one zstd frame per block, TBB over blocks), writes the packed file
// (formats/transport_file.h, version 2: ~4× smaller than the float32 rows), renames it into place
// and removes the partial file. The packed file is what later stages read, and what a re-run
// with other compression settings or environments re-uses without tracing.
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/progress.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

class FinalizePhase final : public FarmPhase {
 public:
  const char* name() const override { return "finalize"; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    const TransportFileInfo info = ctx.writer->info();
    ctx.writer->Sync();
    // The rows' Monte-Carlo variance sums, for the estimate stage.
    if (ctx.variance) {
      ctx.variance->WriteFile();
      ctx.variance.reset();
    }
    // Blocks are read, checksummed and compressed a group at a time: enough blocks for every
    // thread, at most a quarter of --memory-budget of rows in memory.
    const uint64_t block_bytes = info.rows_per_block * info.row_bytes();
    const uint64_t by_memory = std::max<uint64_t>(
        1, ctx.options.memory_budget_bytes / 4 / std::max<uint64_t>(1, block_bytes));
    const uint64_t group = std::min<uint64_t>(by_memory, 2 * static_cast<uint64_t>(ctx.threads));
    const uint64_t blocks = info.block_count();
    PackedTransportWriter packed(ctx.folder.transport, info);
    ProgressOptions po = FarmProgressOptions(ctx, "blocks");
    ctx.run_eta.StepStarted("pack");
    Progress progress("pack", blocks, po);
    std::vector<std::vector<float>> rows(static_cast<std::size_t>(group));
    std::vector<std::string> frames(static_cast<std::size_t>(group));
    std::vector<uint64_t> sums(static_cast<std::size_t>(group));
    for (uint64_t b0 = 0; b0 < blocks; b0 += group) {
      const uint64_t count = std::min(group, blocks - b0);
      for (uint64_t i = 0; i < count; ++i) {
        rows[i].resize(static_cast<std::size_t>(info.RowsInBlock(b0 + i) * info.cols()));
        ctx.writer->ReadRows(info.FirstRowOfBlock(b0 + i), info.RowsInBlock(b0 + i),
                             rows[i].data());
      }
      tbb::parallel_for(uint64_t{0}, count, [&](uint64_t i) {
        sums[i] = Checksum64(rows[i].data(), rows[i].size() * sizeof(float));
        frames[i] = CompressTransportBlock(rows[i].data(), rows[i].size());
      });
      for (uint64_t i = 0; i < count; ++i) packed.Append(b0 + i, frames[i], sums[i]);
      progress.Advance(count);
    }
    if (ctx.options.fail_in == "finalize" && ctx.options.fail_rank == 0)
      ExitAbruptly(0, "before renaming " + ctx.folder.transport);
    const uint64_t bytes = packed.Finish();
    progress.Finish();
    ctx.run_eta.StepFinished("pack");
    ctx.writer.reset();
    std::filesystem::remove(ctx.folder.partial);
    SyncDirectory(ctx.folder.dir);
    spdlog::info(
        "wrote {} ({} rows x {} texels, {} blocks of {} rows; {:.1f} MB packed, {:.1f}% "
        "of the {:.1f} MB of float32 rows)",
        ctx.folder.transport, info.rows, info.cols(), blocks, info.rows_per_block,
        static_cast<double>(bytes) / 1e6,
        100.0 * static_cast<double>(bytes) / static_cast<double>(info.rows * info.row_bytes()),
        static_cast<double>(info.rows * info.row_bytes()) / 1e6);
  }
};

}  // namespace

std::unique_ptr<FarmPhase> MakeFinalizePhase() {
  return std::make_unique<FinalizePhase>();
}

}  // namespace prt
