// .prtpack writer (docs/prtpack-format.md): lays out the header, the section table and the
// 64-byte-aligned sections (META, MESH/MATL per mesh, TRNS or CPCA), then fills in the checksums.
#include "packager/prtpack_writer.h"

#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>

#include "formats/visibility_blocks.h"
#include "packager/draco_mesh_codec.h"
#include "packager/prtpack_format.h"
#include "vocabulary/errors.h"

namespace prt::pack {

std::vector<PackMeshInput> PackMeshesOf(const SceneGeometry& geometry) {
  std::vector<PackMeshInput> out;
  for (const SceneMesh& m : geometry.meshes) {
    out.push_back({m.name, m.mesh, m.albedo, m.is_ground,
                   static_cast<uint32_t>(std::max(0, m.grid_resolution))});
  }
  return out;
}
namespace {

struct PendingSection {
  uint32_t type = 0;
  uint32_t flags = 0;
  Codec codec = Codec::kNone;
  uint32_t id = 0;
  uint64_t raw_size = 0;
  std::vector<uint8_t> bytes;
};

std::vector<uint8_t> ZstdCompress(const uint8_t* data, std::size_t size, int level,
                                  const std::string& what) {
  std::vector<uint8_t> out(ZSTD_compressBound(size));
  const std::size_t n = ZSTD_compress(out.data(), out.size(), data, size, level);
  if (ZSTD_isError(n)) throw InputError(what, std::string("zstd: ") + ZSTD_getErrorName(n));
  out.resize(n);
  return out;
}

nlohmann::json MeshSummary(const PackMeshInput& m, const WriterOptions& o) {
  Vec3 lo{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
          std::numeric_limits<double>::max()};
  Vec3 hi = -lo;
  for (const Vec3& p : m.mesh.positions) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  return {{"name", m.name},
          {"vertices", m.mesh.positions.size()},
          {"triangles", m.mesh.triangles.size()},
          {"position_bits", o.position_bits},
          {"normal_bits", o.normal_bits},
          {"bbox_min", {lo.x, lo.y, lo.z}},
          {"bbox_max", {hi.x, hi.y, hi.z}},
          {"albedo", {m.albedo[0], m.albedo[1], m.albedo[2]}},
          {"is_ground", m.is_ground}};
}

// 1.1 only where the pack uses what 1.1 defines (a TRNS channel count other than 1), so that
// every other pack keeps the bytes 1.0 writers gave it; likewise 1.2 for IMGE and 1.3 for CPCA.
uint16_t MinorVersionOf(const PackInput& input) {
  if (input.glossy) return kVersionMinorGlossyTerms;
  if (input.image && input.image->supersample > 1) return kVersionMinorSupersampled;
  if (input.image && input.image->has_glossy_pixels()) return kVersionMinorGlossyPixels;
  if (input.cpca) return kVersionMinorCpca;
  if (input.image) return kVersionMinorImage;
  return input.transport && input.transport->channels != 1 ? kVersionMinorChannels : 0;
}

PendingSection MetaSection(const PackInput& input, const WriterOptions& o) {
  nlohmann::json meta = nlohmann::json::object();
  if (!input.metadata_json.empty()) {
    meta = nlohmann::json::parse(input.metadata_json, nullptr, /*allow_exceptions=*/false);
    if (meta.is_discarded() || !meta.is_object()) {
      throw InputError("metadata", "metadata is not a JSON object");
    }
  }
  meta["format"] = "prtpack";
  meta["format_version"] =
      std::to_string(kVersionMajor) + "." + std::to_string(MinorVersionOf(input));
  meta["writer"] = "prt-pack";
  nlohmann::json meshes = nlohmann::json::array();
  for (const PackMeshInput& m : input.meshes) meshes.push_back(MeshSummary(m, o));
  meta["meshes"] = std::move(meshes);
  const std::string text = meta.dump();
  PendingSection s;
  s.type = kTypeMeta;
  s.codec = Codec::kZstd;
  s.raw_size = text.size();
  s.bytes = ZstdCompress(reinterpret_cast<const uint8_t*>(text.data()), text.size(), o.zstd_level,
                         "metadata");
  return s;
}

PendingSection MaterialSection(const PackMeshInput& m, uint32_t id) {
  for (float a : m.albedo) {
    if (!(a >= 0.0f && a <= 1.0f)) throw InputError(m.name, "albedo outside [0, 1]");
  }
  if (m.name.size() > kMaxMeshNameLength) throw InputError(m.name, "mesh name too long");
  PendingSection s;
  s.type = kTypeMaterial;
  s.id = id;
  s.bytes.assign(kMaterialHeaderSize + m.name.size(), 0);
  for (int c = 0; c < 3; ++c) StoreAt<float>(s.bytes, std::size_t(4 * c), m.albedo[std::size_t(c)]);
  StoreAt<uint32_t>(s.bytes, 12, m.is_ground ? kMaterialFlagGround : 0u);
  StoreAt<uint32_t>(s.bytes, 16, m.grid_resolution);
  StoreAt<uint32_t>(s.bytes, 20, static_cast<uint32_t>(m.name.size()));
  std::copy(m.name.begin(), m.name.end(), s.bytes.begin() + kMaterialHeaderSize);
  s.raw_size = s.bytes.size();
  return s;
}

// TRNS: header, parameters, block index, then each block zstd-compressed on its own (or stored
// as is when zstd does not shrink it), every block 64-byte aligned inside the section.
// minor: the pack's minor version (from 1.1 on the channel count is always written).
PendingSection TransportSection(const TransportInput& t, const WriterOptions& o, uint16_t minor) {
  if (t.params.size() > kMaxTransportParams) {
    throw InputError("transport", "global parameters exceed 1 GiB");
  }
  if (t.blocks.size() > std::numeric_limits<uint32_t>::max()) {
    throw InputError("transport", "too many blocks");
  }
  if (t.channels != 1 && t.channels != 3) {
    throw InputError("transport", "channel count " + std::to_string(t.channels) + " is not 1 or 3");
  }
  if (t.row_count % t.channels != 0) {
    throw InputError("transport", "row count " + std::to_string(t.row_count) +
                                      " is not a multiple of the channel count " +
                                      std::to_string(t.channels));
  }
  const uint64_t index_offset = AlignUp(kTransportHeaderSize + t.params.size(), 8);
  const uint64_t index_end = index_offset + t.blocks.size() * kBlockEntrySize;
  std::vector<std::vector<uint8_t>> stored(t.blocks.size());
  std::vector<Codec> codecs(t.blocks.size(), Codec::kNone);
  uint64_t end = AlignUp(index_end, 64);
  std::vector<uint64_t> offsets(t.blocks.size());
  uint64_t columns = 0;
  for (std::size_t b = 0; b < t.blocks.size(); ++b) {
    const TransportBlockInput& in = t.blocks[b];
    if (in.column_count == 0) {
      throw InputError("transport", "block " + std::to_string(b) + " has no columns");
    }
    if (!in.bytes.empty()) {
      std::vector<uint8_t> z =
          ZstdCompress(in.bytes.data(), in.bytes.size(), o.zstd_level, "transport");
      if (z.size() < in.bytes.size()) {
        stored[b] = std::move(z);
        codecs[b] = Codec::kZstd;
      }
    }
    if (codecs[b] == Codec::kNone) stored[b] = in.bytes;
    offsets[b] = end;
    end = AlignUp(end + stored[b].size(), 64);
    columns += in.column_count;
  }
  PendingSection s;
  s.type = kTypeTransport;
  s.bytes.assign(end, 0);
  uint8_t* p = s.bytes.data();
  const std::span<uint8_t> sec(s.bytes);
  StoreAt<uint32_t>(sec, kTransportEncoding, t.encoding);
  StoreAt<uint32_t>(sec, kTransportBlockCount, static_cast<uint32_t>(t.blocks.size()));
  StoreAt<uint64_t>(sec, kTransportRowCount, t.row_count);
  StoreAt<uint64_t>(sec, kTransportColumnCount, columns);
  StoreAt<uint32_t>(sec, kTransportParamsSize, static_cast<uint32_t>(t.params.size()));
  // 1.1: the channel count; a one-channel transport keeps 1.0's reserved 0 (and the pack 1.0).
  StoreAt<uint32_t>(sec, kTransportChannels, minor < kVersionMinorChannels ? 0u : t.channels);
  std::copy(t.params.begin(), t.params.end(), p + kTransportHeaderSize);
  uint64_t first = 0;
  for (std::size_t b = 0; b < t.blocks.size(); ++b) {
    const std::span<uint8_t> e = SliceAt(sec, index_offset + b * kBlockEntrySize, kBlockEntrySize);
    StoreAt<uint64_t>(e, 0, first);
    StoreAt<uint32_t>(e, 8, t.blocks[b].column_count);
    StoreAt<uint32_t>(e, 12, static_cast<uint32_t>(codecs[b]));
    StoreAt<uint64_t>(e, 16, offsets[b]);
    StoreAt<uint64_t>(e, 24, stored[b].size());
    StoreAt<uint64_t>(e, 32, t.blocks[b].bytes.size());
    StoreAt<uint64_t>(e, 40, Checksum(stored[b].data(), stored[b].size()));
    std::copy(stored[b].begin(), stored[b].end(), p + offsets[b]);
    first += t.blocks[b].column_count;
  }
  StoreAt<uint64_t>(sec, kTransportIndexChecksum,
                    TransportIndexChecksum(p, t.params.size(), index_offset, t.blocks.size()));
  s.raw_size = s.bytes.size();
  return s;
}

// CPCA: the section payload zstd-compressed as one frame (or stored as is when zstd does not
// shrink it). CRITICAL: a reader that skipped it would see a pack without transport.
PendingSection CpcaSection(const CpcaTransport& t, const WriterOptions& o) {
  const std::vector<uint8_t> raw = EncodeCpcaSection(t);
  PendingSection s;
  s.type = kTypeCpca;
  s.flags = kFlagCritical;
  s.raw_size = raw.size();
  std::vector<uint8_t> z = ZstdCompress(raw.data(), raw.size(), o.zstd_level, "cpca transport");
  if (z.size() < raw.size()) {
    s.codec = Codec::kZstd;
    s.bytes = std::move(z);
  } else {
    s.bytes = raw;
  }
  return s;
}

}  // namespace

std::vector<uint8_t> EncodeCpcaSection(const CpcaTransport& t) {
  ValidateCpcaTransport(t, "cpca transport");
  const std::vector<uint8_t> params = EncodeHeader(t.header);
  const std::vector<uint8_t> body = EncodeCpcaBody(t);
  if (params.size() > kMaxTransportParams) {
    throw InputError("cpca transport", "header exceeds 1 GiB");
  }
  std::vector<uint8_t> out(kCpcaHeaderSize + params.size() + body.size(), 0);
  uint8_t* p = out.data();
  StoreAt<uint32_t>(out, kCpcaParamsSize, static_cast<uint32_t>(params.size()));
  StoreAt<uint32_t>(out, kCpcaChannels, t.header.channels);
  StoreAt<uint64_t>(out, kCpcaRowCount, t.header.sample_count);
  StoreAt<uint32_t>(out, kCpcaClusters, t.header.cpca_clusters);
  StoreAt<uint32_t>(out, kCpcaBases, t.header.cpca_bases);
  StoreAt<uint64_t>(out, kCpcaBodySize, body.size());
  std::copy(params.begin(), params.end(), p + kCpcaHeaderSize);
  std::copy(body.begin(), body.end(), p + kCpcaHeaderSize + params.size());
  return out;
}

std::vector<uint8_t> WritePack(const PackInput& input, const WriterOptions& options) {
  const uint32_t a = options.alignment;
  if (a < 64 || a > 65536 || (a & (a - 1)) != 0) {
    throw InputError("options", "alignment must be a power of two in 64..65536");
  }
  if (input.meshes.empty()) throw InputError("input", "a pack needs at least one mesh");
  if (input.transport && input.cpca) {
    throw InputError("input", "a pack has either a TRNS (column) or a CPCA transport, not both");
  }
  std::vector<PendingSection> sections;
  sections.push_back(MetaSection(input, options));
  for (std::size_t i = 0; i < input.meshes.size(); ++i) {
    const PackMeshInput& m = input.meshes[i];
    PendingSection mesh;
    mesh.type = kTypeMesh;
    mesh.codec = Codec::kDraco;
    mesh.id = static_cast<uint32_t>(i);
    mesh.bytes = EncodeMeshDraco(m.mesh, options.position_bits, options.normal_bits,
                                 m.name.empty() ? "mesh " + std::to_string(i) : m.name);
    mesh.raw_size = MeshRawSize(m.mesh.positions.size(), m.mesh.triangles.size());
    sections.push_back(std::move(mesh));
    sections.push_back(MaterialSection(m, static_cast<uint32_t>(i)));
  }
  for (const ExtraSectionInput& x : input.extra_sections) {
    if (x.type.size() != 4) throw InputError("extra section", "type must be 4 bytes");
    PendingSection s;
    s.type = LoadAt<uint32_t>(x.type, 0);
    if (s.type == kTypeMeta || s.type == kTypeMesh || s.type == kTypeMaterial ||
        s.type == kTypeTransport || s.type == kTypeVisibility || s.type == kTypeImage ||
        s.type == kTypeCpca || s.type == kTypeGlossy) {
      throw InputError("extra section", "type " + x.type + " is reserved");
    }
    s.flags = x.flags;
    s.id = x.id;
    s.bytes = x.bytes;
    s.raw_size = x.bytes.size();
    sections.push_back(std::move(s));
  }
  if (input.visibility) {
    const std::vector<std::vector<uint8_t>>& v = input.visibility->per_mesh;
    if (v.size() != input.meshes.size()) {
      throw InputError("visibility", "has " + std::to_string(v.size()) + " entries for " +
                                         std::to_string(input.meshes.size()) + " meshes");
    }
    int n = 0, bits = 0;
    for (std::size_t i = 0; i < v.size(); ++i) {
      const std::string what = "visibility of mesh " + std::to_string(i);
      const VisibilityBlocks blocks = DecodeVisibilityBlocks(v[i], what);
      if (blocks.vertex_count != input.meshes[i].mesh.positions.size()) {
        throw InputError(what, "holds " + std::to_string(blocks.vertex_count) + " maps for " +
                                   std::to_string(input.meshes[i].mesh.positions.size()) +
                                   " vertices");
      }
      if (i > 0 && (blocks.n != n || blocks.bits != bits)) {
        throw InputError(what, "n or bits differ from mesh 0's");
      }
      n = blocks.n;
      bits = blocks.bits;
      PendingSection s;
      s.type = kTypeVisibility;
      s.codec = Codec::kZstd;
      s.id = static_cast<uint32_t>(i);
      s.raw_size = v[i].size();
      s.bytes = ZstdCompress(v[i].data(), v[i].size(), options.zstd_level, what);
      sections.push_back(std::move(s));
    }
  }
  if (input.image) {
    const ImageSamplesInfo& im = *input.image;
    const std::string bytes = SerializeImageSamples(im);
    // Round trip: what a reader would refuse is refused here, naming the input.
    (void)ParseImageSamples(bytes, "image", static_cast<uint32_t>(input.meshes.size()));
    if (input.transport && input.transport->row_count != im.pixels() * input.transport->channels)
      throw InputError("image", std::to_string(im.pixels()) + " pixels do not match the " +
                                    std::to_string(input.transport->row_count) +
                                    " rows of the transport");
    if (input.cpca &&
        input.cpca->header.sample_count != uint64_t{im.pixels()} * input.cpca->header.channels)
      throw InputError("image", std::to_string(im.pixels()) + " pixels do not match the " +
                                    std::to_string(input.cpca->header.sample_count) +
                                    " rows of the CPCA transport");
    PendingSection s;
    s.type = kTypeImage;
    s.flags = kFlagCritical;
    s.codec = Codec::kZstd;
    s.raw_size = bytes.size();
    s.bytes = ZstdCompress(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(),
                           options.zstd_level, "image");
    sections.push_back(std::move(s));
  }
  if (input.glossy) {
    const std::string bytes = SerializeGlossyFactors(*input.glossy, false);
    const GlossyFactorTable t = ParseGlossyFactors(bytes, "glossy factors");
    if (t.mesh_factor.size() != input.meshes.size())
      throw InputError("glossy factors", std::to_string(t.mesh_factor.size()) +
                                             " meshes for the pack's " +
                                             std::to_string(input.meshes.size()));
    uint64_t vertices = 0;
    for (const PackMeshInput& m : input.meshes) vertices += m.mesh.positions.size();
    const uint64_t rows = input.transport ? input.transport->row_count
                          : input.cpca    ? input.cpca->header.sample_count
                                          : 0;
    if (rows != 0 && rows != vertices * uint64_t(t.terms))
      throw InputError("glossy factors", std::to_string(t.terms) + " terms × " +
                                             std::to_string(vertices) +
                                             " vertices do not match the " + std::to_string(rows) +
                                             " rows of the transport");
    PendingSection s;
    s.type = kTypeGlossy;
    s.flags = kFlagCritical;
    s.codec = Codec::kZstd;
    s.raw_size = bytes.size();
    s.bytes = ZstdCompress(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(),
                           options.zstd_level, "glossy factors");
    sections.push_back(std::move(s));
  }
  if (input.transport)
    sections.push_back(TransportSection(*input.transport, options, MinorVersionOf(input)));
  if (input.cpca) sections.push_back(CpcaSection(*input.cpca, options));

  const uint64_t table_end = kHeaderSize + uint64_t(sections.size()) * kEntrySize;
  std::vector<uint64_t> offsets(sections.size());
  uint64_t end = AlignUp(table_end, a);
  for (std::size_t i = 0; i < sections.size(); ++i) {
    offsets[i] = end;
    end = AlignUp(end + sections[i].bytes.size(), a);
  }
  // The file ends right after the last section (no trailing padding).
  const uint64_t file_size = offsets.back() + sections.back().bytes.size();
  std::vector<uint8_t> file(file_size, 0);
  uint8_t* h = file.data();
  std::copy(kMagic.begin(), kMagic.end(), h);
  StoreAt<uint16_t>(file, kHdrMajor, kVersionMajor);
  StoreAt<uint16_t>(file, kHdrMinor, MinorVersionOf(input));
  StoreAt<uint32_t>(file, kHdrHeaderSize, kHeaderSize);
  StoreAt<uint32_t>(file, kHdrSectionCount, static_cast<uint32_t>(sections.size()));
  StoreAt<uint32_t>(file, kHdrEntrySize, kEntrySize);
  StoreAt<uint64_t>(file, kHdrTableOffset, kHeaderSize);
  StoreAt<uint64_t>(file, kHdrFileSize, file_size);
  StoreAt<uint32_t>(file, kHdrAlignment, a);
  for (std::size_t i = 0; i < sections.size(); ++i) {
    const PendingSection& s = sections[i];
    const std::span<uint8_t> e =
        SliceAt(std::span<uint8_t>(file), kHeaderSize + i * kEntrySize, kEntrySize);
    StoreAt<uint32_t>(e, kSecType, s.type);
    StoreAt<uint32_t>(e, kSecFlags, s.flags);
    StoreAt<uint32_t>(e, kSecCodec, static_cast<uint32_t>(s.codec));
    StoreAt<uint32_t>(e, kSecId, s.id);
    StoreAt<uint64_t>(e, kSecOffset, offsets[i]);
    StoreAt<uint64_t>(e, kSecStored, s.bytes.size());
    StoreAt<uint64_t>(e, kSecRaw, s.raw_size);
    StoreAt<uint64_t>(e, kSecChecksum, Checksum(s.bytes.data(), s.bytes.size()));
    std::copy(s.bytes.begin(), s.bytes.end(), h + offsets[i]);
  }
  StoreAt<uint64_t>(file, kHdrChecksum,
                    HeaderChecksum(h, h + kHeaderSize, std::size_t(sections.size()) * kEntrySize));
  return file;
}

void WritePackFile(const std::string& path, const PackInput& input, const WriterOptions& options) {
  const std::vector<uint8_t> bytes = WritePack(input, options);
  // Written to path.tmp and renamed: a failed write (a full disk) keeps an earlier pack intact.
  const std::string tmp = path + ".tmp";
  std::error_code ec;
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out)
      throw InputError(path, std::string("cannot open for writing: ") + std::strerror(errno));
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    out.close();  // the last buffered bytes are written here
    if (!out) {
      const int e = errno;
      std::filesystem::remove(tmp, ec);
      throw InputError(path, std::string("write failed: ") + std::strerror(e));
    }
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    const std::string reason = ec.message();
    std::filesystem::remove(tmp, ec);
    throw InputError(path, "cannot rename temporary file: " + reason);
  }
}

}  // namespace prt::pack
