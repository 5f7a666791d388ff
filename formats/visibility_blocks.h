// Per-vertex visibility cubemaps in the block-differential representation of Inger, Farbman &
// Lischinski 2013, "Locally Adaptive Products for All-Frequency Relighting", §4.2.
//
// A visibility map is a cubemap of 6·n·n texels (vocabulary/cubemap.h layout, n a multiple of 16
// in [16, 256]) holding quantised visibility levels 0 … L, L = 2^bits − 1 (bits = 1: binary
// visibility, one ray per texel centre; bits 2 … 8: anti-aliased visibility from a supersampled
// binary map, §4.2 and Figure 3). Each face is cut into 16×16 blocks; block b of a map is
//   b = face·(n/16)² + by·(n/16) + bx,   local position k = y·16 + x ∈ [0, 256)
// (the rows of the block concatenated, "the visibility vector V"). A block is
//   kZero  every level 0      (costs nothing at relighting, Algorithm 1 line 1)
//   kOne   every level L      (Algorithm 1 line 5)
//   kMixed anything else, stored as its derivative V_d = D·V (Eq. 5, V[−1] = 0): the sorted
//          positions k where V changes and, for bits > 1, the signed change V[k] − V[k−1].
//          For binary maps the changes alternate +1, −1, … and are not stored (§4.2: "we avoid
//          storing the visibility derivative values and store only the indices").
// The representation is lossless: DecodeVisibilityMap(Build(map)) == map.
//
// Serialised form (EncodeVisibilityBlocks), all integers base-128 varints (protocol buffers):
//   magic 'V' 'B', version 1, n, bits, vertex count, then per vertex:
//     kinds of its blocks, 2 bits each (0 zero, 1 one, 2 mixed), packed 4 per byte, LSB first;
//     for each mixed block in order: change count c ∈ [1, 256], then c entries
//       gap (first: k₀; then kᵢ − kᵢ₋₁ − 1) and, for bits > 1, zigzag(V[k] − V[k−1]).
// DecodeVisibilityBlocks is safe on untrusted input: every count is checked against the bytes
// left and every position, change and running level against its range; it throws
// prt::InputError naming `source` and the vertex/block at fault, never reads out of bounds and
// never allocates more than a small multiple of the input size.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace prt {

inline constexpr int kVisibilityBlockSide = 16;
inline constexpr int kVisibilityBlockSize = 256;  // texels per block

enum class VisibilityBlockKind : uint8_t { kZero = 0, kOne = 1, kMixed = 2 };

// Blocks of 6·n·n texel maps of many vertices, flattened: vertex v's block b is entry
// v·blocks_per_map() + b. Changes of entry e are change_pos[change_begin[e] … change_begin[e+1]).
struct VisibilityBlocks {
  int n = 0;     // cubemap resolution, a multiple of 16 in [16, 256]
  int bits = 1;  // 1: binary; 2…8: quantised anti-aliased levels
  std::size_t vertex_count = 0;
  std::vector<uint8_t> kind;           // VisibilityBlockKind per entry
  std::vector<uint64_t> change_begin;  // entries + 1 offsets (starts with 0)
  std::vector<uint8_t> change_pos;     // positions k where V changes, increasing per block
  std::vector<int16_t> change_value;   // bits > 1 only: V[k] − V[k−1] (≠ 0)

  int max_level() const { return (1 << bits) - 1; }
  int blocks_per_face() const { return (n / kVisibilityBlockSide) * (n / kVisibilityBlockSide); }
  int blocks_per_map() const { return 6 * blocks_per_face(); }
  std::size_t texels_per_map() const { return static_cast<std::size_t>(6) * n * n; }
  std::size_t Entry(std::size_t vertex, int block) const {
    return vertex * static_cast<std::size_t>(blocks_per_map()) + static_cast<std::size_t>(block);
  }
  // In-memory size in bytes of the arrays (kind, offsets, positions, values).
  std::size_t MemoryBytes() const;
};

// Empty blocks for maps of resolution n and `bits` bits per level; throws std::invalid_argument
// when n is not a multiple of 16 in [16, 256] or bits is outside [1, 8].
VisibilityBlocks MakeVisibilityBlocks(int n, int bits);

// Texel index (vocabulary/cubemap.h) of position k of block b of a resolution-n map.
std::size_t VisibilityBlockTexel(int n, int block, int k);

// Appends one vertex's map: `levels` holds 6·n·n levels in texel order, each ≤ max_level()
// (std::invalid_argument otherwise). Derivative representation of §4.2, Eq. 5.
void AppendVisibilityMap(VisibilityBlocks& blocks, std::span<const uint8_t> levels);
// Appends every vertex of `more` (same n and bits, std::invalid_argument otherwise).
void AppendVisibilityBlocks(VisibilityBlocks& blocks, const VisibilityBlocks& more);

// Levels of one block (256 values, row-concatenated) and of a whole map (6·n·n, texel order)
// expanded back from the derivative representation.
void DecodeVisibilityBlock(const VisibilityBlocks& blocks, std::size_t vertex, int block,
                           uint8_t* levels);
std::vector<uint8_t> DecodeVisibilityMap(const VisibilityBlocks& blocks, std::size_t vertex);

// Serialisation (format above). Encoding is deterministic.
std::vector<uint8_t> EncodeVisibilityBlocks(const VisibilityBlocks& blocks);
VisibilityBlocks DecodeVisibilityBlocks(std::span<const uint8_t> bytes,
                                        const std::string& source = "<visibility blocks>");

struct VisibilityBlockCounts {
  std::size_t zero = 0, one = 0, mixed = 0;
  std::size_t changes = 0;  // stored positions (the paper's "coefficients", Table 3)
};
VisibilityBlockCounts CountVisibilityBlocks(const VisibilityBlocks& blocks);

// Base-128 varint helpers (protocol buffers), shared with the benchmark's Haar coder.
void AppendVarint(std::vector<uint8_t>& out, uint64_t value);
inline uint64_t ZigZag(int64_t v) {
  return (static_cast<uint64_t>(v) << 1) ^ static_cast<uint64_t>(v >> 63);
}

}  // namespace prt
