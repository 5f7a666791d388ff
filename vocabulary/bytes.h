// Little-endian bytes: the one writer and the one bounded reader that prtfarm's binary messages
// and files are built with (formats/, packager/, the farm's job messages, the image readers of
// vocabulary/). Values are copied as the host holds them; prtfarm's formats are little-endian and
// require a little-endian host.
//
// Three tools, one per shape of data:
// - ByteWriter / ByteVectorWriter append values (and LEB128 varints) to a byte string;
// - ByteReader reads them back in order from a byte range, never past its end;
// - LoadAt / StoreAt read and write one value at a fixed offset of a layout whose size the caller
//   has checked (a file header, a table entry), still bounds-checked; SliceAt cuts such a layout
//   out of a larger range.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace prt {

static_assert(std::endian::native == std::endian::little,
              "prtfarm's file formats are little-endian; this host is not");

namespace bytes_detail {
[[noreturn]] inline void OutOfRange(const char* op, std::size_t offset, std::size_t n,
                                    std::size_t size) {
  throw std::out_of_range(std::string(op) + ": bytes [" + std::to_string(offset) + ", +" +
                          std::to_string(n) + ") lie outside a range of " + std::to_string(size) +
                          " bytes");
}
}  // namespace bytes_detail

// The value at `offset` of a byte range. The caller checks the range first, with a message that
// names its file; an offset outside it here is a bug of the caller's and throws std::out_of_range
// instead of reading past the end.
template <typename T>
T LoadAt(std::span<const uint8_t> bytes, std::size_t offset) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (offset > bytes.size() || sizeof(T) > bytes.size() - offset)
    bytes_detail::OutOfRange("LoadAt", offset, sizeof(T), bytes.size());
  T v;
  std::memcpy(&v, bytes.data() + offset, sizeof(T));
  return v;
}
template <typename T>
T LoadAt(std::string_view bytes, std::size_t offset) {
  return LoadAt<T>(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
      offset);
}

// Writes `v` at `offset` of a byte range (bounded as LoadAt is).
template <typename T>
void StoreAt(std::span<uint8_t> bytes, std::size_t offset, const T& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (offset > bytes.size() || sizeof(T) > bytes.size() - offset)
    bytes_detail::OutOfRange("StoreAt", offset, sizeof(T), bytes.size());
  std::memcpy(bytes.data() + offset, &v, sizeof(T));
}

// Bytes [offset, offset + n) of a range (a table entry, say), bounded as LoadAt is; unlike
// std::span::subspan, a range outside `bytes` throws instead of being undefined behaviour.
inline std::span<const uint8_t> SliceAt(std::span<const uint8_t> bytes, std::size_t offset,
                                        std::size_t n) {
  if (offset > bytes.size() || n > bytes.size() - offset)
    bytes_detail::OutOfRange("SliceAt", offset, n, bytes.size());
  return bytes.subspan(offset, n);
}
inline std::span<uint8_t> SliceAt(std::span<uint8_t> bytes, std::size_t offset, std::size_t n) {
  if (offset > bytes.size() || n > bytes.size() - offset)
    bytes_detail::OutOfRange("SliceAt", offset, n, bytes.size());
  return bytes.subspan(offset, n);
}

// Appends values to a byte string: std::string (ByteWriter) or std::vector<uint8_t>
// (ByteVectorWriter), whichever the caller hands on, so that nothing is copied to convert.
template <typename Bytes>
class BasicByteWriter {
  static_assert(sizeof(typename Bytes::value_type) == 1);

 public:
  BasicByteWriter() = default;
  // Appends after `prefix` (a message's envelope, say), which is moved in, not copied.
  explicit BasicByteWriter(Bytes prefix) : bytes_(std::move(prefix)) {}
  template <typename T>
  void Put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    PutBytes(&v, sizeof(T));
  }
  void PutBytes(const void* data, std::size_t n) {
    if (n == 0) return;
    const auto* p = static_cast<const typename Bytes::value_type*>(data);
    if constexpr (std::is_same_v<Bytes, std::string>) {
      bytes_.append(p, n);
    } else {
      bytes_.insert(bytes_.end(), p, p + n);
    }
  }
  // The element count (uint64) then the elements.
  template <typename T>
  void PutVector(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    Put(static_cast<uint64_t>(v.size()));
    PutBytes(v.data(), v.size() * sizeof(T));
  }
  // LEB128 (protocol buffers' base-128 varint): 7 bits a byte, low bits first, the high bit set
  // on every byte but the last.
  void PutVarint(uint64_t v) {
    while (v >= 0x80) {
      bytes_.push_back(static_cast<typename Bytes::value_type>(v | 0x80));
      v >>= 7;
    }
    bytes_.push_back(static_cast<typename Bytes::value_type>(v));
  }
  // The message's size in advance: growing a 20 MiB string by doubling copies it ~twice over.
  void Reserve(std::size_t bytes) { bytes_.reserve(bytes); }
  std::size_t size() const { return bytes_.size(); }
  Bytes& bytes() { return bytes_; }

 private:
  Bytes bytes_;
};
using ByteWriter = BasicByteWriter<std::string>;
using ByteVectorWriter = BasicByteWriter<std::vector<uint8_t>>;

