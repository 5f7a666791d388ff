// XXH64 checksums of .prtpack sections and of the header + section table
// (docs/prtpack-format.md, "File header").
#include <xxhash.h>

#include "packager/prtpack_format.h"

namespace prt::pack {

uint64_t Checksum(const uint8_t* data, std::size_t size) {
  return XXH64(data, size, 0);
}

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

namespace {
bool Inside(uint64_t offset, uint64_t size, uint64_t limit) {
  return offset <= limit && size <= limit - offset;
}

void ResealTransport(uint8_t* p, uint64_t n) {
  if (n < kTransportHeaderSize) return;
  const uint32_t block_count = LoadU32(p + 4);
  const uint32_t params_size = LoadU32(p + 24);
  const uint64_t index_offset = AlignUp(kTransportHeaderSize + uint64_t(params_size), 8);
  const uint64_t index_size = uint64_t(block_count) * kBlockEntrySize;
  if (!Inside(index_offset, index_size, n)) return;
  for (uint32_t b = 0; b < block_count; ++b) {
    uint8_t* e = p + index_offset + uint64_t(b) * kBlockEntrySize;
    const uint64_t offset = LoadU64(e + 16), stored = LoadU64(e + 24);
    if (Inside(offset, stored, n)) StoreU64(e + 40, Checksum(p + offset, stored));
  }
  StoreU64(p + 32, TransportIndexChecksum(p, params_size, index_offset, block_count));
}
}  // namespace

void ResealChecksums(std::vector<uint8_t>& file) {
  const uint64_t n = file.size();
  if (n < kHeaderSize) return;
  uint8_t* d = file.data();
  const uint32_t count = LoadU32(d + kHdrSectionCount);
  const uint32_t entry_size = LoadU32(d + kHdrEntrySize);
  const uint64_t table_offset = LoadU64(d + kHdrTableOffset);
  if (count > kMaxSectionCount || entry_size < kEntrySize || entry_size > 4096) return;
  const uint64_t table_size = uint64_t(count) * entry_size;
  if (!Inside(table_offset, table_size, n)) return;
  for (uint32_t i = 0; i < count; ++i) {
    uint8_t* e = d + table_offset + uint64_t(i) * entry_size;
    const uint64_t offset = LoadU64(e + kSecOffset), stored = LoadU64(e + kSecStored);
    if (!Inside(offset, stored, n)) continue;
    if (LoadU32(e + kSecType) == kTypeTransport) ResealTransport(d + offset, stored);
    StoreU64(e + kSecChecksum, Checksum(d + offset, stored));
  }
  StoreU64(d + kHdrChecksum, HeaderChecksum(d, d + table_offset, table_size));
}

}  // namespace prt::pack
