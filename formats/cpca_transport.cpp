// Binary encoding of the clustered-PCA transport (docs/cpca.md). Safe on untrusted input: every
// count is checked against what the remaining bytes can hold before anything is allocated.
#include "formats/cpca_transport.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

constexpr char kBodyMagic[4] = {'P', 'C', 'P', 'C'};

int32_t MaxQ(int bits) {
  return (int32_t{1} << (bits - 1)) - 1;
}

uint32_t ZigZag(int32_t v) {
  return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31);
}
int32_t UnZigZag(uint32_t u) {
  return static_cast<int32_t>((u >> 1) ^ (~(u & 1) + 1));
}

// The body's reader: every failure is an InputError naming the file and the byte.
ByteReader BodyReader(std::span<const uint8_t> bytes, const std::string& name) {
  return ByteReader(bytes, [&name](const char* what, std::size_t at) {
    throw InputError(name, std::string("truncated: ") + what + " (at byte " + std::to_string(at) +
                               " of the CPCA body)");
  });
}
[[noreturn]] void Fail(const ByteReader& r, const std::string& name, const std::string& what) {
  throw InputError(name, what + " (at byte " + std::to_string(r.position()) + " of the CPCA body)");
}
// Out of line, so that Varint needs no stack frame for the message.
[[noreturn, gnu::cold, gnu::noinline]] void BadVarint(const ByteReader& r, const std::string& name,
                                                      const char* what) {
  Fail(r, name, std::string("varint longer than 5 bytes or above 2^32: ") + what);
}
// LEB128, at most 5 bytes, value must fit 32 bits.
uint32_t Varint(ByteReader& r, const std::string& name, const char* what) {
  const std::optional<uint32_t> v = r.GetVarint<uint32_t>(what);
  if (!v) BadVarint(r, name, what);
  return *v;
}

void CheckVector(const CpcaVector& v, uint32_t columns, int bits, const std::string& name,
                 const std::string& where) {
  if (!std::isfinite(v.scale) || v.scale < 0) throw InputError(name, where + ": bad scale");
  if (v.index.size() != v.q.size()) throw InputError(name, where + ": index/value count mismatch");
  if (v.scale == 0 && !v.index.empty())
    throw InputError(name, where + ": terms stored with scale 0");
  if (v.index.size() > columns) throw InputError(name, where + ": more terms than coefficients");
  const int32_t maxq = MaxQ(bits);
  for (std::size_t k = 0; k < v.index.size(); ++k) {
    if (v.index[k] >= columns) throw InputError(name, where + ": index out of range");
    if (k > 0 && v.index[k] <= v.index[k - 1])
      throw InputError(name, where + ": indices not strictly increasing");
    if (v.q[k] == 0 || v.q[k] > maxq || v.q[k] < -maxq)
      throw InputError(name, where + ": quantised value out of range");
  }
}

void PutVector(ByteVectorWriter& w, const CpcaVector& v) {
  w.Put(v.scale);
  w.PutVarint(v.index.size());
  uint32_t prev = 0;
  for (std::size_t k = 0; k < v.index.size(); ++k) {
    w.PutVarint(k == 0 ? v.index[0] : v.index[k] - prev - 1);
    prev = v.index[k];
  }
  for (int32_t q : v.q) w.PutVarint(ZigZag(q));
}

CpcaVector GetVector(ByteReader& r, uint32_t columns, int bits, const std::string& name,
                     const std::string& where) {
  CpcaVector v;
  v.scale = r.Get<float>("vector scale");
  const uint32_t n = Varint(r, name, "vector term count");
  // Every term takes at least two bytes (its gap and its value).
  if (n > columns || n > r.remaining() / 2)
    Fail(r, name, where + ": term count " + std::to_string(n) + " impossible");
  v.index.resize(n);
  v.q.resize(n);
  uint64_t at = 0;
  for (uint32_t k = 0; k < n; ++k) {
    const uint64_t gap = Varint(r, name, "vector index gap");
    at = k == 0 ? gap : at + gap + 1;
    if (at >= columns) Fail(r, name, where + ": index out of range");
    v.index[k] = static_cast<uint32_t>(at);
  }
  for (uint32_t k = 0; k < n; ++k) v.q[k] = UnZigZag(Varint(r, name, "vector value"));
  CheckVector(v, columns, bits, name, where);
  return v;
}

}  // namespace

