// XXH64 checksums of .prtpack sections and of the header + section table
// (docs/prtpack-format.md, "File header").
#include <xxhash.h>

#include <span>

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

void ResealTransport(std::span<uint8_t> sec) {
  const uint64_t n = sec.size();
  if (n < kTransportHeaderSize) return;
  const uint32_t block_count = LoadAt<uint32_t>(sec, kTransportBlockCount);
  const uint32_t params_size = LoadAt<uint32_t>(sec, kTransportParamsSize);
  const uint64_t index_offset = AlignUp(kTransportHeaderSize + uint64_t(params_size), 8);
  const uint64_t index_size = uint64_t(block_count) * kBlockEntrySize;
  if (!Inside(index_offset, index_size, n)) return;
  for (uint32_t b = 0; b < block_count; ++b) {
    const std::span<uint8_t> e =
        SliceAt(sec, index_offset + uint64_t(b) * kBlockEntrySize, kBlockEntrySize);
    const uint64_t offset = LoadAt<uint64_t>(e, 16), stored = LoadAt<uint64_t>(e, 24);
    if (Inside(offset, stored, n)) StoreAt<uint64_t>(e, 40, Checksum(sec.data() + offset, stored));
  }
  StoreAt<uint64_t>(sec, kTransportIndexChecksum,
                    TransportIndexChecksum(sec.data(), params_size, index_offset, block_count));
}
}  // namespace

void ResealChecksums(std::vector<uint8_t>& file) {
  const uint64_t n = file.size();
  if (n < kHeaderSize) return;
  const std::span<uint8_t> d(file);
  const uint32_t count = LoadAt<uint32_t>(d, kHdrSectionCount);
  const uint32_t entry_size = LoadAt<uint32_t>(d, kHdrEntrySize);
  const uint64_t table_offset = LoadAt<uint64_t>(d, kHdrTableOffset);
  if (count > kMaxSectionCount || entry_size < kEntrySize || entry_size > 4096) return;
  const uint64_t table_size = uint64_t(count) * entry_size;
  if (!Inside(table_offset, table_size, n)) return;
  for (uint32_t i = 0; i < count; ++i) {
    const std::span<uint8_t> e = SliceAt(d, table_offset + uint64_t(i) * entry_size, entry_size);
    const uint64_t offset = LoadAt<uint64_t>(e, kSecOffset),
                   stored = LoadAt<uint64_t>(e, kSecStored);
    if (!Inside(offset, stored, n)) continue;
    if (LoadAt<uint32_t>(e, kSecType) == kTypeTransport)
      ResealTransport(SliceAt(d, offset, stored));
    StoreAt<uint64_t>(e, kSecChecksum, Checksum(d.data() + offset, stored));
  }
  StoreAt<uint64_t>(d, kHdrChecksum, HeaderChecksum(d.data(), d.data() + table_offset, table_size));
}

}  // namespace prt::pack
