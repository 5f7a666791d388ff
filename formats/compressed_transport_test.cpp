#include "formats/compressed_transport.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "formats/column_coding.h"
#include "vocabulary/bytes.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {
namespace {

// A header over a Hilbert-ordered mesh of 37 vertices and a 6×5 grid, n = 2 (24 columns).
CompressedTransportHeader TestHeader(int bits = 9) {
  CompressedTransportHeader h;
  h.cubemap_n = 2;
  h.bits = static_cast<uint8_t>(bits);
  h.dither_seed = 1234;
  h.terms_per_column = 7;
  SpatialSegment mesh;
  mesh.kind = SpatialSegment::Kind::kMesh1D;
  mesh.count = 37;
  mesh.order.resize(37);
  std::iota(mesh.order.begin(), mesh.order.end(), 0u);
  std::shuffle(mesh.order.begin(), mesh.order.end(), std::mt19937(5));
  SpatialSegment grid;
  grid.kind = SpatialSegment::Kind::kGrid2D;
  grid.count = 30;
  grid.width = 6;
  grid.height = 5;
  h.domain.segments = {mesh, grid};
  h.sample_count = 67;
  return h;
}

CompressedTransport RandomTransport(const CompressedTransportHeader& h, unsigned seed) {
  std::mt19937 rng(seed);
  CompressedTransport t;
  t.header = h;
  const int maxq = QuantiserMax(h.bits);
  const int maxd = MaxColumnDepth(h.domain);
  for (uint32_t j = 0; j < h.column_count(); ++j) {
    if (rng() % 4 == 0) continue;  // all-zero column
    CompressedColumn c;
    c.column = j;
    c.depth = static_cast<uint8_t>(rng() % (maxd + 1));
    c.scale = std::uniform_real_distribution<float>(0.01f, 3.0f)(rng);
    for (uint32_t i = 0; i < h.sample_count; ++i) {
      if (rng() % 3 != 0) continue;
      int q = static_cast<int>(rng() % (2 * maxq + 1)) - maxq;
      if (q == 0) q = 1;
      c.index.push_back(i);
      c.q.push_back(q);
    }
    if (c.index.empty()) {
      c.index.push_back(3);
      c.q.push_back(-maxq);
    }
    t.columns.push_back(std::move(c));
  }
  return t;
}

void ExpectSameTransport(const CompressedTransport& a, const CompressedTransport& b) {
  EXPECT_EQ(EncodeHeader(a.header), EncodeHeader(b.header));
  ASSERT_EQ(a.columns.size(), b.columns.size());
  for (std::size_t k = 0; k < a.columns.size(); ++k) {
    EXPECT_EQ(a.columns[k].column, b.columns[k].column);
    EXPECT_EQ(a.columns[k].depth, b.columns[k].depth);
    EXPECT_EQ(a.columns[k].scale, b.columns[k].scale);
    EXPECT_EQ(a.columns[k].index, b.columns[k].index);
    EXPECT_EQ(a.columns[k].q, b.columns[k].q);
  }
}

TEST(CompressedTransportFormat, HeaderRoundTripsExactly) {
  const CompressedTransportHeader h = TestHeader();
  const CompressedTransportHeader d = DecodeHeader(EncodeHeader(h), "h");
  EXPECT_EQ(d.cubemap_n, 2u);
  EXPECT_EQ(d.sample_count, 67u);
  EXPECT_EQ(d.bits, 9);
  EXPECT_EQ(d.dither_seed, 1234u);
  EXPECT_EQ(d.terms_per_column, 7u);
  ASSERT_EQ(d.domain.segments.size(), 2u);
  EXPECT_EQ(d.domain.segments[0].order, h.domain.segments[0].order);
  EXPECT_EQ(d.domain.segments[1].width, 6u);
  EXPECT_EQ(d.domain.segments[1].height, 5u);
}

TEST(CompressedTransportFormat, TransportRoundTripsExactlyAtEveryBitDepth) {
  for (int bits : {2, 5, 9, 16, 24}) {
    const CompressedTransport t = RandomTransport(TestHeader(bits), static_cast<unsigned>(bits));
    for (uint32_t per_block : {1u, 5u, 1024u}) {
      const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, per_block);
      ExpectSameTransport(t, DecodeCompressedTransport(bytes, "t"));
    }
  }
}

