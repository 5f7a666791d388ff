// prt-farm's finalize phase (docs/farm.md, "Phases"): the sampled rows become the run's
// transport.prtt. Every block of transport.prtt.partial is read once, checksummed and compressed
// (one zstd frame per block, TBB over blocks) into the packed file (formats/transport_file.h,
// version 2: ~4× smaller than the float32 rows), which is renamed into place; the partial file
// is removed. The packed file is what later stages read, and what a re-run with other
// compression settings or environments re-uses without tracing.
//
// Where every rank sees the run folder (ctx.rows_in_place; docs/farm.md, "Where the rows go")
// the ranks pack the blocks together, in rounds: in each round rank r reads and compresses
// `group` blocks of its own, the frame sizes are all-gathered (8 bytes per block), and every rank
// writes its frames at their offsets in the packed file; rank 0 gathers the blocks' checksums
// (8 bytes each) and writes the header. Otherwise rank 0 packs every block itself. The bytes of
// transport.prtt are the same either way.
#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/mpi_support.h"
#include "farm/progress.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// Rank 0: the sum of every rank's RankVarianceLog (rows in place: brute force, sparse) is added to
// the run's variance sums. Collective. The sums travel as 32-bit digits (TransportVariance::Digits)
// whose MPI_SUM is exact in any reduction order: the same bytes for any number of ranks.
void ReduceRankVariance(FarmContext& ctx) {
  const TransportVariance mine = RowsStage(ctx).rank_variance
                                     ? RowsStage(ctx).rank_variance->total()
                                     : ctx.EmptyVarianceSums();
  RowsStage(ctx).rank_variance.reset();
  std::vector<uint64_t> digits = mine.Digits();
  std::vector<uint64_t> covered = mine.rows_covered;
  ctx.collectives.SumOnRank0(digits, "sum the variance digits");
  ctx.collectives.SumOnRank0(covered, "sum the variance rows");
  if (ctx.rank != 0 || !RowsStage(ctx).variance) return;
  TransportVariance all = ctx.EmptyVarianceSums();
  all.AddDigits(digits);
  all.rows_covered = covered;
  RowsStage(ctx).variance->AddTotal(all);
}

