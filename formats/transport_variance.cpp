// transport.variance and the variance log (see transport_variance.h).
#include "formats/transport_variance.h"

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

#include "vocabulary/bytes.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

constexpr char kMagic[8] = {'P', 'R', 'T', 'V', 'A', 'R', '0', '1'};
constexpr uint32_t kLogMagic = 0x474C5650;  // "PVLG"
constexpr uint64_t kMaxMeshes = 1u << 20;

void PutVariance(ByteWriter& w, const TransportVariance& v) {
  w.Put<uint32_t>(v.cubemap_n);
  w.Put<uint32_t>(v.rays_per_texel);
  w.Put<uint64_t>(v.mesh_rows.size());
  for (std::size_t m = 0; m < v.mesh_rows.size(); ++m) {
    w.Put<uint64_t>(v.mesh_rows[m]);
    w.Put<uint64_t>(v.rows_covered[m]);
    // A mesh none of whose rows is covered has only zeros: nothing is written for it.
    if (v.rows_covered[m] > 0) w.PutBytes(v.sums[m].data(), v.sums[m].size() * sizeof(double));
  }
}

TransportVariance GetVariance(ByteReader& in, const std::string& name) {
  TransportVariance v;
  v.cubemap_n = in.Get<uint32_t>("cubemap n");
  v.rays_per_texel = in.Get<uint32_t>("rays per texel");
  const uint64_t meshes = in.Get<uint64_t>("mesh count");
  if (v.cubemap_n == 0 || v.cubemap_n > 4096 || meshes > kMaxMeshes ||
      meshes * 16 > in.remaining()) {
    throw InputError(name, "damaged variance sums (inconsistent sizes)");
  }
  for (uint64_t m = 0; m < meshes; ++m) {
    v.mesh_rows.push_back(in.Get<uint64_t>("mesh rows"));
    v.rows_covered.push_back(in.Get<uint64_t>("rows covered"));
    if (v.rows_covered.back() > v.mesh_rows.back())
      throw InputError(name, "damaged variance sums (more rows covered than the mesh has)");
    std::vector<double> s(static_cast<std::size_t>(v.texels()), 0.0);
    if (v.rows_covered.back() > 0) {
      const std::string_view raw = in.Take(s.size() * sizeof(double), "sums");
      std::memcpy(s.data(), raw.data(), raw.size());
    }
    for (double x : s) {
      if (!std::isfinite(x) || x < 0) throw InputError(name, "damaged variance sums (not finite)");
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

void TransportVariance::AddRow(uint64_t sample, const float* variance) {
  uint64_t first = 0;
  for (std::size_t m = 0; m < mesh_rows.size(); ++m) {
    if (sample < first + mesh_rows[m]) {
      std::vector<double>& s = sums[m];
      for (std::size_t j = 0; j < s.size(); ++j) s[j] += variance[j];
      ++rows_covered[m];
      return;
    }
    first += mesh_rows[m];
  }
  throw std::out_of_range("TransportVariance::AddRow: sample " + std::to_string(sample) +
                          " beyond the meshes' rows");
}

void TransportVariance::Add(const TransportVariance& o) {
  if (o.cubemap_n != cubemap_n || o.mesh_rows != mesh_rows)
    throw std::invalid_argument("TransportVariance::Add: sums of another shape");
  for (std::size_t m = 0; m < sums.size(); ++m) {
    rows_covered[m] += o.rows_covered[m];
    for (std::size_t j = 0; j < sums[m].size(); ++j) sums[m][j] += o.sums[m][j];
  }
}

TransportVariance MakeTransportVariance(uint32_t cubemap_n, uint32_t rays_per_texel,
                                        std::vector<uint64_t> mesh_rows) {
  TransportVariance v;
  v.cubemap_n = cubemap_n;
  v.rays_per_texel = rays_per_texel;
  v.rows_covered.assign(mesh_rows.size(), 0);
  v.sums.assign(mesh_rows.size(), std::vector<double>(static_cast<std::size_t>(v.texels()), 0.0));
  v.mesh_rows = std::move(mesh_rows);
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
  if (bytes.size() < 16 || bytes.substr(0, 8) != std::string_view(kMagic, 8))
    throw InputError(name, "not a prtfarm variance file (bad magic)");
  if (Checksum64(bytes.data(), bytes.size() - 8) != LoadAt<uint64_t>(bytes, bytes.size() - 8))
    throw InputError(name, "damaged variance file (checksum mismatch)");
  ByteReader in = Reader(bytes.substr(0, bytes.size() - 8), name);
  in.Take(8, "magic");
  TransportVariance v = GetVariance(in, name);
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
    if (magic != kLogMagic || size > bytes.size() - at - 12 || bytes.size() - at - 12 - size < 8)
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
      r.sums = GetVariance(in, name);
      out.push_back(std::move(r));
    } catch (const InputError&) {
      break;
    }
    at += 12 + size + 8;
  }
  return out;
}

}  // namespace prt