// Version 1 files (LEB128 index gaps, fixed-width values) still decode; version 2's adaptive
// Rice codes cost about one bit per gap of 0 and two per value ±1.
TEST(CompressedTransportFormat, VarintAndAdaptiveRiceCodingRoundTripAndRiceIsSmaller) {
  for (IndexCoding coding : {IndexCoding::kVarint, IndexCoding::kAdaptiveRice})
    for (int bits : {2, 9, 24}) {
      CompressedTransportHeader h = TestHeader(bits);
      h.index_coding = coding;
      h.budget = CompressionBudget::kGlobal;
      const CompressedTransport t = RandomTransport(h, static_cast<unsigned>(bits) + 7);
      const CompressedTransport d = DecodeCompressedTransport(EncodeCompressedTransport(t), "t");
      ExpectSameTransport(t, d);
      EXPECT_EQ(d.header.index_coding, coding);
      EXPECT_EQ(d.header.budget, CompressionBudget::kGlobal);
    }
  CompressedTransportHeader h = TestHeader(9);
  h.cubemap_n = 2;
  h.sample_count = 2000;
  h.domain.segments = {SpatialSegment{SpatialSegment::Kind::kMesh1D, 2000, 0, 0, {}}};
  CompressedColumnBlock block;
  block.first_column = 0;
  block.column_span = 24;
  CompressedColumn c;
  c.column = 3;
  c.scale = 1.0f;
  for (uint32_t i = 0; i < 1000; ++i) {
    c.index.push_back(i);
    c.q.push_back(1);
  }
  block.columns = {c};
  h.index_coding = IndexCoding::kVarint;
  const std::size_t varint = EncodeColumnBlock(h, block).size();
  h.index_coding = IndexCoding::kAdaptiveRice;
  const std::vector<uint8_t> rice = EncodeColumnBlock(h, block);
  // Block head 16 bytes, column head 8 (delta, depth, scale, 2-byte count); varint: 1000 index
  // bytes and 1000 9-bit values; adaptive Rice: 1 bit per zero gap, 2 per value of magnitude 1
  // (plus under 256 bits while the value parameter adapts down from k = 6).
  EXPECT_EQ(varint, 16u + 8u + 1000u + 1125u);
  EXPECT_LE(rice.size(), 16u + 8u + (1000u + 2000u + 256u) / 8u);
  EXPECT_EQ(DecodeColumnBlock(h, rice, "rice").columns[0].index, c.index);
  // Large gaps round trip too.
  c.index.clear();
  for (uint32_t i = 0; i < 2; ++i) c.index.push_back(999 + 1000 * i);
  c.q = {3, -4};
  block.columns = {c};
  EXPECT_EQ(DecodeColumnBlock(h, EncodeColumnBlock(h, block), "rice").columns[0].index, c.index);
}

TEST(CompressedTransportFormat, EveryTruncationIsRejectedWithInputError) {
  const CompressedTransport t = RandomTransport(TestHeader(), 7);
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, 8);
  for (std::size_t len = 0; len < bytes.size(); ++len) {
    EXPECT_THROW(DecodeCompressedTransport(std::span(bytes.data(), len), "cut.prtc"), InputError)
        << len;
  }
  std::vector<uint8_t> longer = bytes;
  longer.push_back(0);
  EXPECT_THROW(DecodeCompressedTransport(longer, "long.prtc"), InputError);
}

// The header alone, from the file's first bytes: equal to the whole decode's header, and every cut
// inside the magic, the size or the header (or a size larger than the file) is an InputError.
TEST(CompressedTransportFormat, HeaderIsReadFromTheFileAloneAndTruncationsAreRejected) {
  const CompressedTransport t = RandomTransport(TestHeader(), 7);
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, 8);
  const std::string path = testing::TempDir() + "/header_only.prtc";
  auto write = [&](std::size_t len) {
    WriteFileDurably(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), len));
  };
  write(bytes.size());
  EXPECT_EQ(EncodeHeader(ReadCompressedTransportHeader(path)), EncodeHeader(t.header));
  const auto hsize = LoadAt<uint32_t>(bytes, 8);
  for (std::size_t len = 0; len < 12 + hsize; ++len) {
    write(len);
    EXPECT_THROW(ReadCompressedTransportHeader(path), InputError) << len;
  }
  std::vector<uint8_t> huge = bytes;
  StoreAt<uint32_t>(huge, 8, 0xfffffff0u);
  WriteFileDurably(path, std::string_view(reinterpret_cast<const char*>(huge.data()), huge.size()));
  EXPECT_THROW(ReadCompressedTransportHeader(path), InputError);
  EXPECT_THROW(ReadCompressedTransportHeader(path + ".missing"), InputError);
}