std::size_t CpcaTransport::term_count() const {
  std::size_t n = 0;
  for (const CpcaCluster& c : clusters) {
    n += c.mean.term_count();
    for (const CpcaVector& v : c.basis) n += v.term_count();
  }
  return n;
}

float CpcaTransport::Value(const CpcaVector& v, std::size_t k) const {
  return static_cast<float>(static_cast<double>(v.q[k]) * v.scale / MaxQ(header.bits));
}

float CpcaTransport::Coefficient(std::size_t row, std::size_t i) const {
  const std::size_t S = bases();
  const float scale = clusters[cluster_of[row]].coefficient_scale[i];
  return static_cast<float>(static_cast<double>(coefficients[row * S + i]) * scale /
                            MaxQ(header.cpca_coefficient_bits));
}

void ValidateCpcaTransport(const CpcaTransport& t, const std::string& name) {
  ValidateHeader(t.header, name);
  const CompressedTransportHeader& h = t.header;
  if (h.scheme != CompressionScheme::kCpca) throw InputError(name, "scheme is not cpca");
  const std::size_t rows = h.sample_count;
  const std::size_t S = h.cpca_bases;
  if (t.cluster_of.size() != rows)
    throw InputError(name, "cluster ids for " + std::to_string(t.cluster_of.size()) +
                               " rows, header says " + std::to_string(rows));
  if (t.clusters.size() != h.cpca_clusters)
    throw InputError(name, std::to_string(t.clusters.size()) + " clusters, header says " +
                               std::to_string(h.cpca_clusters));
  if (t.coefficients.size() != rows * S)
    throw InputError(name, "coefficient count " + std::to_string(t.coefficients.size()) +
                               " is not rows × bases");
  for (std::size_t r = 0; r < rows; ++r)
    if (t.cluster_of[r] >= h.cpca_clusters)
      throw InputError(name, "row " + std::to_string(r) + ": cluster id out of range");
  const uint32_t cols = h.column_count();
  for (std::size_t c = 0; c < t.clusters.size(); ++c) {
    const CpcaCluster& k = t.clusters[c];
    const std::string where = "cluster " + std::to_string(c);
    CheckVector(k.mean, cols, h.bits, name, where + " mean");
    if (k.basis.size() != S || k.coefficient_scale.size() != S)
      throw InputError(name, where + ": basis count is not the header's");
    for (std::size_t i = 0; i < S; ++i) {
      CheckVector(k.basis[i], cols, h.bits, name, where + " basis " + std::to_string(i));
      if (!std::isfinite(k.coefficient_scale[i]) || k.coefficient_scale[i] < 0)
        throw InputError(name, where + ": bad coefficient scale");
    }
  }
  const int32_t maxq = MaxQ(h.cpca_coefficient_bits);
  for (std::size_t k = 0; k < t.coefficients.size(); ++k)
    if (t.coefficients[k] > maxq || t.coefficients[k] < -maxq)
      throw InputError(name, "row " + std::to_string(k / std::max<std::size_t>(1, S)) +
                                 ": coefficient out of range");
}

// Body: magic "PCPC"; per row its cluster id (LEB128); per cluster the mean, then S basis
// vectors, then S f32 coefficient scales (a vector: f32 scale, LEB128 term count, LEB128 index
// gaps (the first index itself, then index − previous − 1), zig-zag LEB128 values); then per row
// its S coefficients (zig-zag LEB128).
std::vector<uint8_t> EncodeCpcaBody(const CpcaTransport& t) {
  ValidateCpcaTransport(t, "EncodeCpcaBody");
  ByteVectorWriter w;
  w.PutBytes(kBodyMagic, 4);
  for (uint32_t c : t.cluster_of) w.PutVarint(c);
  for (const CpcaCluster& k : t.clusters) {
    PutVector(w, k.mean);
    for (const CpcaVector& v : k.basis) PutVector(w, v);
    for (float s : k.coefficient_scale) w.Put(s);
  }
  for (int32_t q : t.coefficients) w.PutVarint(ZigZag(q));
  return std::move(w.bytes());
}

