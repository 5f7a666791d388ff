#include "formats/visibility_blocks.h"

#include <algorithm>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

void CheckShape(int n, int bits) {
  if (n < 16 || n > 256 || n % kVisibilityBlockSide != 0)
    throw std::invalid_argument("visibility blocks: n must be a multiple of 16 in [16, 256]");
  if (bits < 1 || bits > 8)
    throw std::invalid_argument("visibility blocks: bits must be in [1, 8]");
}

// The stream's reader: every failure throws InputError naming the source and the byte.
ByteReader StreamReader(std::span<const uint8_t> bytes, const std::string& source) {
  return ByteReader(bytes, [&source](const char* what, std::size_t at) {
    throw InputError(source, std::string("truncated while reading ") + what + " (byte " +
                                 std::to_string(at) + ")");
  });
}
[[noreturn]] void Fail(const ByteReader& in, const std::string& source, const std::string& what) {
  throw InputError(source, what + " (byte " + std::to_string(in.position()) + ")");
}
// Out of line, so that Varint needs no stack frame for the message.
[[noreturn, gnu::cold, gnu::noinline]] void BadVarint(const ByteReader& in,
                                                      const std::string& source, const char* what) {
  Fail(in, source, std::string("varint longer than 10 bytes or above 2^64 in ") + what);
}
uint64_t Varint(ByteReader& in, const std::string& source, const char* what) {
  const std::optional<uint64_t> v = in.GetVarint<uint64_t>(what);
  if (!v) BadVarint(in, source, what);
  return *v;
}

}  // namespace

std::size_t VisibilityBlocks::MemoryBytes() const {
  return kind.size() + change_begin.size() * sizeof(uint64_t) + change_pos.size() +
         change_value.size() * sizeof(int16_t);
}

VisibilityBlocks MakeVisibilityBlocks(int n, int bits) {
  CheckShape(n, bits);
  VisibilityBlocks b;
  b.n = n;
  b.bits = bits;
  b.change_begin.push_back(0);
  return b;
}

std::size_t VisibilityBlockTexel(int n, int block, int k) {
  const int per_side = n / kVisibilityBlockSide;
  const int face = block / (per_side * per_side);
  const int rem = block % (per_side * per_side);
  const int by = rem / per_side, bx = rem % per_side;
  const int x = bx * kVisibilityBlockSide + (k & 15), y = by * kVisibilityBlockSide + (k >> 4);
  return (static_cast<std::size_t>(face) * n + y) * n + x;
}

// §4.2, Eq. 5: V_d = D·V with V[−1] = 0; a block is stored as the positions where V_d ≠ 0
// (and the non-zero V_d values themselves when the map is not binary).
void AppendVisibilityMap(VisibilityBlocks& blocks, std::span<const uint8_t> levels) {
  if (levels.size() != blocks.texels_per_map())
    throw std::invalid_argument("AppendVisibilityMap: map has the wrong number of texels");
  const int max_level = blocks.max_level();
  const int nb = blocks.blocks_per_map();
  uint8_t v[kVisibilityBlockSize];
  for (int b = 0; b < nb; ++b) {
    bool all_zero = true, all_one = true;
    for (int k = 0; k < kVisibilityBlockSize; ++k) {
      v[k] = levels[VisibilityBlockTexel(blocks.n, b, k)];
      if (v[k] > max_level)
        throw std::invalid_argument("AppendVisibilityMap: level above 2^bits − 1");
      all_zero &= v[k] == 0;
      all_one &= v[k] == max_level;
    }
    if (all_zero) {
      blocks.kind.push_back(static_cast<uint8_t>(VisibilityBlockKind::kZero));
    } else if (all_one) {
      blocks.kind.push_back(static_cast<uint8_t>(VisibilityBlockKind::kOne));
    } else {
      blocks.kind.push_back(static_cast<uint8_t>(VisibilityBlockKind::kMixed));
      int prev = 0;
      for (int k = 0; k < kVisibilityBlockSize; ++k) {
        if (v[k] != prev) {
          blocks.change_pos.push_back(static_cast<uint8_t>(k));
          if (blocks.bits > 1) blocks.change_value.push_back(static_cast<int16_t>(v[k] - prev));
          prev = v[k];
        }
      }
    }
    blocks.change_begin.push_back(blocks.change_pos.size());
  }
  ++blocks.vertex_count;
}

