// transport.variance and the variance log (see transport_variance.h).
#include "formats/transport_variance.h"

#include <cmath>
#include <cstring>
#include <span>
#include <stdexcept>
#include <string>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// Version 2 holds the exact sums (two uint64 per texel, lo then hi); version 1 (prt-farm before
// the sums were exact) held doubles, which are read and rounded to the same units.
constexpr char kMagic[8] = {'P', 'R', 'T', 'V', 'A', 'R', '0', '2'};
constexpr char kMagicV1[8] = {'P', 'R', 'T', 'V', 'A', 'R', '0', '1'};
constexpr uint32_t kLogMagic = 0x324C5650;    // "PVL2": records of exact sums
constexpr uint32_t kLogMagicV1 = 0x474C5650;  // "PVLG": records of doubles (read, not written)
constexpr uint64_t kMaxMeshes = 1u << 20;
constexpr uint64_t kMaxSums = uint64_t{1} << 28;
constexpr double kUnit = 0x1p88;  // 2^kVarianceFractionBits
static_assert(kVarianceFractionBits == 88);

void PutVariance(ByteWriter& w, const TransportVariance& v) {
  w.Put<uint32_t>(v.cubemap_n);
  w.Put<uint32_t>(v.rays_per_texel);
  w.Put<uint64_t>(v.mesh_rows.size());
  for (std::size_t m = 0; m < v.mesh_rows.size(); ++m) {
    w.Put<uint64_t>(v.mesh_rows[m]);
    w.Put<uint64_t>(v.rows_covered[m]);
    // A mesh none of whose rows is covered has only zeros: nothing is written for it.
    if (v.rows_covered[m] > 0) {
      static_assert(sizeof(ExactVarianceSum) == 16);
      w.PutBytes(v.sums[m].data(), v.sums[m].size() * sizeof(ExactVarianceSum));
    }
  }
}

// `exact`: version 2's sums; else version 1's doubles.
TransportVariance GetVariance(ByteReader& in, const std::string& name, bool exact) {
  TransportVariance v;
  v.cubemap_n = in.Get<uint32_t>("cubemap n");
  v.rays_per_texel = in.Get<uint32_t>("rays per texel");
  const uint64_t meshes = in.Get<uint64_t>("mesh count");
  // A mesh none of whose rows is covered takes no bytes but its zeros take memory: at most
  // kMaxSums sums in all (4 GiB), whatever a hostile file claims.
  if (v.cubemap_n == 0 || v.cubemap_n > 4096 || meshes > kMaxMeshes ||
      meshes * 16 > in.remaining() || meshes * v.texels() > kMaxSums) {
    throw InputError(name, "damaged variance sums (inconsistent sizes)");
  }
  const std::size_t texels = static_cast<std::size_t>(v.texels());
  for (uint64_t m = 0; m < meshes; ++m) {
    v.mesh_rows.push_back(in.Get<uint64_t>("mesh rows"));
    v.rows_covered.push_back(in.Get<uint64_t>("rows covered"));
    const uint64_t covered = v.rows_covered.back();
    if (covered > v.mesh_rows.back() || v.mesh_rows.back() >= kMaxMeshRows)
      throw InputError(name, "damaged variance sums (more rows covered than the mesh has)");
    const std::size_t bytes = texels * (exact ? sizeof(ExactVarianceSum) : sizeof(double));
    if (covered > 0 && bytes > in.remaining())
      throw InputError(name, "truncated variance file in sums");
    std::vector<ExactVarianceSum> s(texels);
    if (covered > 0 && exact) {
      const std::string_view raw = in.Take(texels * sizeof(ExactVarianceSum), "sums");
      std::memcpy(s.data(), raw.data(), raw.size());
      // A row adds at most kMaxRowVariance = 2^4, i.e. 2^92 units: hi < covered · 2^28.
      for (const ExactVarianceSum& x : s)
        if ((x.hi >> 28) > covered)
          throw InputError(name, "damaged variance sums (beyond what its rows can hold)");
    } else if (covered > 0) {
      const std::string_view raw = in.Take(texels * sizeof(double), "sums");
      for (std::size_t j = 0; j < texels; ++j) {
        const double x = LoadAt<double>(raw, j * sizeof(double));
        if (!std::isfinite(x) || x < 0 || x >= static_cast<double>(covered) * kMaxRowVariance)
          throw InputError(name, "damaged variance sums (not finite, negative or too large)");
        s[j] = ExactVarianceSum::FromValue(x);
      }
    }
    v.sums.push_back(std::move(s));
  }
  return v;
}

ByteReader Reader(std::string_view bytes, const std::string& name) {
  return ByteReader(bytes, [&name](const char* what, std::size_t) {
    throw InputError(name, std::string("truncated variance file in ") + what);
  });
}

}  // namespace