// Reads values from a byte range, never past its end. Safe on untrusted input: a read that does
// not fit calls `truncated(what, at)`, which must throw (the caller's error names its file or
// message). The handler runs only on failure: a read that fits costs a compare and a copy.
class ByteReader {
 public:
  using Truncated = std::function<void(const char* what, std::size_t at)>;
  // Reads from byte `at` on (an `at` past the end starts at the end).
  ByteReader(std::string_view bytes, Truncated truncated, std::size_t at = 0)
      : bytes_(bytes),
        truncated_(std::move(truncated)),
        at_(at < bytes.size() ? at : bytes.size()) {}
  ByteReader(std::span<const uint8_t> bytes, Truncated truncated, std::size_t at = 0)
      : ByteReader(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()),
                   std::move(truncated), at) {}

  template <typename T>
  T Get(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    Need(sizeof(T), what);
    T v;
    std::memcpy(&v, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return v;
  }
  // `n` bytes as a view into the range.
  std::string_view Take(std::size_t n, const char* what) {
    Need(n, what);
    const std::string_view s = bytes_.substr(at_, n);
    at_ += n;
    return s;
  }
  void Skip(std::size_t n, const char* what) {
    Need(n, what);
    at_ += n;
  }
  // A PutVector's elements; the count is checked against the bytes left before anything is
  // allocated.
  template <typename T>
  std::vector<T> GetVector(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    const uint64_t n = Get<uint64_t>(what);
    if (n > remaining() / sizeof(T)) Fail(what);
    std::vector<T> v(static_cast<std::size_t>(n));
    // An empty vector's data() may be null, and memcpy's pointers must not be (UBSan:
    // nonnull-attribute), even for zero bytes.
    if (!v.empty()) std::memcpy(v.data(), bytes_.data() + at_, v.size() * sizeof(T));
    at_ += v.size() * sizeof(T);
    return v;
  }
  // A PutVarint's value as U (uint32_t or uint64_t): std::nullopt, with the bytes read, when the
  // encoding is longer than U needs (5 bytes for 32 bits, 10 for 64) or the value does not fit
  // U; the caller names that error. A varint cut off by the end of the range is truncated. One
  // bounds check per varint, not per byte: varints are most of what the transport and visibility
  // decoders read.
  template <typename U>
  std::optional<U> GetVarint(const char* what) {
    static_assert(std::is_same_v<U, uint32_t> || std::is_same_v<U, uint64_t>);
    constexpr int kBits = std::numeric_limits<U>::digits;
    constexpr std::size_t kMaxBytes = (kBits + 6) / 7;
    const std::size_t n = remaining() < kMaxBytes ? remaining() : kMaxBytes;
    U v = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const auto b = static_cast<uint8_t>(bytes_[at_ + i]);
      const int shift = 7 * static_cast<int>(i);
      // The last byte that U can hold carries kBits − shift value bits.
      if (kBits - shift < 7 && ((b & 0x7fu) >> (kBits - shift)) != 0) {
        at_ += i + 1;
        return std::nullopt;
      }
      v |= static_cast<U>(static_cast<U>(b & 0x7fu) << shift);
      if ((b & 0x80u) == 0) {
        at_ += i + 1;
        return v;
      }
    }
    at_ += n;
    if (n == kMaxBytes) return std::nullopt;  // longer than U needs
    Fail(what);                               // the range ends inside the varint
  }
  void Need(std::size_t n, const char* what) const {
    if (n > remaining()) Fail(what);
  }
  std::size_t remaining() const { return bytes_.size() - at_; }
  std::size_t position() const { return at_; }
  // The bytes not read yet, to look ahead (a magic number, a line) without moving.
  std::string_view rest() const { return bytes_.substr(at_); }

 private:
  // Out of line and cold: the reads that fit stay small enough to inline.
  [[noreturn, gnu::cold, gnu::noinline]] void Fail(const char* what) const {
    truncated_(what, at_);
    throw std::logic_error("ByteReader: the truncation handler returned");
  }
  std::string_view bytes_;
  Truncated truncated_;
  std::size_t at_;  // ≤ bytes_.size()
};

}  // namespace prt
