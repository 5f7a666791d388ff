// Data structures and binary encoding of compressed transport (docs/compression.md).
// Decoders are safe on untrusted input: every read is bounds-checked, every count is checked
// against what the remaining bytes can hold before anything is allocated.
#include "formats/compressed_transport.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/wavelets.h"

namespace prt {
namespace {

constexpr char kHeaderMagic[8] = {'P', 'R', 'T', 'C', 'T', 'H', 'D', '1'};
constexpr char kBlockMagic[4] = {'P', 'C', 'B', '1'};
constexpr char kFileMagic[8] = {'P', 'R', 'T', 'C', 'T', 'F', 'L', '1'};
// Version 3 adds the channel count and is written only for channels ≠ 1, so a one-channel header
// keeps version 2's bytes; 1 (varint indices, column budget) and 2 are still read, as 1 channel.
constexpr uint32_t kFormatVersion = 2;
constexpr uint32_t kChannelsVersion = 3;
// Version 4 adds the CPCA fields and is written only for scheme kCpca.
constexpr uint32_t kCpcaVersion = 4;
constexpr uint32_t kMaxSamples = 1u << 28;  // consumers allocate O(samples)

// Every reader of this file's formats: a truncated read is an InputError naming the file, the
// field and the byte.
ByteReader Reader(std::span<const uint8_t> bytes, const std::string& name) {
  return ByteReader(bytes, [&name](const char* what, std::size_t at) {
    throw InputError(name,
                     std::string("truncated: ") + what + " (at byte " + std::to_string(at) + ")");
  });
}
std::span<const uint8_t> AsBytes(std::string_view s) {
  return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}
[[noreturn]] void Fail(const ByteReader& r, const std::string& name, const std::string& what) {
  throw InputError(name, what + " (at byte " + std::to_string(r.position()) + ")");
}
void Magic(ByteReader& r, const std::string& name, const char* m, std::size_t n, const char* what) {
  r.Need(n, what);
  if (r.rest().substr(0, n) != std::string_view(m, n))
    Fail(r, name, std::string("bad magic: ") + what);
  r.Skip(n, what);
}
// Out of line, so that Varint32 needs no stack frame for the message.
[[noreturn, gnu::cold, gnu::noinline]] void BadVarint(const ByteReader& r, const std::string& name,
                                                      const char* what) {
  Fail(r, name, std::string("varint longer than 5 bytes or above 2^32: ") + what);
}
// LEB128, at most 5 bytes, value must fit 32 bits.
uint32_t Varint32(ByteReader& r, const std::string& name, const char* what) {
  const std::optional<uint32_t> v = r.GetVarint<uint32_t>(what);
  if (!v) BadVarint(r, name, what);
  return *v;
}

// Packs `bits`-bit two's complement fields, little-endian bit order, padded to a byte.
void PutPackedSigned(ByteVectorWriter& w, const std::vector<int32_t>& q, int bits) {
  std::vector<uint8_t>& out = w.bytes();
  uint64_t acc = 0;
  int filled = 0;
  const uint64_t mask = (uint64_t{1} << bits) - 1;
  for (int32_t v : q) {
    acc |= (static_cast<uint64_t>(static_cast<int64_t>(v)) & mask) << filled;
    filled += bits;
    while (filled >= 8) {
      out.push_back(static_cast<uint8_t>(acc));
      acc >>= 8;
      filled -= 8;
    }
  }
  if (filled > 0) out.push_back(static_cast<uint8_t>(acc));
}
std::vector<int32_t> GetPackedSigned(ByteReader& r, std::size_t count, int bits, const char* what) {
  const std::size_t nbytes = (count * static_cast<std::size_t>(bits) + 7) / 8;
  const auto* b = reinterpret_cast<const uint8_t*>(r.Take(nbytes, what).data());
  std::vector<int32_t> q(count);
  uint64_t acc = 0;
  int filled = 0;
  std::size_t p = 0;
  const uint64_t mask = (uint64_t{1} << bits) - 1;
  for (std::size_t k = 0; k < count; ++k) {
    while (filled < bits) {
      acc |= static_cast<uint64_t>(b[p++]) << filled;
      filled += 8;
    }
    uint64_t u = acc & mask;
    acc >>= bits;
    filled -= bits;
    int64_t v = static_cast<int64_t>(u);
    if (u >> (bits - 1)) v -= static_cast<int64_t>(uint64_t{1} << bits);  // sign extend
    q[k] = static_cast<int32_t>(v);
  }
  return q;
}

int MaxQ(int bits) {
  return (1 << (bits - 1)) - 1;
}

// Adaptive Golomb-Rice coding (as in JPEG-LS, LOCO-I): a value v ≥ 0 is coded with parameter
// k = the smallest k with N·2^k ≥ A, where A sums the recent values and N counts them (halved
// every kRiceReset values), so k follows the local density with no side information: v >> k in
// unary (1 bits, then a 0), then its k low bits; when v >> k ≥ kRiceEscape, kRiceEscape 1 bits
// then v in `raw_bits` bits. Bits are LSB-first.
constexpr int kRiceEscape = 24;
constexpr uint32_t kRiceReset = 16;

struct RiceState {
  uint64_t a, n = 1;
  explicit RiceState(uint64_t initial) : a(std::max<uint64_t>(initial, 1)) {}
  int k() const {
    int k = 0;
    while ((n << k) < a && k < 30) ++k;
    return k;
  }
  void Update(uint64_t v) {
    a += v;
    if (++n == kRiceReset) {
      a = (a + 1) >> 1;
      n >>= 1;
    }
  }
};

class BitWriter {
 public:
  explicit BitWriter(std::vector<uint8_t>& out) : out_(out) {}
  void Put(uint64_t v, int nbits) {  // nbits ≤ 32
    for (int done = 0; done < nbits;) {
      const int take = std::min(nbits - done, 8 - filled_);
      acc_ |= static_cast<uint32_t>((v >> done) & ((1u << take) - 1)) << filled_;
      filled_ += take;
      done += take;
      if (filled_ == 8) {
        out_.push_back(static_cast<uint8_t>(acc_));
        acc_ = 0;
        filled_ = 0;
      }
    }
  }
  void Rice(uint64_t v, RiceState& st, int raw_bits) {
    const int k = st.k();
    const uint64_t high = v >> k;
    if (high >= static_cast<uint64_t>(kRiceEscape)) {
      Put((uint64_t{1} << kRiceEscape) - 1, kRiceEscape);
      Put(v, raw_bits);
    } else {
      Put((uint64_t{1} << high) - 1, static_cast<int>(high));
      Put(0, 1);
      Put(v & ((uint64_t{1} << k) - 1), k);
    }
    st.Update(v);
  }
  void Flush() {
    if (filled_ > 0) out_.push_back(static_cast<uint8_t>(acc_));
    acc_ = 0;
    filled_ = 0;
  }