TEST(CompressedTransportFormat, CorruptedBytesAreRejectedOrDecodeToValidData) {
  const CompressedTransport t = RandomTransport(TestHeader(), 8);
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, 8);
  std::mt19937 rng(3);
  int rejected = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<uint8_t> b = bytes;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) b[rng() % b.size()] ^= static_cast<uint8_t>(1 + rng() % 255);
    try {
      const CompressedTransport d = DecodeCompressedTransport(b, "bad.prtc");
      // Whatever got through must satisfy every invariant the relighter relies on.
      ValidateHeader(d.header, "bad.prtc");
      for (const auto& c : d.columns) ValidateColumn(d.header, c, "bad.prtc");
    } catch (const InputError& e) {
      ++rejected;
      EXPECT_NE(std::string(e.what()).find("bad.prtc"), std::string::npos);
    }
  }
  EXPECT_GT(rejected, 1000);
}

TEST(CompressedTransportFormat, MaliciousCountsAreRejectedWithoutAllocating) {
  const CompressedTransportHeader h = TestHeader();
  // A block claiming 2^32−1 stored columns and a column with 2^32−1 terms.
  std::vector<uint8_t> b = {'P', 'C', 'B', '1', 0, 0, 0, 0, 24, 0, 0, 0, 0xff, 0xff, 0xff, 0xff};
  EXPECT_THROW(DecodeColumnBlock(h, b, "evil"), InputError);
  std::vector<uint8_t> c = {
      'P',  'C',  'B',  '1',  0,    0, 0, 0, 24,   0,    0, 0,
      1,    0,    0,    0,    0,    0, 0, 0, 0x80, 0x3f,  // delta, depth, scale 1
      0xff, 0xff, 0xff, 0xff, 0x0f, 0, 0, 0, 0,    0,    0, 0};
  EXPECT_THROW(DecodeColumnBlock(h, c, "evil"), InputError);
  // Overlong varint, index out of range, depth beyond the maximum, zero value.
  std::vector<uint8_t> d = {'P', 'C',  'B',  '1',  0,    0,    0,    0, 24, 0, 0, 0, 1, 0, 0,
                            0,   0xff, 0xff, 0xff, 0xff, 0xff, 0x01, 0, 0,  0, 0, 0, 0, 0, 0};
  EXPECT_THROW(DecodeColumnBlock(h, d, "evil"), InputError);
  CompressedColumnBlock ok;
  ok.first_column = 0;
  ok.column_span = 24;
  CompressedColumn col;
  col.column = 3;
  col.depth = 1;
  col.scale = 1.0f;
  col.index = {5};
  col.q = {2};
  ok.columns = {col};
  EXPECT_NO_THROW(DecodeColumnBlock(h, EncodeColumnBlock(h, ok), "good"));
  CompressedColumn bad = col;
  bad.index = {67};
  ok.columns = {bad};
  EXPECT_THROW(EncodeColumnBlock(h, ok), InputError);
  bad = col;
  bad.depth = static_cast<uint8_t>(MaxColumnDepth(h.domain) + 1);
  EXPECT_THROW(ValidateColumn(h, bad, "x"), InputError);
  bad = col;
  bad.q = {0};
  EXPECT_THROW(ValidateColumn(h, bad, "x"), InputError);
  bad = col;
  bad.q = {QuantiserMax(h.bits) + 1};
  EXPECT_THROW(ValidateColumn(h, bad, "x"), InputError);
  // Header: grid size mismatch, order not a permutation, segments not covering the samples.
  CompressedTransportHeader hb = h;
  hb.domain.segments[1].width = 7;
  EXPECT_THROW(ValidateHeader(hb, "x"), InputError);
  hb = h;
  hb.domain.segments[0].order[0] = hb.domain.segments[0].order[1];
  EXPECT_THROW(ValidateHeader(hb, "x"), InputError);
  hb = h;
  hb.sample_count = 66;
  EXPECT_THROW(ValidateHeader(hb, "x"), InputError);
  hb = h;
  hb.cubemap_n = 3;
  EXPECT_THROW(ValidateHeader(hb, "x"), InputError);
}

// TestHeader's domain three times over: a 3-channel transport of 3 × 67 rows.
CompressedTransportHeader ThreeChannelHeader(int bits = 9) {
  CompressedTransportHeader h = TestHeader(bits);
  h.domain = PerChannelDomain(h.domain, 3);
  h.sample_count = 3 * 67;
  h.channels = 3;
  return h;
}

// Byte offsets in an encoded header: the version, the sample count and (version 3) the channels.
constexpr std::size_t kVersionAt = 8, kSamplesAt = 16, kChannelsAt = 47;

