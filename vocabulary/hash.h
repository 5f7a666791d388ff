// The hashes every stage shares: one checksum for every prtfarm file format and message, one
// counter-based mixer for every deterministic random number.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace prt {

// XXH64 (seed 0) of a byte range: the checksum of every prtfarm file format and farm message.
uint64_t Checksum64(const void* data, std::size_t bytes);
// A 64-bit hash as 16 lower-case hex digits (journal lines, manifest keys).
std::string Hex16(uint64_t value);

// SplitMix64 (Steele, Lea & Flood 2014): a bijective 64-bit mixer, used as a counter-based hash
// so that a random number is a pure function of its key (no generator state to carry or share).
constexpr uint64_t SplitMix64(uint64_t z) {
  z += 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

}  // namespace prt