ExactVarianceSum ExactVarianceSum::FromValue(double v) {
  // v·2^88 is exact (a power of two; v < 2^40 keeps it below 2^128), then rounded to an integer
  // (to nearest, ties to even: the default rounding mode; Embree's flush-to-zero does not matter,
  // anything it would flush is far below one unit).
  const double x = std::nearbyint(v * kUnit);
  ExactVarianceSum s;
  if (x < 0x1p64) {
    s.lo = static_cast<uint64_t>(x);
    return s;
  }
  // x ≥ 2^64 has at most 53 significant bits: hi = ⌊x / 2^64⌋ and the rest are both exact.
  const double hi = std::floor(x * 0x1p-64);
  s.hi = static_cast<uint64_t>(hi);
  s.lo = static_cast<uint64_t>(x - hi * 0x1p64);
  return s;
}

void ExactVarianceSum::Add(const ExactVarianceSum& o) {
  const uint64_t lo_sum = lo + o.lo;
  const uint64_t carry = lo_sum < lo ? 1 : 0;
  const uint64_t hi_part = hi + o.hi;
  const uint64_t hi_sum = hi_part + carry;
  if (hi_part < hi || hi_sum < hi_part)
    throw std::overflow_error("ExactVarianceSum: sum beyond 2^128 units");
  lo = lo_sum;
  hi = hi_sum;
}

double ExactVarianceSum::Value() const {
  return static_cast<double>(hi) * 0x1p-24 + static_cast<double>(lo) * 0x1p-88;
}

std::vector<double> TransportVariance::MeshSums(std::size_t m) const {
  std::vector<double> out(sums.at(m).size());
  for (std::size_t j = 0; j < out.size(); ++j) out[j] = sums[m][j].Value();
  return out;
}

void TransportVariance::AddRow(uint64_t sample, const float* variance) {
  std::size_t m = 0;
  if (sample_group) {
    if (sample >= sample_group->size() || (*sample_group)[sample] >= sums.size())
      throw std::out_of_range("TransportVariance::AddRow: sample " + std::to_string(sample) +
                              " beyond the groups' samples");
    m = (*sample_group)[sample];
  } else {
    uint64_t first = 0;
    while (m < mesh_rows.size() && sample >= first + mesh_rows[m]) first += mesh_rows[m++];
    if (m == mesh_rows.size())
      throw std::out_of_range("TransportVariance::AddRow: sample " + std::to_string(sample) +
                              " beyond the meshes' rows");
  }
  std::vector<ExactVarianceSum>& s = sums[m];
  for (std::size_t j = 0; j < s.size(); ++j) {
    const float x = variance[j];
    // !(x <= max) also refuses NaN.
    if (!(x >= 0.0f && x <= static_cast<float>(kMaxRowVariance)))
      throw NumericalError("variance " + std::to_string(x) + " of sample " +
                           std::to_string(sample) + ", texel " + std::to_string(j) +
                           " is not in [0, 16] (a texel's variance is at most 8/9)");
    s[j].Add(ExactVarianceSum::FromValue(x));
  }
  ++rows_covered[m];
}

void TransportVariance::Add(const TransportVariance& o) {
  if (o.cubemap_n != cubemap_n || o.mesh_rows != mesh_rows)
    throw std::invalid_argument("TransportVariance::Add: sums of another shape");
  for (std::size_t m = 0; m < sums.size(); ++m) {
    rows_covered[m] += o.rows_covered[m];
    for (std::size_t j = 0; j < sums[m].size(); ++j) sums[m][j].Add(o.sums[m][j]);
  }
}

std::vector<uint64_t> TransportVariance::Digits() const {
  std::vector<uint64_t> out;
  out.reserve(sums.size() * static_cast<std::size_t>(texels()) * 4);
  for (const std::vector<ExactVarianceSum>& s : sums) {
    for (const ExactVarianceSum& x : s) {
      out.push_back(x.lo & 0xffffffffu);
      out.push_back(x.lo >> 32);
      out.push_back(x.hi & 0xffffffffu);
      out.push_back(x.hi >> 32);
    }
  }
  return out;
}

void TransportVariance::AddDigits(std::span<const uint64_t> digits) {
  if (digits.size() != sums.size() * static_cast<std::size_t>(texels()) * 4)
    throw std::invalid_argument("TransportVariance::AddDigits: digits of another shape");
  std::size_t k = 0;
  for (std::vector<ExactVarianceSum>& s : sums) {
    for (ExactVarianceSum& x : s) {
      // Σ digit_i · 2^(32 i), each digit below 2^64: carried 32 bits at a time.
      uint64_t word[4];
      uint64_t carry = 0;
      for (int i = 0; i < 4; ++i) {
        const uint64_t d = digits[k + static_cast<std::size_t>(i)];
        const uint64_t low = (d & 0xffffffffu) + (carry & 0xffffffffu);
        word[i] = low & 0xffffffffu;
        carry = (d >> 32) + (carry >> 32) + (low >> 32);
      }
      k += 4;
      if (carry != 0) throw std::overflow_error("TransportVariance::AddDigits: beyond 2^128");
      x.Add({word[0] | (word[1] << 32), word[2] | (word[3] << 32)});
    }
  }
}