// A one-channel header is written as version 2, exactly as before channels existed; a 3-channel
// header as version 3: one more byte (the channel count) and channel 0's segments only, the
// decoder repeating them at offsets V and 2V.
TEST(CompressedTransportFormat, ThreeChannelHeaderIsVersion3WithOneChannelsSegments) {
  const std::vector<uint8_t> one = EncodeHeader(TestHeader());
  EXPECT_EQ(LoadAt<uint32_t>(one, kVersionAt), 2u);
  EXPECT_EQ(DecodeHeader(one, "h").channels, 1u);
  const CompressedTransportHeader h = ThreeChannelHeader();
  const std::vector<uint8_t> three = EncodeHeader(h);
  EXPECT_EQ(LoadAt<uint32_t>(three, kVersionAt), 3u);
  EXPECT_EQ(three[kChannelsAt], 3u);
  EXPECT_EQ(three.size(), one.size() + 1);
  const CompressedTransportHeader d = DecodeHeader(three, "h3");
  EXPECT_EQ(d.channels, 3u);
  EXPECT_EQ(d.sample_count, 201u);
  EXPECT_EQ(d.spatial_count(), 67u);
  ASSERT_EQ(d.domain.segments.size(), 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(d.domain.segments[i].kind, h.domain.segments[i % 2].kind);
    EXPECT_EQ(d.domain.segments[i].count, h.domain.segments[i % 2].count);
    EXPECT_EQ(d.domain.segments[i].order, h.domain.segments[i % 2].order);
  }
  EXPECT_EQ(EncodeHeader(d), three);
  // A version 3 header may say 1 channel (this writer never does): it reads as version 2's.
  std::vector<uint8_t> v3one = EncodeHeader(TestHeader());
  v3one[kVersionAt] = 3;
  v3one.insert(v3one.begin() + kChannelsAt, uint8_t{1});
  EXPECT_EQ(EncodeHeader(DecodeHeader(v3one, "h")), one);
  // Whole files round-trip at every block size, and the channels stay apart in the domain: no
  // segment crosses a multiple of V.
  for (uint32_t per_block : {1u, 5u, 1024u}) {
    const CompressedTransport t = RandomTransport(h, 11 + per_block);
    ExpectSameTransport(t, DecodeCompressedTransport(EncodeCompressedTransport(t, per_block), "t"));
  }
  std::size_t off = 0;
  for (const SpatialSegment& s : d.domain.segments) {
    EXPECT_EQ(off / 67, (off + s.count - 1) / 67);
    off += s.count;
  }
}

// The bytes of a one-channel .prtc are those main wrote before channels existed: the size and
// XXH64 of a fixed transport's encoding, computed with the encoder of commit 8ad5212.
constexpr std::size_t kOneChannelFileSize = 492;
constexpr uint64_t kOneChannelFileXxh64 = 0xa7026226b2b1f8e6ull;

TEST(CompressedTransportFormat, OneChannelFilesKeepTheirBytes) {
  CompressedTransportHeader h;
  h.cubemap_n = 2;
  h.bits = 9;
  h.dither_seed = 99;
  h.terms_per_column = 5;
  h.budget = CompressionBudget::kGlobal;
  h.light_weight = 2;
  SpatialSegment mesh;
  mesh.count = 10;
  for (uint32_t k = 0; k < 10; ++k) mesh.order.push_back(9 - k);
  SpatialSegment grid;
  grid.kind = SpatialSegment::Kind::kGrid2D;
  grid.count = 12;
  grid.width = 4;
  grid.height = 3;
  h.domain.segments = {mesh, grid};
  h.sample_count = 22;
  CompressedTransport t;
  t.header = h;
  for (uint32_t j = 0; j < 24; j += 3) {
    CompressedColumn c;
    c.column = j;
    c.depth = static_cast<uint8_t>(j % 4);
    c.scale = 0.25f * static_cast<float>(j + 1);
    for (uint32_t i = j % 5; i < 22; i += 1 + j % 3) {
      c.index.push_back(i);
      c.q.push_back(static_cast<int32_t>((i * 7 + j) % 255) - 127 == 0
                        ? 1
                        : static_cast<int32_t>((i * 7 + j) % 255) - 127);
    }
    t.columns.push_back(c);
  }
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, 5);
  EXPECT_EQ(bytes.size(), kOneChannelFileSize);
  EXPECT_EQ(Checksum64(bytes.data(), bytes.size()), kOneChannelFileXxh64);
}

