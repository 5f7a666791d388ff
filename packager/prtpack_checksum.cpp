// XXH64 checksums of .prtpack sections and of the header + section table
// (docs/prtpack-format.md, "File header").
#include <xxhash.h>

#include "packager/prtpack_format.h"

namespace prt::pack {

uint64_t Checksum(const uint8_t* data, std::size_t size) { return XXH64(data, size, 0); }

uint64_t HeaderChecksum(const uint8_t* header, const uint8_t* table, std::size_t table_size) {
  XXH64_state_t* state = XXH64_createState();
  XXH64_reset(state, 0);
  XXH64_update(state, header, kHdrChecksum);
  XXH64_update(state, table, table_size);
  const uint64_t h = XXH64_digest(state);
  XXH64_freeState(state);
  return h;
}

uint64_t TransportIndexChecksum(const uint8_t* section, std::size_t params_size,
                                std::size_t index_offset, std::size_t block_count) {
  XXH64_state_t* state = XXH64_createState();
  XXH64_reset(state, 0);
  XXH64_update(state, section, 32);
  XXH64_update(state, section + kTransportHeaderSize, params_size);
  XXH64_update(state, section + index_offset, block_count * kBlockEntrySize);
  const uint64_t h = XXH64_digest(state);
  XXH64_freeState(state);
  return h;
}

}  // namespace prt::pack
