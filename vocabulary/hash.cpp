#include "vocabulary/hash.h"

#include <xxhash.h>

namespace prt {

uint64_t Checksum64(const void* data, std::size_t bytes) {
  return XXH64(data, bytes, 0);
}

}  // namespace prt
