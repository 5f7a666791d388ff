// Writing transport.prtc (see compressed_file.h).
#include "farm/compressed_file.h"

#include <fstream>
#include <string>
#include <string_view>

#include "farm/farm_context.h"
#include "vocabulary/durable_file.h"

namespace prt {

void WriteCompressedFile(const FarmContext& ctx, const std::vector<uint8_t>& file) {
  const FarmOptions& options = ctx.options;
  const std::string& prtc = ctx.folder.compressed;
  if (options.fail_in == "write" && options.fail_rank == 0) {
    // As if killed inside WriteFileDurably: half of its temporary file is on disk.
    std::ofstream(prtc + ".tmp", std::ios::binary)
        .write(reinterpret_cast<const char*>(file.data()),
               static_cast<std::streamsize>(file.size() / 2));
    ExitAbruptly(ctx.rank, "halfway through writing " + prtc);
  }
  WriteFileDurably(prtc, std::string_view(reinterpret_cast<const char*>(file.data()), file.size()));
}

}  // namespace prt