class FinalizePhase final : public FarmPhase {
 public:
  const char* name() const override { return "finalize"; }
  const char* stage() const override { return kStageRows; }
  // Packing: ~1 GB/s of float32 rows (the 2-core VM's prior; docs/farm.md, "Progress").
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double cols = 6.0 * ctx.params.cubemap_n * ctx.params.cubemap_n;
    steps.push_back({"pack", "pack", static_cast<double>(ctx.params.rows) * cols * 4.0, 1e-9});
  }
  void Run(FarmContext& ctx) override {
    if (ctx.rows_in_place) ReduceRankVariance(ctx);
    if (ctx.rank != 0 && !ctx.rows_in_place) return;
    const TransportFileInfo info = ctx.RowsFileInfo();
    if (ctx.rank == 0) {
      if (!(RowsStage(ctx).writer->info() == info))
        throw std::logic_error("finalize: rows file differs");
      RowsStage(ctx).writer->Sync();
      // The rows' Monte-Carlo variance sums, for the estimate stage.
      if (RowsStage(ctx).variance) {
        RowsStage(ctx).variance->WriteFile();
        RowsStage(ctx).variance.reset();
      }
    }
    // Blocks are read, checksummed and compressed a group at a time: enough blocks for every
    // thread, at most a quarter of --memory-budget of rows in memory.
    const uint64_t block_bytes = info.rows_per_block * info.row_bytes();
    const uint64_t by_memory = std::max<uint64_t>(
        1, ctx.options.memory_budget_bytes / 4 / std::max<uint64_t>(1, block_bytes));
    const uint64_t group = std::min<uint64_t>(by_memory, 2 * static_cast<uint64_t>(ctx.threads));
    const uint64_t blocks = info.block_count();
    const int ranks = ctx.rows_in_place ? ctx.size : 1;
    std::optional<PackedTransportWriter> packed;
    if (ctx.rank == 0) packed.emplace(ctx.folder.transport, info);
    std::optional<Progress> progress;
    if (ctx.rank == 0) {
      ctx.run_eta.StepStarted("pack");
      progress.emplace("pack", blocks, FarmProgressOptions(ctx, "blocks"));
    }
    // The other ranks' handles: the partial file to read, the packed file to write (rank 0
    // created it before they open it).
    std::optional<TransportFileWriter> rows_in;
    int out_fd = -1;
    if (ranks > 1) {
      ctx.collectives.WaitForEveryRank("finalize: wait for the packed file");
      if (ctx.rank != 0) {
        rows_in.emplace(TransportFileWriter::OpenRows(ctx.folder.partial, info));
        const std::string tmp = ctx.folder.transport + ".tmp";
        out_fd = ::open(tmp.c_str(), O_WRONLY | O_CLOEXEC);
        if (out_fd < 0) throw FileIoError(tmp, SystemReason("cannot open"));
      }
    }
    const TransportFileWriter& source = ctx.rank == 0 ? *RowsStage(ctx).writer : *rows_in;
    const std::string out_path = ctx.folder.transport + ".tmp";
    std::vector<std::vector<float>> rows(static_cast<std::size_t>(group));
    std::vector<std::string> frames(static_cast<std::size_t>(group));
    std::vector<uint64_t> sums(static_cast<std::size_t>(group)), sizes(group);
    std::vector<uint64_t> all_sizes(group * static_cast<uint64_t>(ranks)),
        all_sums(ctx.rank == 0 ? all_sizes.size() : 0);
    const uint64_t per_round = group * static_cast<uint64_t>(ranks);
    uint64_t at = PackedTransportWriter::FirstFrameOffset(info);
    for (uint64_t r0 = 0; r0 < blocks; r0 += per_round) {
      // This rank's blocks of the round: [b0, b0 + count).
      const uint64_t b0 = std::min(blocks, r0 + static_cast<uint64_t>(ctx.rank) * group);
      const uint64_t count = std::min(group, blocks - b0);
      for (uint64_t i = 0; i < count; ++i) {
        rows[i].resize(static_cast<std::size_t>(info.RowsInBlock(b0 + i) * info.cols()));
        source.ReadRows(info.FirstRowOfBlock(b0 + i), info.RowsInBlock(b0 + i), rows[i].data());
      }
      tbb::parallel_for(uint64_t{0}, count, [&](uint64_t i) {
        sums[i] = Checksum64(rows[i].data(), rows[i].size() * sizeof(float));
        frames[i] = CompressTransportBlock(rows[i].data(), rows[i].size());
      });
      std::fill(sizes.begin(), sizes.end(), 0);
      for (uint64_t i = 0; i < count; ++i) sizes[i] = frames[i].size();
      if (ranks > 1) {
        all_sizes = ctx.collectives.GatherEverywhere(sizes, "gather frame sizes");
        all_sums = ctx.collectives.GatherOnRank0(sums, "gather block checksums");
      } else {
        all_sizes.assign(sizes.begin(), sizes.end());
        all_sums.assign(sums.begin(), sums.end());
      }
      // Frames in block order: rank r's g-th block of the round is block r0 + r·group + g.
      const uint64_t round_blocks = std::min(per_round, blocks - r0);
      for (uint64_t k = 0; k < round_blocks; ++k) {
        const uint64_t b = r0 + k;
        const uint64_t owner = k / group, g = k % group;
        const uint64_t bytes = all_sizes[owner * group + g];
        if (owner == static_cast<uint64_t>(ctx.rank)) {
          const std::string& frame = frames[g];
          if (ctx.rank == 0) {
            PwriteAll(packed->fd(), frame.data(), frame.size(), at, out_path);
          } else {
            PwriteAll(out_fd, frame.data(), frame.size(), at, out_path);
          }
        }
        if (ctx.rank == 0) packed->Place(b, bytes, all_sums[owner * group + g]);
        at += bytes;
      }
      if (progress) progress->Advance(round_blocks);
    }
    if (out_fd >= 0) {
      const bool synced = ::fsync(out_fd) == 0;
      ::close(out_fd);
      if (!synced) throw FileIoError(out_path, SystemReason("fsync failed"));
    }
    if (ranks > 1) ctx.collectives.WaitForEveryRank("finalize: wait for every rank's frames");
    if (ctx.rank == 0) Finish(ctx, *packed, *progress, info, blocks, ranks);
    // The next phases read transport.prtt on every rank: not before it is in place.
    if (ranks > 1) ctx.collectives.WaitForEveryRank("finalize: wait for transport.prtt");
  }

 private:
  static void Finish(FarmContext& ctx, PackedTransportWriter& packed, Progress& progress,
                     const TransportFileInfo& info, uint64_t blocks, int ranks) {
    if (ctx.options.fail_in == "finalize" && ctx.options.fail_rank == 0)
      ExitAbruptly(0, "before renaming " + ctx.folder.transport);
    const uint64_t bytes = packed.Finish();
    progress.Finish();
    ctx.run_eta.StepFinished("pack");
    RowsStage(ctx).writer.reset();
    std::filesystem::remove(ctx.folder.partial);
    SyncDirectory(ctx.folder.dir);
    spdlog::info(
        "wrote {} ({} rows x {} texels, {} blocks of {} rows, packed by {} rank(s); {:.1f} MB "
        "packed, {:.1f}% of the {:.1f} MB of float32 rows)",
        ctx.folder.transport, info.rows, info.cols(), blocks, info.rows_per_block, ranks,
        static_cast<double>(bytes) / 1e6,
        100.0 * static_cast<double>(bytes) / static_cast<double>(info.rows * info.row_bytes()),
        static_cast<double>(info.rows * info.row_bytes()) / 1e6);
  }
};

}  // namespace

// The sampled rows of a transport run (brute force or sparse) become transport.prtt.
void AddFinalizePhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.visibility || !ctx.params.run_rows) return;
  phases.push_back(std::make_unique<FinalizePhase>());
}

}  // namespace prt
