// Writing transport.prtc, which both compression schemes' phases do the same way
// (farm/compression_phase.cpp, farm/cpca_phase.cpp).
#pragma once

#include <cstdint>
#include <vector>

namespace prt {

struct FarmContext;

// Rank 0 writes transport.prtc durably (temp, fsync, rename, fsync of the folder); with
// --fail-in write (tests of a kill while writing) it dies halfway through, leaving half a
// temporary file.
void WriteCompressedFile(const FarmContext& ctx, const std::vector<uint8_t>& file);

}  // namespace prt
