// vocabulary/bytes.h: the exact bytes the writers produce, and the bounds every reader keeps.
#include "vocabulary/bytes.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace prt {
namespace {

struct Truncated : std::runtime_error {
  Truncated(const std::string& what, std::size_t at)
      : std::runtime_error(what + " at " + std::to_string(at)) {}
};

ByteReader Reader(std::string_view bytes) {
  return ByteReader(bytes, [](const char* what, std::size_t at) { throw Truncated(what, at); });
}

std::string Message(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

TEST(Bytes, WritersAppendLittleEndianBytesAndAgree) {
  ByteWriter w;
  w.Put<uint32_t>(0x04030201u);
  w.Put<uint16_t>(0xBEEF);
  w.Put<float>(1.0f);  // 0x3f800000
  w.PutVarint(300);    // 0xAC 0x02
  EXPECT_EQ(w.bytes(), std::string("\x01\x02\x03\x04\xEF\xBE\x00\x00\x80\x3F\xAC\x02", 12));
  ByteVectorWriter v;
  v.Put<uint32_t>(0x04030201u);
  v.Put<uint16_t>(0xBEEF);
  v.Put<float>(1.0f);
  v.PutVarint(300);
  EXPECT_EQ(std::string(v.bytes().begin(), v.bytes().end()), w.bytes());
  EXPECT_EQ(v.size(), 12u);
}

TEST(Bytes, VarintsRoundTripAtTheirLimits) {
  ByteWriter w;
  const std::vector<uint64_t> values = {0,     1,     127,           128,
                                        16383, 16384, 0xFFFFFFFFull, 0xFFFFFFFFFFFFFFFFull};
  for (uint64_t x : values) w.PutVarint(x);
  // 2^32 − 1 takes five bytes, 2^64 − 1 ten.
  EXPECT_EQ(w.size(), 1u + 1 + 1 + 2 + 2 + 3 + 5 + 10);
  ByteReader r = Reader(w.bytes());
  for (uint64_t x : values) EXPECT_EQ(r.GetVarint<uint64_t>("v"), x);
  EXPECT_EQ(r.remaining(), 0u);
  ByteReader r32 = Reader(w.bytes());
  for (std::size_t i = 0; i + 1 < values.size(); ++i)
    EXPECT_EQ(r32.GetVarint<uint32_t>("v"), values[i]);
  // 2^64 − 1 does not fit 32 bits: refused after the fifth byte.
  EXPECT_EQ(r32.GetVarint<uint32_t>("v"), std::nullopt);
  EXPECT_EQ(r32.remaining(), 5u);
}

TEST(Bytes, OverlongAndOverflowingVarintsAreRefused) {
  // 2^32: the fifth byte carries a fifth value bit.
  EXPECT_EQ(Reader(std::string("\x80\x80\x80\x80\x10", 5)).GetVarint<uint32_t>("v"), std::nullopt);
  EXPECT_EQ(Reader(std::string("\x80\x80\x80\x80\x10", 5)).GetVarint<uint64_t>("v"),
            uint64_t{1} << 32);
  // A sixth byte for 32 bits, an eleventh for 64.
  EXPECT_EQ(Reader(std::string("\x80\x80\x80\x80\x80\x00", 6)).GetVarint<uint32_t>("v"),
            std::nullopt);
  EXPECT_EQ(Reader(std::string(10, '\x80') + '\0').GetVarint<uint64_t>("v"), std::nullopt);
  // 2^64: the tenth byte may hold one bit only.
  EXPECT_EQ(Reader(std::string(9, '\x80') + '\x02').GetVarint<uint64_t>("v"), std::nullopt);
  EXPECT_EQ(Reader(std::string(9, '\x80') + '\x01').GetVarint<uint64_t>("v"), uint64_t{1} << 63);
  // Cut off: the truncation handler, with the field and the byte.
  EXPECT_EQ(Message([] { Reader(std::string("\x80\x80", 2)).GetVarint<uint32_t>("count"); }),
            "count at 2");
}

TEST(Bytes, ReaderStopsAtTheEndAndNamesTheField) {
  ByteWriter w;
  w.Put<uint32_t>(7);
  w.PutBytes("abc", 3);
  ByteReader r = Reader(w.bytes());
  EXPECT_EQ(r.rest().size(), 7u);
  EXPECT_EQ(r.Get<uint32_t>("n"), 7u);
  EXPECT_EQ(r.rest(), "abc");
  EXPECT_EQ(Message([&] { r.Skip(4, "name"); }), "name at 4");
  r.Skip(1, "name");
  EXPECT_EQ(r.position(), 5u);
  EXPECT_EQ(r.Take(2, "name"), "bc");
  EXPECT_EQ(r.remaining(), 0u);
  EXPECT_EQ(Message([&] { r.Get<uint8_t>("tail"); }), "tail at 7");
  // A vector whose count exceeds what is left is refused before anything is allocated.
  ByteWriter v;
  v.Put<uint64_t>(uint64_t{1} << 60);
  ByteReader rv = Reader(v.bytes());
  EXPECT_EQ(Message([&] { rv.GetVector<double>("sums"); }), "sums at 8");
}

TEST(Bytes, LoadAtAndStoreAtStayInsideTheirRange) {
  std::vector<uint8_t> b(12, 0);
  StoreAt<uint64_t>(b, 4, 0x0807060504030201ull);
  EXPECT_EQ(b[4], 0x01);
  EXPECT_EQ(b[11], 0x08);
  EXPECT_EQ(LoadAt<uint32_t>(b, 4), 0x04030201u);
  EXPECT_EQ(LoadAt<uint64_t>(b, 4), 0x0807060504030201ull);
  EXPECT_EQ(LoadAt<uint16_t>(std::string_view("\x34\x12", 2), 0), 0x1234);
  EXPECT_THROW(LoadAt<uint64_t>(b, 5), std::out_of_range);
  EXPECT_THROW(LoadAt<uint32_t>(b, std::size_t{1} << 62), std::out_of_range);
  EXPECT_THROW(StoreAt<uint32_t>(b, 9, 0u), std::out_of_range);
  EXPECT_EQ(b[9], 0x06);  // untouched
}

}  // namespace
}  // namespace prt