// Channel counts other than 1 and 3, sample counts that do not split into the channels, and
// channels whose segments differ are refused, in memory and in the bytes.
TEST(CompressedTransportFormat, BadChannelCountsAreRejectedWithInputError) {
  const CompressedTransportHeader good = ThreeChannelHeader();
  EXPECT_NO_THROW(ValidateHeader(good, "x"));
  for (uint32_t channels : {0u, 2u, 4u}) {
    CompressedTransportHeader h = good;
    h.channels = channels;
    EXPECT_THROW(ValidateHeader(h, "x"), InputError) << channels;
    EXPECT_THROW(PerChannelDomain(TestHeader().domain, channels), InputError) << channels;
  }
  CompressedTransportHeader h = TestHeader();
  h.channels = 3;  // 67 rows in one copy: not a multiple of 3
  EXPECT_THROW(ValidateHeader(h, "x"), InputError);
  h = good;
  h.domain.segments[3].width = 5;  // channel 1's grid differs
  EXPECT_THROW(ValidateHeader(h, "x"), InputError);
  h = good;
  std::swap(h.domain.segments[2].order[0], h.domain.segments[2].order[1]);  // a valid order
  try {
    ValidateHeader(h, "x");
    ADD_FAILURE() << "channel 1's mesh order differs from channel 0's";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("differs from its copy in channel 0"), std::string::npos);
  }
  const std::vector<uint8_t> bytes = EncodeHeader(good);
  for (uint8_t channels : {uint8_t{0}, uint8_t{2}, uint8_t{4}, uint8_t{255}}) {
    std::vector<uint8_t> b = bytes;
    b[kChannelsAt] = channels;
    try {
      DecodeHeader(b, "bad.prtc");
      ADD_FAILURE() << "channels " << int(channels) << " decoded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("channel count " + std::to_string(channels) +
                                           " is not 1 or 3"),
                std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find("bad.prtc"), std::string::npos);
    }
  }
  std::vector<uint8_t> b = bytes;
  b[kSamplesAt] = 200;  // 200 rows for 3 channels
  try {
    DecodeHeader(b, "bad.prtc");
    ADD_FAILURE() << "200 rows of 3 channels decoded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not a multiple of the channel count 3"),
              std::string::npos)
        << e.what();
  }
  b[kSamplesAt] = 198;  // a multiple of 3, but not what the segments cover
  EXPECT_THROW(DecodeHeader(b, "bad.prtc"), InputError);
}

// Every truncation of a 3-channel file, and 3000 random corruptions, are refused with an
// InputError naming the file or decode to data that passes validation.
TEST(CompressedTransportFormat, ThreeChannelFilesSurviveTruncationAndCorruption) {
  const CompressedTransport t = RandomTransport(ThreeChannelHeader(), 21);
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(t, 8);
  for (std::size_t len = 0; len < bytes.size(); len += 1 + len / 64) {
    EXPECT_THROW(DecodeCompressedTransport(std::span(bytes.data(), len), "cut.prtc"), InputError)
        << len;
  }
  std::mt19937 rng(4);
  int rejected = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<uint8_t> b = bytes;
    const int flips = 1 + static_cast<int>(rng() % 4);
    // Half the trials aim at the header (where the channel count and the segments are).
    for (int f = 0; f < flips; ++f) {
      const std::size_t at = trial % 2 == 0 ? rng() % 200 : rng() % b.size();
      b[at] ^= static_cast<uint8_t>(1 + rng() % 255);
    }
    try {
      const CompressedTransport d = DecodeCompressedTransport(b, "bad.prtc");
      ValidateHeader(d.header, "bad.prtc");
      EXPECT_EQ(d.header.sample_count % d.header.channels, 0u);
      for (const auto& c : d.columns) ValidateColumn(d.header, c, "bad.prtc");
    } catch (const InputError& e) {
      ++rejected;
      EXPECT_NE(std::string(e.what()).find("bad.prtc"), std::string::npos);
    }
  }
  EXPECT_GT(rejected, 1000);
}

TEST(CompressedTransportFormat, ParsesSchemeAndWaveletNames) {
  EXPECT_EQ(ParseRowWavelet("d4", "f"), RowWavelet::kD4);
  EXPECT_EQ(ParseColumnWavelet("cdf97", "f"), ColumnWavelet::kCdf97);
  EXPECT_EQ(ParseCompressionScheme("2d", "f"), CompressionScheme::k2D);
  EXPECT_THROW(ParseCompressionScheme("3d", "scene.toml"), InputError);
  EXPECT_STREQ(ToString(CompressionScheme::kAdaptive4D), "adaptive4d");
}

}  // namespace
}  // namespace prt