void AppendVisibilityBlocks(VisibilityBlocks& blocks, const VisibilityBlocks& more) {
  if (blocks.n != more.n || blocks.bits != more.bits)
    throw std::invalid_argument("AppendVisibilityBlocks: different n or bits");
  const uint64_t base = blocks.change_pos.size();
  blocks.kind.insert(blocks.kind.end(), more.kind.begin(), more.kind.end());
  blocks.change_pos.insert(blocks.change_pos.end(), more.change_pos.begin(), more.change_pos.end());
  blocks.change_value.insert(blocks.change_value.end(), more.change_value.begin(),
                             more.change_value.end());
  for (std::size_t i = 1; i < more.change_begin.size(); ++i)
    blocks.change_begin.push_back(base + more.change_begin[i]);
  blocks.vertex_count += more.vertex_count;
}

void DecodeVisibilityBlock(const VisibilityBlocks& blocks, std::size_t vertex, int block,
                           uint8_t* levels) {
  const std::size_t e = blocks.Entry(vertex, block);
  const auto kind = static_cast<VisibilityBlockKind>(blocks.kind[e]);
  if (kind != VisibilityBlockKind::kMixed) {
    std::fill(levels, levels + kVisibilityBlockSize,
              kind == VisibilityBlockKind::kOne ? static_cast<uint8_t>(blocks.max_level()) : 0);
    return;
  }
  int level = 0, k = 0;
  for (uint64_t i = blocks.change_begin[e]; i < blocks.change_begin[e + 1]; ++i) {
    const int pos = blocks.change_pos[i];
    for (; k < pos; ++k) levels[k] = static_cast<uint8_t>(level);
    level = blocks.bits == 1 ? 1 - level : level + blocks.change_value[i];
  }
  for (; k < kVisibilityBlockSize; ++k) levels[k] = static_cast<uint8_t>(level);
}

std::vector<uint8_t> DecodeVisibilityMap(const VisibilityBlocks& blocks, std::size_t vertex) {
  std::vector<uint8_t> map(blocks.texels_per_map());
  uint8_t v[kVisibilityBlockSize];
  for (int b = 0; b < blocks.blocks_per_map(); ++b) {
    DecodeVisibilityBlock(blocks, vertex, b, v);
    for (int k = 0; k < kVisibilityBlockSize; ++k) map[VisibilityBlockTexel(blocks.n, b, k)] = v[k];
  }
  return map;
}

void AppendVarint(std::vector<uint8_t>& out, uint64_t value) {
  ByteVectorWriter w(std::move(out));
  w.PutVarint(value);
  out = std::move(w.bytes());
}

std::vector<uint8_t> EncodeVisibilityBlocks(const VisibilityBlocks& blocks) {
  ByteVectorWriter w;
  w.PutBytes("VB", 2);
  w.PutVarint(1);
  w.PutVarint(static_cast<uint64_t>(blocks.n));
  w.PutVarint(static_cast<uint64_t>(blocks.bits));
  w.PutVarint(blocks.vertex_count);
  const int nb = blocks.blocks_per_map();
  for (std::size_t v = 0; v < blocks.vertex_count; ++v) {
    const std::size_t e0 = blocks.Entry(v, 0);
    for (int b = 0; b < nb; b += 4) {
      uint8_t packed = 0;
      for (int i = 0; i < 4 && b + i < nb; ++i)
        packed = static_cast<uint8_t>(packed | (blocks.kind[e0 + b + i] << (2 * i)));
      w.Put<uint8_t>(packed);
    }
    for (int b = 0; b < nb; ++b) {
      const std::size_t e = e0 + b;
      if (blocks.kind[e] != static_cast<uint8_t>(VisibilityBlockKind::kMixed)) continue;
      const uint64_t first = blocks.change_begin[e], last = blocks.change_begin[e + 1];
      w.PutVarint(last - first);
      int prev = -1;
      for (uint64_t i = first; i < last; ++i) {
        w.PutVarint(static_cast<uint64_t>(blocks.change_pos[i] - prev - 1));
        prev = blocks.change_pos[i];
        if (blocks.bits > 1) w.PutVarint(ZigZag(blocks.change_value[i]));
      }
    }
  }
  return std::move(w.bytes());
}