TransportVariance MakeTransportVariance(uint32_t cubemap_n, uint32_t rays_per_texel,
                                        std::vector<uint64_t> mesh_rows,
                                        SampleGroupMap sample_group) {
  for (uint64_t rows : mesh_rows)
    if (rows >= kMaxMeshRows)
      throw std::invalid_argument("variance sums: a mesh of 2^36 rows or more (see kMaxMeshRows)");
  TransportVariance v;
  v.cubemap_n = cubemap_n;
  if (mesh_rows.size() * v.texels() > kMaxSums)
    throw std::invalid_argument("variance sums: more than 2^28 (meshes x 6n^2), see kMaxSums");
  v.rays_per_texel = rays_per_texel;
  v.rows_covered.assign(mesh_rows.size(), 0);
  v.sums.assign(mesh_rows.size(),
                std::vector<ExactVarianceSum>(static_cast<std::size_t>(v.texels())));
  if (sample_group) {
    std::vector<uint64_t> counted(mesh_rows.size(), 0);
    for (uint32_t g : *sample_group) {
      if (g >= counted.size())
        throw std::invalid_argument("variance sums: a sample's group is beyond the groups");
      ++counted[g];
    }
    if (counted != mesh_rows)
      throw std::invalid_argument("variance sums: the samples' groups do not hold mesh_rows");
  }
  v.mesh_rows = std::move(mesh_rows);
  v.sample_group = std::move(sample_group);
  return v;
}

std::string EncodeTransportVariance(const TransportVariance& v) {
  ByteWriter w;
  w.PutBytes(kMagic, 8);
  PutVariance(w, v);
  std::string& out = w.bytes();
  w.Put<uint64_t>(Checksum64(out.data(), out.size()));
  return std::move(out);
}

TransportVariance DecodeTransportVariance(std::string_view bytes, const std::string& name) {
  const bool v2 = bytes.size() >= 16 && bytes.substr(0, 8) == std::string_view(kMagic, 8);
  const bool v1 = bytes.size() >= 16 && bytes.substr(0, 8) == std::string_view(kMagicV1, 8);
  if (!v1 && !v2) throw InputError(name, "not a prtfarm variance file (bad magic)");
  if (Checksum64(bytes.data(), bytes.size() - 8) != LoadAt<uint64_t>(bytes, bytes.size() - 8))
    throw InputError(name, "damaged variance file (checksum mismatch)");
  ByteReader in = Reader(bytes.substr(0, bytes.size() - 8), name);
  in.Take(8, "magic");
  TransportVariance v = GetVariance(in, name, v2);
  if (in.remaining() != 0) throw InputError(name, "damaged variance file (trailing bytes)");
  return v;
}

std::string EncodeVarianceLogRecord(const VarianceLogRecord& r) {
  ByteWriter body;
  body.Put<uint32_t>(static_cast<uint32_t>(r.phase.size()));
  body.PutBytes(r.phase.data(), r.phase.size());
  body.Put<uint64_t>(r.first);
  body.Put<uint64_t>(r.count);
  PutVariance(body, r.sums);
  const std::string& b = body.bytes();
  ByteWriter w;
  w.Put<uint32_t>(kLogMagic);
  w.Put<uint64_t>(b.size());
  w.PutBytes(b.data(), b.size());
  w.Put<uint64_t>(Checksum64(b.data(), b.size()));
  return std::move(w.bytes());
}

std::vector<VarianceLogRecord> DecodeVarianceLog(std::string_view bytes, const std::string& name) {
  std::vector<VarianceLogRecord> out;
  std::size_t at = 0;
  while (bytes.size() - at >= 12) {
    const auto magic = LoadAt<uint32_t>(bytes, at);
    const auto size = LoadAt<uint64_t>(bytes, at + 4);
    if ((magic != kLogMagic && magic != kLogMagicV1) || size > bytes.size() - at - 12 ||
        bytes.size() - at - 12 - size < 8)
      break;  // torn or damaged: the records after it are not trusted
    const std::string_view body = bytes.substr(at + 12, size);
    if (Checksum64(body.data(), body.size()) != LoadAt<uint64_t>(bytes, at + 12 + size)) break;
    try {
      ByteReader in = Reader(body, name);
      VarianceLogRecord r;
      const uint32_t len = in.Get<uint32_t>("phase name");
      r.phase = std::string(in.Take(len, "phase name"));
      r.first = in.Get<uint64_t>("first");
      r.count = in.Get<uint64_t>("count");
      r.sums = GetVariance(in, name, magic == kLogMagic);
      out.push_back(std::move(r));
    } catch (const InputError&) {
      break;
    }
    at += 12 + size + 8;
  }
  return out;
}

}  // namespace prt
