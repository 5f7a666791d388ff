// Shared fixtures for the packager tests and the fuzz harness: a small pack with every section
// kind (a TRNS or a CPCA transport), and a canonical full read for comparing two packs.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "packager/prtpack_format.h"
#include "packager/prtpack_reader.h"
#include "packager/prtpack_transport.h"
#include "packager/prtpack_writer.h"

namespace prt::pack::testing {

// An octahedron-based closed mesh of 6 + 12 vertices (octahedron plus edge midpoints).
inline TriangleMesh MakeSmallMesh(double scale = 1.0) {
  TriangleMesh m;
  m.source = "small";
  const Vec3 v[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  const uint32_t f[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4},
                            {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (const Vec3& p : v) m.positions.push_back(p * scale);
  for (const auto& t : f) m.triangles.push_back({t[0], t[1], t[2]});
  for (const Vec3& p : m.positions) m.normals.push_back(Normalize(p));
  return m;
}

inline std::vector<uint8_t> PseudoRandomBytes(std::size_t n, uint32_t seed, bool compressible) {
  std::vector<uint8_t> b(n);
  uint32_t x = seed * 2654435761u + 1;
  for (std::size_t i = 0; i < n; ++i) {
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    b[i] = compressible ? static_cast<uint8_t>((x & 3) == 0 ? x >> 8 : 0) : static_cast<uint8_t>(x);
  }
  return b;
}

inline PackInput MakeSmallInput() {
  PackInput in;
  in.metadata_json = R"({"scene":{"name":"tiny"},"parameters":{"bits":9},"report":{"rays":42}})";
  PackMeshInput a;
  a.name = "octa";
  a.mesh = MakeSmallMesh();
  a.albedo = {0.5f, 0.25f, 0.75f};
  in.meshes.push_back(a);
  PackMeshInput g;
  g.name = "ground";
  g.mesh = MakeSmallMesh(3.0);
  g.is_ground = true;
  g.grid_resolution = 4;
  in.meshes.push_back(g);
  TransportInput t;
  t.encoding = 7;
  t.row_count = 12;
  t.params = {1, 2, 3, 4, 5};
  t.blocks.push_back({3, PseudoRandomBytes(120, 1, true)});  // zstd
  t.blocks.push_back({5, PseudoRandomBytes(40, 2, false)});  // stored as is
  t.blocks.push_back({1, {}});                               // empty block
  in.transport = t;
  return in;
}

// An image pack (IMGE, 1.2): a 4×3 image over the small input's two meshes and its 12 rows of T.
inline PackInput MakeImageInput() {
  PackInput in = MakeSmallInput();
  ImageSamplesInfo im;
  im.camera.eye = {0, 1, 4};
  im.camera.target = {0, 0.5, 0};
  im.camera.width = 4;
  im.camera.height = 3;
  im.camera.fov_deg = 35;
  im.pixel_mesh = {0, 0, 1, kImageBackground, 1, 1, 0, 0, 1, kImageBackground, 1, 0};
  in.image = im;
  return in;
}

// A supersampled image pack (IMGE holding PRTIMG03, 1.5): MakeImageInput at k = 4 with each
// pixel's coverage (pixel 1 half covered) and weight (coverage × its mesh's albedo).
inline PackInput MakeSupersampledImageInput() {
  PackInput in = MakeImageInput();
  ImageSamplesInfo& im = *in.image;
  im.supersample = 4;
  im.coverage.assign(im.pixels(), 1.f);
  im.pixel_weight.resize(im.pixels());
  for (std::size_t p = 0; p < im.pixels(); ++p) {
    const uint32_t m = im.pixel_mesh[p];
    const float cov = m == kImageBackground ? 0.f : (p == 1 ? 0.5f : 1.f);
    im.coverage[p] = cov;
    for (std::size_t c = 0; c < 3; ++c)
      im.pixel_weight[p][c] = m == kImageBackground ? 0.f : cov * in.meshes[m].albedo[c];
  }
  return in;
}

// Visibility maps at n = 16 for `vertices` vertices with every block kind: face 0 all visible,
// face 1 occluded, the other faces a vertex-dependent pattern (mixed blocks).
inline std::vector<uint8_t> MakeSmallVisibility(std::size_t vertices, uint32_t seed) {
  VisibilityBlocks b = MakeVisibilityBlocks(16, 1);
  std::vector<uint8_t> levels(6 * 16 * 16);
  for (std::size_t v = 0; v < vertices; ++v) {
    for (std::size_t t = 0; t < levels.size(); ++t) {
      const std::size_t face = t / 256, x = t % 16, y = (t / 16) % 16;
      levels[t] = face == 0   ? 1
                  : face == 1 ? 0
                              : static_cast<uint8_t>((x * (v + 1) + y * seed + face) % 5 < 2);
    }
    AppendVisibilityMap(b, levels);
  }
  return EncodeVisibilityBlocks(b);
}

// MakeSmallInput with visibility for both meshes (one VISB section each).
inline PackInput MakeSmallGlossyInput() {
  PackInput in = MakeSmallInput();
  VisibilityInput vis;
  for (std::size_t m = 0; m < in.meshes.size(); ++m) {
    vis.per_mesh.push_back(
        MakeSmallVisibility(in.meshes[m].mesh.positions.size(), static_cast<uint32_t>(m + 3)));
  }
  in.visibility = std::move(vis);
  return in;
}

// A valid compressed transport (formats/compressed_transport.h) for 12 samples at n = 2,
// split into blocks of 5 columns; with channels = 3, 3 × 12 channel-major rows (a term in each
// channel's rows).
inline CompressedTransport MakeSmallCompressedTransport(uint32_t channels = 1) {
  CompressedTransport ct;
  ct.header.cubemap_n = 2;
  ct.header.sample_count = 12 * channels;
  ct.header.channels = channels;
  ct.header.terms_per_column = 3;
  SpatialSegment seg;
  seg.count = 12;
  ct.header.domain.segments.push_back(seg);
  ct.header.domain = PerChannelDomain(ct.header.domain, channels);
  for (uint32_t col : {0u, 4u, 5u, 17u, 23u}) {
    CompressedColumn c;
    c.column = col;
    c.scale = 0.5f + float(col);
    c.index = {1, 2 + col % 10};
    c.q = {5, -static_cast<int32_t>(col) - 1};
    for (uint32_t ch = 1; ch < channels; ++ch) {
      c.index.push_back(12 * ch + col % 12);
      c.q.push_back(static_cast<int32_t>(ch + col));
    }
    ct.columns.push_back(c);
  }
  return ct;
}
inline TransportInput MakeSmallCompressedTransportInput(uint32_t channels = 1) {
  return MakeTransportInput(MakeSmallCompressedTransport(channels), 5);
}

// A valid clustered-PCA transport (formats/cpca_transport.h) built by hand for the 12 vertices
// of MakeSmallInput at n = 2 (24 columns): K = 2 clusters, S = 2 bases, bits 9 (|q| ≤ 255),
// coefficient bits 12 (|q| ≤ 2047); row r is in cluster 1 when r % 3 == 0, else 0. Cluster 0's
// second basis vector is empty (no variance) and its coefficients 0. With channels = 3, 3 × 12
// channel-major rows. prtpack_c_test.c checks the same numbers.
inline CpcaTransport MakeSmallCpcaTransport(uint32_t channels = 1) {
  CpcaTransport t;
  CompressedTransportHeader& h = t.header;
  h.cubemap_n = 2;
  h.sample_count = 12 * channels;
  h.channels = channels;
  h.scheme = CompressionScheme::kCpca;
  h.bits = 9;
  h.keep_fraction = 0.25;
  h.terms_per_column = 0;
  h.dither_seed = 7;
  h.cpca_clusters = 2;
  h.cpca_bases = 2;
  h.cpca_coefficient_bits = 12;
  h.cpca_method = CpcaMethod::kStandard;
  SpatialSegment seg;
  seg.count = 12;
  h.domain.segments.push_back(seg);
  h.domain = PerChannelDomain(h.domain, channels);
  CpcaCluster c0;
  c0.mean = {1.5f, {0, 3, 7}, {100, -50, 255}};
  c0.basis = {{0.25f, {1, 2}, {-3, 200}}, {}};
  c0.coefficient_scale = {0.5f, 0.0f};
  CpcaCluster c1;
  c1.mean = {2.0f, {0, 23}, {255, 1}};
  c1.basis = {{0.5f, {5, 6, 7, 8}, {1, -1, 2, -2}}, {0.125f, {23}, {-255}}};
  c1.coefficient_scale = {1.0f, 0.75f};
  t.clusters = {c0, c1};
  for (uint32_t r = 0; r < h.sample_count; ++r) {
    const uint32_t k = r % 3 == 0 ? 1 : 0;
    t.cluster_of.push_back(k);
    t.coefficients.push_back(static_cast<int32_t>(r * 37 % 2000) - 1000);
    t.coefficients.push_back(k == 1 ? -static_cast<int32_t>(r * 10) : 0);
  }
  return t;
}

// MakeSmallInput with the CPCA transport instead of TRNS (a 1.3 pack).
inline PackInput MakeSmallCpcaInput(uint32_t channels = 1) {
  PackInput in = MakeSmallInput();
  in.transport.reset();
  in.cpca = MakeSmallCpcaTransport(channels);
  return in;
}

// `in` with `payload` as its CPCA section, as given (codec none, CRITICAL): the writer validates
// what it encodes, so a hostile payload goes in as an unknown section whose type is then patched
// to CPCA, and the checksums are resealed.
inline std::vector<uint8_t> PackWithRawCpca(PackInput in, const std::vector<uint8_t>& payload) {
  in.cpca.reset();
  in.extra_sections.push_back({"XCPC", kFlagCritical, 0, payload});
  std::vector<uint8_t> file = WritePack(in);
  const uint32_t sections = LoadAt<uint32_t>(file, kHdrSectionCount);
  for (uint32_t i = 0; i < sections; ++i) {
    const std::size_t type = kHeaderSize + std::size_t(i) * kEntrySize + kSecType;
    if (LoadAt<uint32_t>(file, type) == FourCC("XCPC")) StoreAt<uint32_t>(file, type, kTypeCpca);
  }
  // A CPCA pack is 1.3 (with a TRNS too, as WritePack made it: its channel field stays 1.0's).
  if (!in.transport) StoreAt<uint16_t>(file, kHdrMinor, kVersionMinorCpca);
  ResealChecksums(file);
  return file;
}

// Everything a pack holds, fully decoded (throws InputError like the reader).
struct FullRead {
  std::string metadata;
  std::vector<UnpackedMesh> meshes;
  TransportIndex index;
  std::vector<std::vector<uint8_t>> blocks;
  std::vector<std::vector<uint8_t>> visibility;  // per vertex, all meshes: decoded levels
  std::vector<uint8_t> cpca;                     // EncodeCpcaTransport of the CPCA section
};

inline FullRead ReadEverything(const PackReader& r) {
  r.VerifyAll();
  FullRead out;
  out.metadata = r.ReadMetadata();
  for (std::size_t i = 0; i < r.mesh_count(); ++i) out.meshes.push_back(r.ReadMesh(i));
  if (r.has_transport()) {
    out.index = r.ReadTransportIndex();
    for (std::size_t b = 0; b < out.index.blocks.size(); ++b) {
      out.blocks.push_back(r.ReadTransportBlock(out.index, b));
    }
  }
  if (r.has_visibility()) {
    const VisibilityBlocks v = r.ReadAllVisibility();
    for (std::size_t i = 0; i < v.vertex_count; ++i)
      out.visibility.push_back(DecodeVisibilityMap(v, i));
  }
  if (r.has_cpca()) out.cpca = EncodeCpcaTransport(ReadCpcaTransport(r));
  return out;
}

inline bool SameRead(const FullRead& a, const FullRead& b) {
  if (a.metadata != b.metadata || a.meshes.size() != b.meshes.size() || a.blocks != b.blocks ||
      a.index.params != b.index.params || a.index.encoding != b.index.encoding ||
      a.index.row_count != b.index.row_count || a.index.column_count != b.index.column_count ||
      a.visibility != b.visibility || a.cpca != b.cpca) {
    return false;
  }
  for (std::size_t i = 0; i < a.meshes.size(); ++i) {
    const UnpackedMesh& x = a.meshes[i];
    const UnpackedMesh& y = b.meshes[i];
    if (x.name != y.name || x.positions != y.positions || x.normals != y.normals ||
        x.triangles != y.triangles || x.albedo != y.albedo || x.is_ground != y.is_ground ||
        x.grid_resolution != y.grid_resolution) {
      return false;
    }
  }
  return true;
}

}  // namespace prt::pack::testing
