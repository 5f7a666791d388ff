// prt-farm's finalize phase (docs/farm.md, "Phases"): rank 0 computes the block checksums of
// transport.prtt.partial, marks it complete, fsyncs it and renames it to transport.prtt.
#include <spdlog/spdlog.h>

#include <filesystem>

#include "farm/farm_context.h"
#include "vocabulary/durable_file.h"

namespace prt {

namespace {

class FinalizePhase final : public FarmPhase {
 public:
  const char* name() const override { return "finalize"; }
  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    ctx.writer->Finalize();
    ctx.writer.reset();
    if (ctx.options.fail_in == "finalize" && ctx.options.fail_rank == 0)
      ExitAbruptly(0, "before renaming " + ctx.folder.partial);
    std::filesystem::rename(ctx.folder.partial, ctx.folder.transport);
    SyncDirectory(ctx.folder.dir);
    spdlog::info("wrote {} ({} rows x {} texels, {} blocks of {} rows)", ctx.folder.transport,
                 ctx.params.rows, 6ull * ctx.params.cubemap_n * ctx.params.cubemap_n,
                 (ctx.params.rows + ctx.options.rows_per_block - 1) / ctx.options.rows_per_block,
                 ctx.options.rows_per_block);
  }
};

}  // namespace

std::unique_ptr<FarmPhase> MakeFinalizePhase() {
  return std::make_unique<FinalizePhase>();
}

}  // namespace prt