VisibilityBlocks DecodeVisibilityBlocks(std::span<const uint8_t> bytes, const std::string& source) {
  ByteReader in = StreamReader(bytes, source);
  if (in.Get<uint8_t>("magic") != 'V' || in.Get<uint8_t>("magic") != 'B')
    Fail(in, source, "not a visibility block stream");
  if (Varint(in, source, "version") != 1) Fail(in, source, "unsupported version");
  const uint64_t n = Varint(in, source, "n"), bits = Varint(in, source, "bits");
  if (n < 16 || n > 256 || n % 16 != 0) Fail(in, source, "n is not a multiple of 16 in [16, 256]");
  if (bits < 1 || bits > 8) Fail(in, source, "bits outside [1, 8]");
  VisibilityBlocks out = MakeVisibilityBlocks(static_cast<int>(n), static_cast<int>(bits));
  const uint64_t vertices = Varint(in, source, "vertex count");
  const int nb = out.blocks_per_map();
  const std::size_t kind_bytes = static_cast<std::size_t>(nb + 3) / 4;
  // Every vertex needs at least its kind bytes: bounds the allocation by the input size.
  if (vertices > in.remaining() / kind_bytes) Fail(in, source, "vertex count larger than the data");
  out.kind.reserve(vertices * nb);
  out.change_begin.reserve(vertices * nb + 1);
  const int max_level = out.max_level();
  for (uint64_t v = 0; v < vertices; ++v) {
    const std::size_t e0 = out.kind.size();
    for (std::size_t i = 0; i < kind_bytes; ++i) {
      const uint8_t packed = in.Get<uint8_t>("block kinds");
      for (int j = 0; j < 4; ++j) {
        const int b = static_cast<int>(i) * 4 + j;
        const uint8_t k = static_cast<uint8_t>((packed >> (2 * j)) & 3);
        if (b >= nb) {
          if (k != 0)
            Fail(in, source, "padding bits set in block kinds of vertex " + std::to_string(v));
          continue;
        }
        if (k > 2) Fail(in, source, "invalid block kind at vertex " + std::to_string(v));
        out.kind.push_back(k);
      }
    }
    for (int b = 0; b < nb; ++b) {
      if (out.kind[e0 + b] == static_cast<uint8_t>(VisibilityBlockKind::kMixed)) {
        const std::string where =
            " (vertex " + std::to_string(v) + ", block " + std::to_string(b) + ")";
        const uint64_t count = Varint(in, source, "change count");
        if (count < 1 || count > kVisibilityBlockSize)
          Fail(in, source, "change count out of range" + where);
        if (count > in.remaining()) Fail(in, source, "change count larger than the data" + where);
        int64_t pos = -1;
        int level = 0;
        for (uint64_t c = 0; c < count; ++c) {
          pos += static_cast<int64_t>(
                     std::min<uint64_t>(Varint(in, source, "change position"), 1024)) +
                 1;
          if (pos >= kVisibilityBlockSize)
            Fail(in, source, "change position beyond the block" + where);
          out.change_pos.push_back(static_cast<uint8_t>(pos));
          if (bits > 1) {
            const uint64_t z = Varint(in, source, "change value");
            if (z > 1024) Fail(in, source, "change value out of range" + where);
            const int64_t d = static_cast<int64_t>(z >> 1) ^ -static_cast<int64_t>(z & 1);
            level += static_cast<int>(d);
            if (d == 0 || level < 0 || level > max_level)
              Fail(in, source, "level out of range" + where);
            out.change_value.push_back(static_cast<int16_t>(d));
          } else {
            level = 1 - level;
          }
        }
      }
      out.change_begin.push_back(out.change_pos.size());
    }
    ++out.vertex_count;
  }
  if (in.remaining() != 0) Fail(in, source, "trailing bytes after the last vertex");
  return out;
}

VisibilityBlockCounts CountVisibilityBlocks(const VisibilityBlocks& blocks) {
  VisibilityBlockCounts c;
  for (uint8_t k : blocks.kind) {
    if (k == 0)
      ++c.zero;
    else if (k == 1)
      ++c.one;
    else
      ++c.mixed;
  }
  c.changes = blocks.change_pos.size();
  return c;
}

}  // namespace prt
