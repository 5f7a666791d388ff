#include "vocabulary/hash.h"

#include <xxhash.h>

#include <cinttypes>
#include <cstdio>

namespace prt {

uint64_t Checksum64(const void* data, std::size_t bytes) {
  return XXH64(data, bytes, 0);
}

std::string Hex16(uint64_t value) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016" PRIx64, value);
  return buf;
}

}  // namespace prt