 private:
  std::vector<uint8_t>& out_;
  uint32_t acc_ = 0;
  int filled_ = 0;
};

// Reads what BitWriter wrote from `b`; fails (InputError via fail) past its end.
class BitReader {
 public:
  explicit BitReader(std::span<const uint8_t> b) : b_(b) {}
  template <class Fail>
  uint64_t Get(int nbits, Fail&& fail) {
    uint64_t v = 0;
    for (int i = 0; i < nbits; ++i) {
      if (filled_ == 0) {
        if (p_ >= b_.size()) fail();
        acc_ = b_[p_++];
        filled_ = 8;
      }
      v |= static_cast<uint64_t>(acc_ & 1u) << i;
      acc_ >>= 1;
      --filled_;
    }
    return v;
  }
  template <class Fail>
  uint64_t Rice(RiceState& st, int raw_bits, Fail&& fail) {
    const int k = st.k();
    int high = 0;
    while (high < kRiceEscape && Get(1, fail) != 0) ++high;
    const uint64_t v = high == kRiceEscape ? Get(raw_bits, fail)
                                           : (static_cast<uint64_t>(high) << k) | Get(k, fail);
    st.Update(v);
    return v;
  }
  std::size_t end() const { return p_; }  // the byte after the last one read

 private:
  std::span<const uint8_t> b_;
  std::size_t p_ = 0;
  uint32_t acc_ = 0;
  int filled_ = 0;
};

// Initial states: the mean gap if the terms were spread evenly; values start at a quarter of
// the quantiser range.
uint64_t InitialGapMean(uint64_t samples, uint64_t terms) {
  return terms > 0 ? (samples - std::min(samples, terms)) / terms : 1;
}
uint64_t InitialValueMean(int bits) {
  return uint64_t{1} << std::max(0, bits - 3);
}
constexpr int kGapRawBits = 28;  // gaps < kMaxSamples

}  // namespace

RowWavelet ParseRowWavelet(const std::string& s, const std::string& file) {
  if (s == "haar") return RowWavelet::kHaar;
  if (s == "d4") return RowWavelet::kD4;
  throw InputError(file, "unknown row wavelet '" + s + "' (expected haar or d4)");
}
ColumnWavelet ParseColumnWavelet(const std::string& s, const std::string& file) {
  if (s == "legall53") return ColumnWavelet::kLeGall53;
  if (s == "cdf97") return ColumnWavelet::kCdf97;
  throw InputError(file, "unknown column wavelet '" + s + "' (expected legall53 or cdf97)");
}
CompressionScheme ParseCompressionScheme(const std::string& s, const std::string& file) {
  if (s == "2d") return CompressionScheme::k2D;
  if (s == "4d") return CompressionScheme::k4D;
  if (s == "adaptive4d") return CompressionScheme::kAdaptive4D;
  if (s == "cpca") return CompressionScheme::kCpca;
  throw InputError(file,
                   "unknown compression scheme '" + s + "' (expected 2d, 4d, adaptive4d or cpca)");
}
CompressionBudget ParseCompressionBudget(const std::string& s, const std::string& file) {
  if (s == "column") return CompressionBudget::kColumn;
  if (s == "global") return CompressionBudget::kGlobal;
  throw InputError(file, "unknown compression budget '" + s + "' (expected column or global)");
}
const char* ToString(CompressionBudget b) {
  return b == CompressionBudget::kColumn ? "column" : "global";
}
const char* ToString(RowWavelet w) {
  return w == RowWavelet::kHaar ? "haar" : "d4";
}
const char* ToString(ColumnWavelet w) {
  return w == ColumnWavelet::kLeGall53 ? "legall53" : "cdf97";
}
const char* ToString(CompressionScheme s) {
  switch (s) {
    case CompressionScheme::k2D:
      return "2d";
    case CompressionScheme::k4D:
      return "4d";
    case CompressionScheme::kAdaptive4D:
      return "adaptive4d";
    case CompressionScheme::kCpca:
      return "cpca";
  }
  return "?";
}

std::size_t SpatialDomain::sample_count() const {
  std::size_t n = 0;
  for (const auto& s : segments) n += s.count;
  return n;
}

std::size_t CompressedTransport::term_count() const {
  std::size_t n = 0;
  for (const auto& c : columns) n += c.index.size();
  return n;
}

SpatialDomain PerChannelDomain(const SpatialDomain& spatial, uint32_t channels) {
  if (channels != 1 && channels != 3)
    throw InputError("PerChannelDomain",
                     "channel count " + std::to_string(channels) + " is not 1 or 3");
  SpatialDomain d;
  d.segments.reserve(spatial.segments.size() * channels);
  for (uint32_t c = 0; c < channels; ++c)
    d.segments.insert(d.segments.end(), spatial.segments.begin(), spatial.segments.end());
  return d;
}

SpatialDomain SpatialDomainOfChannel(const SpatialDomain& domain, uint32_t channels) {
  SpatialDomain d;
  const std::size_t per = channels == 0 ? 0 : domain.segments.size() / channels;
  d.segments.assign(domain.segments.begin(),
                    domain.segments.begin() + static_cast<std::ptrdiff_t>(per));
  return d;
}

namespace {
bool SameSegment(const SpatialSegment& a, const SpatialSegment& b) {
  return a.kind == b.kind && a.count == b.count && a.width == b.width && a.height == b.height &&
         a.order == b.order;
}
}  // namespace

void ValidateHeader(const CompressedTransportHeader& h, const std::string& name) {
  const uint32_t n = h.cubemap_n;
  if (n == 0 || n > 256 || (n & (n - 1)) != 0)
    throw InputError(name,
                     "cubemap size " + std::to_string(n) + " is not a power of two in [1,256]");
  if (h.sample_count == 0 || h.sample_count > kMaxSamples)
    throw InputError(name, "sample count " + std::to_string(h.sample_count) + " out of range");
  if (static_cast<uint8_t>(h.row_wavelet) > 1) throw InputError(name, "unknown row wavelet id");
  if (static_cast<uint8_t>(h.column_wavelet) > 1)
    throw InputError(name, "unknown column wavelet id");
  if (static_cast<uint8_t>(h.scheme) > 3) throw InputError(name, "unknown compression scheme id");
  if (h.scheme == CompressionScheme::kCpca) {
    if (h.cpca_clusters == 0 || h.cpca_clusters > h.sample_count)
      throw InputError(name, "CPCA cluster count " + std::to_string(h.cpca_clusters) +
                                 " not in [1, rows " + std::to_string(h.sample_count) + "]");
    if (h.cpca_bases > kMaxCpcaBases || h.cpca_bases > h.column_count())
      throw InputError(name, "CPCA basis count " + std::to_string(h.cpca_bases) + " not in [0, " +
                                 std::to_string(kMaxCpcaBases) + "]");
    if (h.cpca_coefficient_bits < 2 || h.cpca_coefficient_bits > 24)
      throw InputError(name, "CPCA coefficient bits " + std::to_string(h.cpca_coefficient_bits) +
                                 " not in [2,24]");
    if (static_cast<uint8_t>(h.cpca_method) > 1) throw InputError(name, "unknown CPCA method id");
  }
  if (static_cast<uint8_t>(h.budget) > 1) throw InputError(name, "unknown compression budget id");
  if (static_cast<uint8_t>(h.index_coding) > 1) throw InputError(name, "unknown index coding id");
  if (h.light_weight > 16) throw InputError(name, "light weight exponent > 16");
  if (h.bits < 2 || h.bits > 24)
    throw InputError(name, "quantiser bits " + std::to_string(h.bits) + " not in [2,24]");
  if (!std::isfinite(h.keep_fraction) || h.keep_fraction < 0 || h.keep_fraction > 1)
    throw InputError(name, "keep fraction not in [0,1]");
  if (h.terms_per_column > h.sample_count)
    throw InputError(name, "terms per column exceeds the sample count");
  if (h.domain.segments.empty()) throw InputError(name, "spatial domain has no segments");
  uint64_t total = 0;
  for (std::size_t i = 0; i < h.domain.segments.size(); ++i) {
    const SpatialSegment& s = h.domain.segments[i];
    const std::string where = "segment " + std::to_string(i) + ": ";
    if (s.count == 0) throw InputError(name, where + "empty");
    total += s.count;
    if (s.kind == SpatialSegment::Kind::kGrid2D) {
      if (s.width == 0 || s.height == 0 || static_cast<uint64_t>(s.width) * s.height != s.count)
        throw InputError(name, where + "grid width·height != count");
      if (!s.order.empty()) throw InputError(name, where + "grid with a vertex order");
    } else if (s.kind == SpatialSegment::Kind::kMesh1D) {
      if (!s.order.empty()) {
        if (s.order.size() != s.count) throw InputError(name, where + "order size != count");
        std::vector<uint8_t> seen(s.count, 0);
        for (uint32_t v : s.order) {
          if (v >= s.count || seen[v]) throw InputError(name, where + "order is not a permutation");
          seen[v] = 1;
        }
      }
    } else {
      throw InputError(name, where + "unknown segment kind");
    }
  }
  if (total != h.sample_count)
    throw InputError(name, "segments cover " + std::to_string(total) + " samples, header says " +
                               std::to_string(h.sample_count));
  // Colour channels: channel c's rows [c·V, (c+1)·V) are a copy of the spatial segments, so that
  // every segment (and thus every column transform) lies inside one channel.
  if (h.channels != 1 && h.channels != 3)
    throw InputError(name, "channel count " + std::to_string(h.channels) + " is not 1 or 3");
  if (h.sample_count % h.channels != 0)
    throw InputError(name, "sample count " + std::to_string(h.sample_count) +
                               " is not a multiple of the channel count " +
                               std::to_string(h.channels));
  if (h.domain.segments.size() % h.channels != 0)
    throw InputError(name, std::to_string(h.domain.segments.size()) +
                               " segments do not split into " + std::to_string(h.channels) +
                               " channels");
  const std::size_t per = h.domain.segments.size() / h.channels;
  for (std::size_t i = per; i < h.domain.segments.size(); ++i)
    if (!SameSegment(h.domain.segments[i], h.domain.segments[i % per]))
      throw InputError(name, "segment " + std::to_string(i) + " (channel " +
                                 std::to_string(i / per) + ") differs from its copy in channel 0");
}

void ValidateColumn(const CompressedTransportHeader& h, const CompressedColumn& c,
                    const std::string& name) {
  const std::string where = "column " + std::to_string(c.column) + ": ";
  if (c.column >= h.column_count()) throw InputError(name, where + "column index out of range");
  if (c.depth > MaxColumnDepth(h.domain))
    throw InputError(name, where + "depth " + std::to_string(c.depth) + " exceeds the maximum");
  if (c.index.size() != c.q.size()) throw InputError(name, where + "index/value count mismatch");
  if (c.index.empty()) throw InputError(name, where + "empty column stored");
  if (c.index.size() > h.sample_count) throw InputError(name, where + "more terms than samples");
  if (!std::isfinite(c.scale) || !(c.scale > 0)) throw InputError(name, where + "bad scale");
  const int maxq = MaxQ(h.bits);
  for (std::size_t k = 0; k < c.index.size(); ++k) {
    if (c.index[k] >= h.sample_count) throw InputError(name, where + "index out of range");
    if (k > 0 && c.index[k] <= c.index[k - 1])
      throw InputError(name, where + "indices not strictly increasing");
    if (c.q[k] == 0 || c.q[k] > maxq || c.q[k] < -maxq)
      throw InputError(name, where + "quantised value out of range");
  }
}

// Header layout: magic "PRTCTHD1", u32 version, u32 n, u32 samples, u8 row wavelet,
// u8 column wavelet, u8 scheme, u8 bits, f64 keep fraction, u32 terms per column, u64 seed,
// (version ≥ 2: u8 budget, u8 index coding, u8 light weight), (version 3: u8 channels),
// u32 segment count, then per segment: u8 kind, u32 count, u32 width, u32 height, u8 has_order,
// [count × u32 order]. Version 3 stores channel 0's segments only (the others are copies).
std::vector<uint8_t> EncodeHeader(const CompressedTransportHeader& h) {
  ValidateHeader(h, "EncodeHeader");
  const bool v4 = h.scheme == CompressionScheme::kCpca;
  const bool v3 = h.channels != 1 || v4;
  const SpatialDomain stored = v3 ? SpatialDomainOfChannel(h.domain, h.channels) : SpatialDomain{};
  const SpatialDomain& domain = v3 ? stored : h.domain;
  ByteVectorWriter w;
  w.PutBytes(kHeaderMagic, 8);
  w.Put<uint32_t>(v4 ? kCpcaVersion : v3 ? kChannelsVersion : kFormatVersion);
  w.Put<uint32_t>(h.cubemap_n);
  w.Put<uint32_t>(h.sample_count);
  w.Put<uint8_t>(static_cast<uint8_t>(h.row_wavelet));
  w.Put<uint8_t>(static_cast<uint8_t>(h.column_wavelet));
  w.Put<uint8_t>(static_cast<uint8_t>(h.scheme));
  w.Put<uint8_t>(h.bits);
  w.Put<double>(h.keep_fraction);
  w.Put<uint32_t>(h.terms_per_column);
  w.Put<uint64_t>(h.dither_seed);
  w.Put<uint8_t>(static_cast<uint8_t>(h.budget));
  w.Put<uint8_t>(static_cast<uint8_t>(h.index_coding));
  w.Put<uint8_t>(h.light_weight);
  if (v3) w.Put<uint8_t>(static_cast<uint8_t>(h.channels));
  if (v4) {
    w.Put<uint32_t>(h.cpca_clusters);
    w.Put<uint32_t>(h.cpca_bases);
    w.Put<uint8_t>(h.cpca_coefficient_bits);
    w.Put<uint8_t>(static_cast<uint8_t>(h.cpca_method));
  }
  w.Put<uint32_t>(static_cast<uint32_t>(domain.segments.size()));
  for (const auto& s : domain.segments) {
    w.Put<uint8_t>(static_cast<uint8_t>(s.kind));
    w.Put<uint32_t>(s.count);
    w.Put<uint32_t>(s.width);
    w.Put<uint32_t>(s.height);
    w.Put<uint8_t>(s.order.empty() ? 0 : 1);
    for (uint32_t v : s.order) w.Put<uint32_t>(v);
  }
  return std::move(w.bytes());
}

namespace {
CompressedTransportHeader ReadHeader(ByteReader& r, const std::string& name) {
  CompressedTransportHeader h;
  Magic(r, name, kHeaderMagic, 8, "header magic");
  const uint32_t version = r.Get<uint32_t>("version");
  if (version != kCpcaVersion && version != kChannelsVersion && version != kFormatVersion &&
      version != 1)
    Fail(r, name, "unsupported compressed-transport version " + std::to_string(version));
  h.cubemap_n = r.Get<uint32_t>("cubemap size");
  h.sample_count = r.Get<uint32_t>("sample count");
  const uint8_t rw = r.Get<uint8_t>("row wavelet");
  const uint8_t cw = r.Get<uint8_t>("column wavelet");
  const uint8_t sc = r.Get<uint8_t>("scheme");
  if (rw > 1) Fail(r, name, "unknown row wavelet id " + std::to_string(rw));
  if (cw > 1) Fail(r, name, "unknown column wavelet id " + std::to_string(cw));
  if (sc > (version >= kCpcaVersion ? 3 : 2))
    Fail(r, name, "unknown scheme id " + std::to_string(sc));
  h.row_wavelet = static_cast<RowWavelet>(rw);
  h.column_wavelet = static_cast<ColumnWavelet>(cw);
  h.scheme = static_cast<CompressionScheme>(sc);
  h.bits = r.Get<uint8_t>("bits");
  h.keep_fraction = r.Get<double>("keep fraction");
  h.terms_per_column = r.Get<uint32_t>("terms per column");
  h.dither_seed = r.Get<uint64_t>("dither seed");
  h.budget = CompressionBudget::kColumn;
  h.index_coding = IndexCoding::kVarint;
  if (version >= 2) {
    const uint8_t bu = r.Get<uint8_t>("budget");
    const uint8_t ic = r.Get<uint8_t>("index coding");
    if (bu > 1) Fail(r, name, "unknown budget id " + std::to_string(bu));
    if (ic > 1) Fail(r, name, "unknown index coding id " + std::to_string(ic));
    h.budget = static_cast<CompressionBudget>(bu);
    h.index_coding = static_cast<IndexCoding>(ic);
    h.light_weight = r.Get<uint8_t>("light weight");
  }
  h.channels = 1;
  if (version >= kChannelsVersion) {
    const uint8_t ch = r.Get<uint8_t>("channels");
    if (ch != 1 && ch != 3) Fail(r, name, "channel count " + std::to_string(ch) + " is not 1 or 3");
    if (h.sample_count % ch != 0)
      Fail(r, name,
           "sample count " + std::to_string(h.sample_count) +
               " is not a multiple of the channel count " + std::to_string(ch));
    h.channels = ch;
  }
  if (version >= kCpcaVersion) {
    h.cpca_clusters = r.Get<uint32_t>("CPCA clusters");
    h.cpca_bases = r.Get<uint32_t>("CPCA bases");
    h.cpca_coefficient_bits = r.Get<uint8_t>("CPCA coefficient bits");
    const uint8_t m = r.Get<uint8_t>("CPCA method");
    if (m > 1) Fail(r, name, "unknown CPCA method id " + std::to_string(m));
    h.cpca_method = static_cast<CpcaMethod>(m);
    if (h.scheme != CompressionScheme::kCpca)
      Fail(r, name, "version 4 header of a scheme other than cpca");
  }
  const uint32_t nseg = r.Get<uint32_t>("segment count");
  // Every segment takes at least 14 bytes: bound the count before allocating.
  if (nseg == 0 || nseg > r.remaining() / 14)
    Fail(r, name, "segment count " + std::to_string(nseg));
  h.domain.segments.resize(nseg);
  for (auto& s : h.domain.segments) {
    const uint8_t kind = r.Get<uint8_t>("segment kind");
    if (kind > 1) Fail(r, name, "unknown segment kind " + std::to_string(kind));
    s.kind = static_cast<SpatialSegment::Kind>(kind);
    s.count = r.Get<uint32_t>("segment count");
    s.width = r.Get<uint32_t>("segment width");
    s.height = r.Get<uint32_t>("segment height");
    const uint8_t has_order = r.Get<uint8_t>("segment order flag");
    if (has_order > 1) Fail(r, name, "bad order flag");
    if (has_order) {
      if (s.count > kMaxSamples || s.count > r.remaining() / 4)
        Fail(r, name, "truncated vertex order");
      s.order.resize(s.count);
      for (auto& v : s.order) v = r.Get<uint32_t>("vertex order");
    }
  }
  // Version 3 stored one channel's segments: the others are copies (at most 3× what was read).
  if (h.channels != 1) h.domain = PerChannelDomain(h.domain, h.channels);
  ValidateHeader(h, name);
  return h;
}

void WriteBlock(ByteVectorWriter& w, const CompressedTransportHeader& h,
                const CompressedColumnBlock& block) {
  if (static_cast<uint64_t>(block.first_column) + block.column_span > h.column_count())
    throw InputError("EncodeColumnBlock", "block column range exceeds the column count");
  w.PutBytes(kBlockMagic, 4);
  w.Put<uint32_t>(block.first_column);
  w.Put<uint32_t>(block.column_span);
  w.Put<uint32_t>(static_cast<uint32_t>(block.columns.size()));
  uint32_t prev = block.first_column;
  bool first = true;
  for (const auto& c : block.columns) {
    ValidateColumn(h, c, "EncodeColumnBlock");
    if (c.column < block.first_column || c.column >= block.first_column + block.column_span ||
        (!first && c.column <= prev))
      throw InputError("EncodeColumnBlock", "columns not sorted inside the block range");
    w.PutVarint(c.column - (first ? block.first_column : prev + 1));
    prev = c.column;
    first = false;
    w.Put<uint8_t>(c.depth);
    w.Put<float>(c.scale);
    w.PutVarint(c.index.size());
    if (h.index_coding == IndexCoding::kAdaptiveRice) {
      // Gaps (first index, then index − previous − 1), then (|q| − 1, sign) per term.
      BitWriter bw(w.bytes());
      RiceState gaps(InitialGapMean(h.sample_count, c.index.size()));
      uint32_t last = 0;
      for (std::size_t k = 0; k < c.index.size(); ++k) {
        bw.Rice(k == 0 ? c.index[0] : c.index[k] - last - 1, gaps, kGapRawBits);
        last = c.index[k];
      }
      RiceState values(InitialValueMean(h.bits));
      for (int32_t q : c.q) {
        bw.Rice(static_cast<uint64_t>(std::abs(q)) - 1, values, h.bits - 1);
        bw.Put(q < 0 ? 1 : 0, 1);
      }
      bw.Flush();
      continue;
    } else {
      uint32_t pi = 0;
      for (std::size_t k = 0; k < c.index.size(); ++k) {
        w.PutVarint(k == 0 ? c.index[0] : c.index[k] - pi - 1);
        pi = c.index[k];
      }
    }
    PutPackedSigned(w, c.q, h.bits);
  }
}

CompressedColumnBlock ReadBlock(ByteReader& r, const CompressedTransportHeader& h,
                                const std::string& name) {
  CompressedColumnBlock b;
  Magic(r, name, kBlockMagic, 4, "block magic");
  b.first_column = r.Get<uint32_t>("first column");
  b.column_span = r.Get<uint32_t>("column span");
  if (static_cast<uint64_t>(b.first_column) + b.column_span > h.column_count())
    Fail(r, name, "block column range exceeds the column count");
  const uint32_t ncols = r.Get<uint32_t>("column count");
  // Each stored column takes at least 8 bytes (delta, depth, scale, count, one index, one value).
  if (ncols > b.column_span || ncols > r.remaining() / 8)
    Fail(r, name, "stored column count " + std::to_string(ncols) + " impossible");
  b.columns.resize(ncols);
  uint64_t next = b.first_column;
  for (auto& c : b.columns) {
    const uint64_t col = next + Varint32(r, name, "column delta");
    if (col >= static_cast<uint64_t>(b.first_column) + b.column_span)
      Fail(r, name, "column outside the block range");
    c.column = static_cast<uint32_t>(col);
    next = col + 1;
    c.depth = r.Get<uint8_t>("depth");
    c.scale = r.Get<float>("scale");
    const uint32_t nterms = Varint32(r, name, "term count");
    // Every term costs at least one index bit and `bits` value bits: never allocate beyond a
    // constant times the input.
    if (nterms == 0 || nterms > h.sample_count ||
        (h.index_coding == IndexCoding::kVarint &&
         nterms > r.remaining() * 8 / (static_cast<std::size_t>(h.bits) + 1)))
      Fail(r, name, "term count " + std::to_string(nterms) + " impossible");
    if (h.index_coding == IndexCoding::kAdaptiveRice) {
      // At least 1 bit per gap and 2 per value.
      if (nterms > r.remaining() * 8 / 3)
        Fail(r, name, "term count " + std::to_string(nterms) + " impossible");
      BitReader br(AsBytes(r.rest()));
      auto fail = [&]() { Fail(r, name, "truncated adaptive Rice codes"); };
      c.index.resize(nterms);
      c.q.resize(nterms);
      RiceState gaps(InitialGapMean(h.sample_count, nterms));
      uint64_t from = 0;
      for (uint32_t k = 0; k < nterms; ++k) {
        const uint64_t idx = from + br.Rice(gaps, kGapRawBits, fail);
        if (idx >= h.sample_count) Fail(r, name, "coefficient index out of range");
        c.index[k] = static_cast<uint32_t>(idx);
        from = idx + 1;
      }
      RiceState values(InitialValueMean(h.bits));
      const uint64_t maxq = static_cast<uint64_t>(MaxQ(h.bits));
      for (uint32_t k = 0; k < nterms; ++k) {
        const uint64_t m = br.Rice(values, h.bits - 1, fail) + 1;
        if (m > maxq) Fail(r, name, "quantised value out of range");
        c.q[k] = br.Get(1, fail) != 0 ? -static_cast<int32_t>(m) : static_cast<int32_t>(m);
      }
      r.Skip(br.end(), "adaptive Rice codes");
      ValidateColumn(h, c, name);
      continue;
    } else {
      c.index.resize(nterms);
      uint64_t idx = 0;
      for (uint32_t k = 0; k < nterms; ++k) {
        const uint64_t d = Varint32(r, name, "index delta");
        idx = (k == 0) ? d : idx + 1 + d;
        if (idx >= h.sample_count) Fail(r, name, "coefficient index out of range");
        c.index[k] = static_cast<uint32_t>(idx);
      }
    }
    c.q = GetPackedSigned(r, nterms, h.bits, "quantised values");
    ValidateColumn(h, c, name);
  }
  return b;
}
}  // namespace

CompressedTransportHeader DecodeHeader(std::span<const uint8_t> bytes, const std::string& name) {
  ByteReader r = Reader(bytes, name);
  CompressedTransportHeader h = ReadHeader(r, name);
  if (r.remaining() != 0) Fail(r, name, "trailing bytes after header");
  return h;
}

std::vector<uint8_t> EncodeColumnBlock(const CompressedTransportHeader& h,
                                       const CompressedColumnBlock& block) {
  ByteVectorWriter w;
  WriteBlock(w, h, block);
  return std::move(w.bytes());
}

CompressedColumnBlock DecodeColumnBlock(const CompressedTransportHeader& h,
                                        std::span<const uint8_t> bytes, const std::string& name) {
  ByteReader r = Reader(bytes, name);
  CompressedColumnBlock b = ReadBlock(r, h, name);
  if (r.remaining() != 0) Fail(r, name, "trailing bytes after column block");
  return b;
}

// File layout: magic "PRTCTFL1", u32 header bytes, header, u32 block count, then per block
// u32 block bytes and the block.
std::vector<uint8_t> EncodeCompressedFileStart(const CompressedTransportHeader& h) {
  const std::vector<uint8_t> head = EncodeHeader(h);
  ByteVectorWriter w;
  w.PutBytes(kFileMagic, 8);
  w.Put<uint32_t>(static_cast<uint32_t>(head.size()));
  w.PutBytes(head.data(), head.size());
  return std::move(w.bytes());
}

CompressedTransportHeader DecodeCompressedFileStart(std::span<const uint8_t> bytes,
                                                    const std::string& name,
                                                    std::size_t& body_offset) {
  ByteReader r = Reader(bytes, name);
  Magic(r, name, kFileMagic, 8, "file magic");
  const uint32_t hsize = r.Get<uint32_t>("header size");
  r.Need(hsize, "header");
  CompressedTransportHeader h = DecodeHeader(bytes.subspan(r.position(), hsize), name);
  body_offset = r.position() + hsize;
  return h;
}

std::vector<uint8_t> EncodeCompressedTransport(const CompressedTransport& t,
                                               uint32_t columns_per_block) {
  if (columns_per_block == 0) columns_per_block = 1;
  if (t.header.scheme == CompressionScheme::kCpca)
    throw std::invalid_argument("EncodeCompressedTransport: a cpca header has no columns");
  ByteVectorWriter w;
  {
    std::vector<uint8_t> start = EncodeCompressedFileStart(t.header);
    w.PutBytes(start.data(), start.size());
  }
  const uint32_t ncol = t.header.column_count();
  const uint32_t nblocks = (ncol + columns_per_block - 1) / columns_per_block;
  w.Put<uint32_t>(nblocks);
  std::size_t k = 0;
  for (uint32_t b = 0; b < nblocks; ++b) {
    CompressedColumnBlock block;
    block.first_column = b * columns_per_block;
    block.column_span = std::min(columns_per_block, ncol - block.first_column);
    while (k < t.columns.size() && t.columns[k].column < block.first_column + block.column_span) {
      block.columns.push_back(t.columns[k++]);
    }
    const std::vector<uint8_t> bytes = EncodeColumnBlock(t.header, block);
    w.Put<uint32_t>(static_cast<uint32_t>(bytes.size()));
    w.PutBytes(bytes.data(), bytes.size());
  }
  if (k != t.columns.size())
    throw InputError("EncodeCompressedTransport", "columns not sorted or out of range");
  return std::move(w.bytes());
}

CompressedTransport DecodeCompressedTransport(std::span<const uint8_t> bytes,
                                              const std::string& name) {
  ByteReader r = Reader(bytes, name);
  CompressedTransport t;
  std::size_t body = 0;
  t.header = DecodeCompressedFileStart(bytes, name, body);
  if (t.header.scheme == CompressionScheme::kCpca)
    throw InputError(name, "holds a CPCA transport (scheme cpca), not compressed columns");
  ByteReader r2 = Reader(bytes.subspan(body), name);
  const uint32_t nblocks = r2.Get<uint32_t>("block count");
  if (nblocks > t.header.column_count() || nblocks > r2.remaining() / 16)
    Fail(r2, name, "block count " + std::to_string(nblocks) + " impossible");
  std::size_t off = body + 4;
  uint64_t next_column = 0;
  for (uint32_t b = 0; b < nblocks; ++b) {
    ByteReader rs = Reader(bytes.subspan(off), name);
    const uint32_t bsize = rs.Get<uint32_t>("block size");
    rs.Need(bsize, "column block");
    CompressedColumnBlock block = DecodeColumnBlock(t.header, bytes.subspan(off + 4, bsize), name);
    if (block.first_column != next_column) Fail(rs, name, "column blocks not contiguous");
    next_column = static_cast<uint64_t>(block.first_column) + block.column_span;
    for (auto& c : block.columns) t.columns.push_back(std::move(c));
    off += 4 + static_cast<std::size_t>(bsize);
  }
  if (next_column != t.header.column_count())
    Fail(r, name, "column blocks do not cover every column");
  if (off != bytes.size()) Fail(r, name, "trailing bytes after the last column block");
  return t;
}

CompressedTransportHeader ReadCompressedTransportHeader(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open for reading");
  std::vector<uint8_t> start(12);
  in.read(reinterpret_cast<char*>(start.data()), static_cast<std::streamsize>(start.size()));
  start.resize(static_cast<std::size_t>(std::max<std::streamsize>(0, in.gcount())));
  ByteReader r = Reader(start, path);
  Magic(r, path, kFileMagic, 8, "file magic");
  const uint32_t hsize = r.Get<uint32_t>("header size");
  // The size is checked against the file before anything is allocated (safe on hostile input).
  const std::streampos here = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streamoff left = in.tellg() - here;
  in.seekg(here);
  if (!in || left < static_cast<std::streamoff>(hsize))
    Fail(Reader(start, path), path, "truncated: header");
  std::vector<uint8_t> header(hsize);
  in.read(reinterpret_cast<char*>(header.data()), static_cast<std::streamsize>(hsize));
  if (in.gcount() != static_cast<std::streamsize>(hsize))
    Fail(Reader(start, path), path, "truncated: header");
  return DecodeHeader(header, path);
}

void SegmentShape(const SpatialSegment& s, int& w, int& h) {
  if (s.kind == SpatialSegment::Kind::kGrid2D) {
    w = static_cast<int>(s.width);
    h = static_cast<int>(s.height);
  } else {
    w = static_cast<int>(s.count);
    h = 1;
  }
}

int MaxSegmentDepth(const SpatialSegment& s) {
  int w, h;
  SegmentShape(s, w, h);
  return WaveletMaxDepth2D(WaveletFilter::kLeGall53, w, h);
}

int MaxColumnDepth(const SpatialDomain& d) {
  int m = 0;
  for (const auto& s : d.segments) m = std::max(m, MaxSegmentDepth(s));
  return m;
}

}  // namespace prt