CpcaTransport DecodeCpcaBody(const CompressedTransportHeader& h, std::span<const uint8_t> bytes,
                             const std::string& name) {
  ValidateHeader(h, name);
  if (h.scheme != CompressionScheme::kCpca) throw InputError(name, "scheme is not cpca");
  ByteReader r = BodyReader(bytes, name);
  for (int i = 0; i < 4; ++i)
    if (r.Get<char>("CPCA body magic") != kBodyMagic[i]) Fail(r, name, "bad magic: CPCA body");
  CpcaTransport t;
  t.header = h;
  const std::size_t rows = h.sample_count;
  const std::size_t S = h.cpca_bases;
  const uint32_t cols = h.column_count();
  // Each row takes at least one byte for its cluster and one per coefficient.
  if (rows * (1 + S) > r.remaining()) Fail(r, name, "truncated: " + std::to_string(rows) + " rows");
  t.cluster_of.resize(rows);
  for (std::size_t i = 0; i < rows; ++i) {
    t.cluster_of[i] = Varint(r, name, "cluster id");
    if (t.cluster_of[i] >= h.cpca_clusters)
      Fail(r, name, "row " + std::to_string(i) + ": cluster id out of range");
  }
  // Each cluster takes at least 5 bytes per vector and 4 per coefficient scale.
  if (static_cast<uint64_t>(h.cpca_clusters) * (5 + 9 * S) > r.remaining())
    Fail(r, name, "truncated: " + std::to_string(h.cpca_clusters) + " clusters");
  t.clusters.resize(h.cpca_clusters);
  for (std::size_t c = 0; c < t.clusters.size(); ++c) {
    CpcaCluster& k = t.clusters[c];
    const std::string where = "cluster " + std::to_string(c);
    k.mean = GetVector(r, cols, h.bits, name, where + " mean");
    k.basis.reserve(S);
    for (std::size_t i = 0; i < S; ++i)
      k.basis.push_back(GetVector(r, cols, h.bits, name, where + " basis " + std::to_string(i)));
    k.coefficient_scale.resize(S);
    for (float& s : k.coefficient_scale) s = r.Get<float>("coefficient scale");
  }
  if (rows * S > r.remaining()) Fail(r, name, "truncated: coefficients");
  t.coefficients.resize(rows * S);
  for (int32_t& q : t.coefficients) q = UnZigZag(Varint(r, name, "coefficient"));
  if (r.remaining() != 0) Fail(r, name, "trailing bytes after the coefficients");
  ValidateCpcaTransport(t, name);
  return t;
}

std::vector<uint8_t> EncodeCpcaTransport(const CpcaTransport& t) {
  std::vector<uint8_t> out = EncodeCompressedFileStart(t.header);
  const std::vector<uint8_t> body = EncodeCpcaBody(t);
  out.insert(out.end(), body.begin(), body.end());
  return out;
}

CpcaTransport DecodeCpcaTransport(std::span<const uint8_t> bytes, const std::string& name) {
  std::size_t body = 0;
  const CompressedTransportHeader h = DecodeCompressedFileStart(bytes, name, body);
  if (h.scheme != CompressionScheme::kCpca)
    throw InputError(
        name, std::string("holds a transport of scheme ") + ToString(h.scheme) + ", not cpca");
  return DecodeCpcaBody(h, bytes.subspan(body), name);
}

void DecodeCpcaRow(const CpcaTransport& t, std::size_t row, std::span<float> out) {
  const uint32_t cols = t.header.column_count();
  if (out.size() != cols) throw std::invalid_argument("DecodeCpcaRow: output size");
  std::fill(out.begin(), out.end(), 0.0f);
  const CpcaCluster& k = t.clusters[t.cluster_of[row]];
  std::vector<double> acc(cols, 0.0);
  for (std::size_t j = 0; j < k.mean.term_count(); ++j) acc[k.mean.index[j]] += t.Value(k.mean, j);
  for (std::size_t i = 0; i < k.basis.size(); ++i) {
    const double w = t.Coefficient(row, i);
    if (w == 0) continue;
    for (std::size_t j = 0; j < k.basis[i].term_count(); ++j)
      acc[k.basis[i].index[j]] += w * t.Value(k.basis[i], j);
  }
  for (uint32_t j = 0; j < cols; ++j) out[j] = static_cast<float>(acc[j]);
}

double CpcaDecodedRelativeError(const CpcaTransport& t, const float* rows_hat) {
  const std::size_t d = t.header.column_count();
  std::vector<float> row(d);
  double e = 0, n = 0;
  for (std::size_t r = 0; r < t.row_count(); ++r) {
    DecodeCpcaRow(t, r, row);
    for (std::size_t j = 0; j < d; ++j) {
      const double x = rows_hat[r * d + j];
      e += (x - row[j]) * (x - row[j]);
      n += x * x;
    }
  }
  return n > 0 ? std::sqrt(e / n) : std::sqrt(e);
}

}  // namespace prt
