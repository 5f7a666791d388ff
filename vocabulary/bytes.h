// Little-endian bytes: the one writer and the one bounded reader that prtfarm's binary messages
// and files are built with (formats/, the farm's job messages). Values are copied as the host
// holds them; prtfarm's formats are little-endian and require a little-endian host.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace prt {

static_assert(std::endian::native == std::endian::little,
              "prtfarm's file formats are little-endian; this host is not");

// Appends values to a byte string.
class ByteWriter {
 public:
  ByteWriter() = default;
  // Appends after `prefix` (a message's envelope, say), which is moved in, not copied.
  explicit ByteWriter(std::string prefix) : bytes_(std::move(prefix)) {}
  template <typename T>
  void Put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void PutBytes(const void* data, std::size_t n) {
    if (n > 0) bytes_.append(static_cast<const char*>(data), n);
  }
  // The element count (uint64) then the elements.
  template <typename T>
  void PutVector(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    Put(static_cast<uint64_t>(v.size()));
    PutBytes(v.data(), v.size() * sizeof(T));
  }
  // The message's size in advance: growing a 20 MiB string by doubling copies it ~twice over.
  void Reserve(std::size_t bytes) { bytes_.reserve(bytes); }
  std::string& bytes() { return bytes_; }

 private:
  std::string bytes_;
};

// Reads values from a byte range, never past its end. Safe on untrusted input: a read that does
// not fit calls `truncated(what, at)`, which must throw (the caller's error names its file or
// message).
class ByteReader {
 public:
  using Truncated = std::function<void(const char* what, std::size_t at)>;
  ByteReader(std::string_view bytes, Truncated truncated, std::size_t at = 0)
      : bytes_(bytes), truncated_(std::move(truncated)), at_(at) {}

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
  void Need(std::size_t n, const char* what) const {
    if (n > remaining()) Fail(what);
  }
  std::size_t remaining() const { return at_ <= bytes_.size() ? bytes_.size() - at_ : 0; }
  std::size_t position() const { return at_; }

 private:
  [[noreturn]] void Fail(const char* what) const {
    truncated_(what, at_);
    throw std::logic_error("ByteReader: the truncation handler returned");
  }
  std::string_view bytes_;
  Truncated truncated_;
  std::size_t at_;
};

}  // namespace prt
