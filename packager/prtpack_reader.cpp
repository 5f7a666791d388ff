// .prtpack reader (docs/prtpack-format.md). Every offset, size, count and index read from the
// file is range-checked before it is used, in 64-bit arithmetic that cannot overflow (sizes are
// compared against the remaining length, never added blindly), and every decoded size is
// bounded before anything is allocated. Fields are read with vocabulary/bytes.h's LoadAt and
// SliceAt, bounded themselves: a check forgotten here would throw, not read outside the file.
#include "packager/prtpack_reader.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <span>

#include "formats/compressed_transport.h"
#include "packager/draco_mesh_codec.h"
#include "packager/prtpack_format.h"
#include "vocabulary/errors.h"

namespace prt::pack {
namespace {

// Bytes of the file: either a private mmap of it or an owned copy.
class Storage {
 public:
  virtual ~Storage() = default;
  const uint8_t* data = nullptr;
  std::size_t size = 0;
};

class VectorStorage : public Storage {
 public:
  explicit VectorStorage(std::vector<uint8_t> v) : bytes_(std::move(v)) {
    data = bytes_.data();
    size = bytes_.size();
  }

 private:
  std::vector<uint8_t> bytes_;
};

class MmapStorage : public Storage {
 public:
  MmapStorage(void* p, std::size_t n) : map_(p) {
    data = static_cast<const uint8_t*>(p);
    size = n;
  }
  ~MmapStorage() override { munmap(map_, size); }

 private:
  void* map_;
};

std::string Hex(uint64_t v) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// [offset, offset + size) lies inside [0, limit).
bool InRange(uint64_t offset, uint64_t size, uint64_t limit) {
  return offset <= limit && size <= limit - offset;
}

bool KnownCodecFor(uint32_t type, uint32_t codec) {
  if (type == kTypeMeta) return codec == uint32_t(Codec::kNone) || codec == uint32_t(Codec::kZstd);
  if (type == kTypeMesh) return codec == uint32_t(Codec::kDraco);
  if (type == kTypeMaterial || type == kTypeTransport) return codec == uint32_t(Codec::kNone);
  if (type == kTypeVisibility || type == kTypeImage || type == kTypeCpca || type == kTypeGlossy) {
    return codec == uint32_t(Codec::kNone) || codec == uint32_t(Codec::kZstd);
  }
  return true;
}

bool IsKnownType(uint32_t type) {
  return type == kTypeMeta || type == kTypeMesh || type == kTypeMaterial ||
         type == kTypeTransport || type == kTypeVisibility || type == kTypeImage ||
         type == kTypeCpca || type == kTypeGlossy;
}

}  // namespace

struct PackReader::Impl {
  std::string name;
  std::unique_ptr<Storage> storage;
  ReaderOptions options;
  uint16_t major = 0, minor = 0;
  std::vector<SectionInfo> sections;
  std::size_t meta = 0;
  std::vector<std::size_t> mesh_sections, material_sections, visibility_sections;
  bool has_transport = false;
  std::size_t transport = 0;
  bool has_image = false;
  std::size_t image = 0;
  bool has_cpca = false;
  std::size_t cpca = 0;
  bool has_glossy = false;
  std::size_t glossy = 0;

  [[noreturn]] void Fail(const std::string& what) const { throw InputError(name, what); }
  const uint8_t* data() const { return storage->data; }

  std::string SectionName(std::size_t i) const {
    const SectionInfo& s = sections[i];
    return "section " + std::to_string(i) + " (" + s.type + " " + std::to_string(s.id) + ")";
  }

  void Parse();
  // The stored bytes of section i after its checksum passed.
  const uint8_t* CheckedBytes(std::size_t i) const;
  // Decompresses one zstd frame of exactly raw_size bytes (≤ the cap) into dst.
  void Unzstd(const uint8_t* src, uint64_t src_size, uint8_t* dst, uint64_t raw_size,
              const std::string& what) const;
  std::string Metadata() const;
  MeshMaterial Material(std::size_t i) const;
  UnpackedMesh Mesh(std::size_t i) const;
  TransportIndex Transport() const;
  VisibilityBlocks Visibility(std::size_t i) const;
  ImageSamplesInfo Image() const;
  GlossyFactorTable Glossy() const;
  // The CPCA section decompressed, its 32-byte header checked against raw_size.
  struct CpcaPayload {
    std::vector<uint8_t> raw;
    uint32_t channels = 0, clusters = 0, bases = 0, params_size = 0;
    uint64_t row_count = 0;
    std::span<const uint8_t> params() const {
      return std::span<const uint8_t>(raw).subspan(kCpcaHeaderSize, params_size);
    }
    std::span<const uint8_t> body() const {
      return std::span<const uint8_t>(raw).subspan(kCpcaHeaderSize + params_size);
    }
  };
  CpcaPayload CpcaBytes() const;
  CpcaTransport Cpca() const;
  void Block(const TransportIndex& index, std::size_t b, uint8_t* dst) const;
};

void PackReader::Impl::Parse() {
  const uint8_t* d = data();
  const uint64_t n = storage->size;
  const std::span<const uint8_t> file(d, n);
  if (n < kMagic.size() || std::memcmp(d, kMagic.data(), kMagic.size()) != 0) {
    if (n == 0) Fail("empty file: not a .prtpack");
    if (n < kMagic.size() && std::memcmp(d, kMagic.data(), n) == 0) {
      Fail("truncated: " + std::to_string(n) + " bytes, shorter than the .prtpack header");
    }
    Fail("not a .prtpack file (bad magic)");
  }
  if (n < kHeaderSize) {
    Fail("truncated: " + std::to_string(n) + " bytes, shorter than the 64-byte header");
  }
  major = LoadAt<uint16_t>(file, kHdrMajor);
  minor = LoadAt<uint16_t>(file, kHdrMinor);
  if (major != kVersionMajor) {
    Fail("unsupported .prtpack major version " + std::to_string(major) + " (this reader reads " +
         std::to_string(kVersionMajor) + ".x)");
  }
  const uint32_t header_size = LoadAt<uint32_t>(file, kHdrHeaderSize);
  const uint32_t count = LoadAt<uint32_t>(file, kHdrSectionCount);
  const uint32_t entry_size = LoadAt<uint32_t>(file, kHdrEntrySize);
  const uint64_t table_offset = LoadAt<uint64_t>(file, kHdrTableOffset);
  const uint64_t file_size = LoadAt<uint64_t>(file, kHdrFileSize);
  const uint32_t alignment = LoadAt<uint32_t>(file, kHdrAlignment);
  if (file_size > n) {
    Fail("truncated: " + std::to_string(n) + " bytes, the header says " +
         std::to_string(file_size));
  }
  if (file_size < n) {
    Fail("has " + std::to_string(n - file_size) + " trailing bytes after the declared end " +
         std::to_string(file_size));
  }
  if (header_size < kHeaderSize || header_size > 65536) Fail("bad header size");
  if (entry_size < kEntrySize || entry_size > 4096) Fail("bad section entry size");
  if (count > kMaxSectionCount) Fail("too many sections (" + std::to_string(count) + ")");
  if (table_offset != header_size) Fail("section table does not follow the header");
  if (alignment < 64 || alignment > 65536 || (alignment & (alignment - 1)) != 0) {
    Fail("bad section alignment " + std::to_string(alignment));
  }
  const uint64_t table_size = uint64_t(count) * entry_size;
  if (!InRange(table_offset, table_size, n)) Fail("truncated inside the section table");
  const uint64_t expect = LoadAt<uint64_t>(file, kHdrChecksum);
  const uint64_t got = HeaderChecksum(d, d + table_offset, table_size);
  if (expect != got) {
    Fail("header checksum mismatch (stored " + Hex(expect) + ", computed " + Hex(got) +
         "): the header or section table is corrupted");
  }
  uint64_t previous_end = table_offset + table_size;
  int metas = 0, transports = 0, images = 0, cpcas = 0, glossies = 0;
  std::vector<int64_t> mesh_by_id, material_by_id, visibility_by_id;
  for (uint32_t i = 0; i < count; ++i) {
    const std::span<const uint8_t> e =
        SliceAt(file, table_offset + uint64_t(i) * entry_size, entry_size);
    SectionInfo s;
    s.type_code = LoadAt<uint32_t>(e, kSecType);
    s.type = FourCCString(s.type_code);
    s.flags = LoadAt<uint32_t>(e, kSecFlags);
    s.codec = LoadAt<uint32_t>(e, kSecCodec);
    s.id = LoadAt<uint32_t>(e, kSecId);
    s.offset = LoadAt<uint64_t>(e, kSecOffset);
    s.stored_size = LoadAt<uint64_t>(e, kSecStored);
    s.raw_size = LoadAt<uint64_t>(e, kSecRaw);
    s.checksum = LoadAt<uint64_t>(e, kSecChecksum);
    s.known = IsKnownType(s.type_code);
    sections.push_back(s);
    const std::string where = SectionName(i);
    if (s.offset % alignment != 0) Fail(where + " is not aligned to " + std::to_string(alignment));
    if (s.offset < previous_end) Fail(where + " overlaps the table or the previous section");
    if (!InRange(s.offset, s.stored_size, n)) Fail(where + " extends past the end of the file");
    previous_end = s.offset + s.stored_size;
    if (!s.known) {
      if (s.flags & kFlagCritical) Fail("unknown critical section '" + s.type + "'");
      continue;  // unknown, not critical: skipped
    }
    if (!KnownCodecFor(s.type_code, s.codec)) {
      Fail(where + " has unsupported codec " + std::to_string(s.codec));
    }
    if (s.raw_size > options.max_section_bytes) {
      Fail(where + " declares " + std::to_string(s.raw_size) + " decoded bytes, above the limit " +
           std::to_string(options.max_section_bytes));
    }
    if (s.codec == uint32_t(Codec::kNone) && s.raw_size != s.stored_size) {
      Fail(where + " is uncompressed but its raw and stored sizes differ");
    }
    if (s.type_code == kTypeMeta) {
      ++metas;
      meta = i;
    } else if (s.type_code == kTypeTransport) {
      ++transports;
      transport = i;
    } else if (s.type_code == kTypeImage) {
      ++images;
      image = i;
    } else if (s.type_code == kTypeCpca) {
      ++cpcas;
      cpca = i;
    } else if (s.type_code == kTypeGlossy) {
      ++glossies;
      glossy = i;
    } else {
      auto& by_id = s.type_code == kTypeMesh       ? mesh_by_id
                    : s.type_code == kTypeMaterial ? material_by_id
                                                   : visibility_by_id;
      if (s.id >= count) Fail(where + " has id " + std::to_string(s.id) + " out of range");
      if (by_id.size() <= s.id) by_id.resize(s.id + 1, -1);
      if (by_id[s.id] >= 0) Fail(where + " repeats id " + std::to_string(s.id));
      by_id[s.id] = i;
    }
  }
  if (metas != 1) Fail("needs exactly one META section, has " + std::to_string(metas));
  if (transports > 1) Fail("has more than one TRNS section");
  if (images > 1) Fail("has more than one IMGE section");
  if (cpcas > 1) Fail("has more than one CPCA section");
  if (glossies > 1) Fail("has more than one GLSY section");
  if (glossies == 1 && images == 1) Fail("has both GLSY (vertex terms) and IMGE (pixels)");
  has_glossy = glossies == 1;
  if (cpcas == 1 && transports == 1) {
    Fail("has both a TRNS and a CPCA transport (a pack has one or the other)");
  }
  has_image = images == 1;
  has_transport = transports == 1;
  has_cpca = cpcas == 1;
  if (mesh_by_id.empty()) Fail("has no MESH section");
  if (mesh_by_id.size() != material_by_id.size()) Fail("MESH and MATL ids do not pair up");
  for (std::size_t m = 0; m < mesh_by_id.size(); ++m) {
    if (mesh_by_id[m] < 0 || material_by_id[m] < 0) {
      Fail("mesh " + std::to_string(m) + " lacks its MESH or MATL section");
    }
    mesh_sections.push_back(std::size_t(mesh_by_id[m]));
    material_sections.push_back(std::size_t(material_by_id[m]));
  }
  if (!visibility_by_id.empty()) {
    if (visibility_by_id.size() > mesh_by_id.size()) {
      Fail("VISB id " + std::to_string(visibility_by_id.size() - 1) + " has no mesh");
    }
    visibility_by_id.resize(mesh_by_id.size(), -1);
    for (std::size_t m = 0; m < mesh_by_id.size(); ++m) {
      if (visibility_by_id[m] < 0) {
        Fail("mesh " + std::to_string(m) + " lacks its VISB section (VISB must cover every mesh)");
      }
      visibility_sections.push_back(std::size_t(visibility_by_id[m]));
    }
  }
}

const uint8_t* PackReader::Impl::CheckedBytes(std::size_t i) const {
  const SectionInfo& s = sections[i];
  const uint8_t* p = data() + s.offset;
  const uint64_t got = Checksum(p, s.stored_size);
  if (got != s.checksum) {
    Fail(SectionName(i) + " checksum mismatch (stored " + Hex(s.checksum) + ", computed " +
         Hex(got) + "): the section is corrupted");
  }
  return p;
}

void PackReader::Impl::Unzstd(const uint8_t* src, uint64_t src_size, uint8_t* dst,
                              uint64_t raw_size, const std::string& what) const {
  if (raw_size > options.max_section_bytes) Fail(what + " exceeds the decoded-size limit");
  const unsigned long long declared = ZSTD_getFrameContentSize(src, src_size);
  if (declared == ZSTD_CONTENTSIZE_ERROR) Fail(what + " is not a zstd frame");
  if (declared == ZSTD_CONTENTSIZE_UNKNOWN) Fail(what + ": zstd frame does not declare its size");
  if (declared != raw_size) {
    Fail(what + ": zstd frame holds " + std::to_string(declared) + " bytes, the index says " +
         std::to_string(raw_size));
  }
  const std::size_t frame = ZSTD_findFrameCompressedSize(src, src_size);
  if (ZSTD_isError(frame) || frame != src_size) Fail(what + ": not exactly one zstd frame");
  const std::size_t got = ZSTD_decompress(dst, raw_size, src, src_size);
  if (ZSTD_isError(got)) Fail(what + ": zstd: " + ZSTD_getErrorName(got));
  if (got != raw_size) Fail(what + ": zstd produced a different size than declared");
}

std::string PackReader::Impl::Metadata() const {
  const SectionInfo& s = sections[meta];
  const uint8_t* p = CheckedBytes(meta);
  std::string text;
  // Metadata is a JSON object of a few KiB; a claim of more than 64 MiB is a hostile size, not a
  // scene (refused before the allocation).
  if (s.raw_size > (uint64_t{64} << 20))
    Fail("META claims " + std::to_string(s.raw_size) + " bytes decoded (at most 64 MiB)");
  if (s.codec == uint32_t(Codec::kZstd)) {
    text.resize(s.raw_size);
    Unzstd(p, s.stored_size, reinterpret_cast<uint8_t*>(text.data()), s.raw_size, "META");
  } else {
    text.assign(reinterpret_cast<const char*>(p), s.stored_size);
  }
  // accept() runs the parser without building a tree (no recursion on deep nesting).
  const std::size_t first = text.find_first_not_of(" \t\r\n");
  if (first == std::string::npos || text[first] != '{' || !nlohmann::json::accept(text)) {
    Fail("META is not a JSON object");
  }
  return text;
}

MeshMaterial PackReader::Impl::Material(std::size_t i) const {
  const std::size_t si = material_sections[i];
  const SectionInfo& s = sections[si];
  const uint8_t* p = CheckedBytes(si);
  const std::string where = SectionName(si);
  if (s.stored_size < kMaterialHeaderSize) Fail(where + " is too short");
  const std::span<const uint8_t> bytes(p, s.stored_size);
  MeshMaterial m;
  for (int c = 0; c < 3; ++c) {
    const float a = LoadAt<float>(bytes, std::size_t(4 * c));
    if (!(a >= 0.0f && a <= 1.0f)) Fail(where + " albedo outside [0, 1]");
    m.albedo[std::size_t(c)] = a;
  }
  const uint32_t flags = LoadAt<uint32_t>(bytes, 12);
  m.is_ground = (flags & kMaterialFlagGround) != 0;
  m.grid_resolution = LoadAt<uint32_t>(bytes, 16);
  const uint32_t name_length = LoadAt<uint32_t>(bytes, 20);
  if (name_length > kMaxMeshNameLength || s.stored_size != kMaterialHeaderSize + name_length) {
    Fail(where + " name length disagrees with the section size");
  }
  m.name.assign(reinterpret_cast<const char*>(p + kMaterialHeaderSize), name_length);
  return m;
}

UnpackedMesh PackReader::Impl::Mesh(std::size_t i) const {
  const std::size_t si = mesh_sections[i];
  const SectionInfo& s = sections[si];
  const std::string where = SectionName(si);
  const MeshMaterial material = Material(i);
  const uint8_t* p = CheckedBytes(si);
  const DracoMeshCounts counts = PeekDracoMeshCounts(p, s.stored_size, name + ": " + where);
  if (MeshRawSize(counts.points, counts.faces) != s.raw_size) {
    Fail(where + " declares " + std::to_string(counts.points) + " vertices and " +
         std::to_string(counts.faces) + " triangles, which disagrees with its raw size " +
         std::to_string(s.raw_size));
  }
  // A decompression-bomb guard: Draco allocates per its declared counts before it finds the
  // data missing. Real meshes decode to ≈ 2.4× their stored size (docs/prtpack-format.md).
  if (s.raw_size > kMaxMeshExpansion * s.stored_size + 4096) {
    Fail(where + " declares " + std::to_string(s.raw_size) + " decoded bytes from " +
         std::to_string(s.stored_size) + " stored: more than Draco can compress");
  }
  MeshArrays arrays = DecodeMeshDraco(p, s.stored_size, counts, name + ": " + where);
  UnpackedMesh m;
  m.name = material.name;
  m.albedo = material.albedo;
  m.is_ground = material.is_ground;
  m.grid_resolution = material.grid_resolution;
  m.positions = std::move(arrays.positions);
  m.normals = std::move(arrays.normals);
  m.triangles = std::move(arrays.triangles);
  return m;
}

TransportIndex PackReader::Impl::Transport() const {
  if (!has_transport) {
    Fail(has_cpca ? "has no TRNS (transport) section: its transport is CPCA (clustered PCA)"
                  : "has no TRNS (transport) section");
  }
  const SectionInfo& s = sections[transport];
  const std::string where = SectionName(transport);
  const uint8_t* p = data() + s.offset;
  const uint64_t n = s.stored_size;
  if (n < kTransportHeaderSize) Fail(where + " is too short for its header");
  const std::span<const uint8_t> sec(p, n);
  TransportIndex t;
  t.encoding = LoadAt<uint32_t>(sec, kTransportEncoding);
  const uint32_t block_count = LoadAt<uint32_t>(sec, kTransportBlockCount);
  t.row_count = LoadAt<uint64_t>(sec, kTransportRowCount);
  t.column_count = LoadAt<uint64_t>(sec, kTransportColumnCount);
  const uint32_t params_size = LoadAt<uint32_t>(sec, kTransportParamsSize);
  if (params_size > kMaxTransportParams) Fail(where + " parameters exceed 1 GiB");
  const uint64_t index_offset = AlignUp(kTransportHeaderSize + uint64_t(params_size), 8);
  const uint64_t index_size = uint64_t(block_count) * kBlockEntrySize;
  if (!InRange(index_offset, index_size, n)) Fail(where + " block index extends past the section");
  const uint64_t expect = LoadAt<uint64_t>(sec, kTransportIndexChecksum);
  const uint64_t got = TransportIndexChecksum(p, params_size, index_offset, block_count);
  if (expect != got) Fail(where + " index checksum mismatch: the transport index is corrupted");
  // The channel count (1.1; a reserved field that 1.0 readers ignore, so 1 in a 1.0 pack).
  if (minor >= kVersionMinorChannels) {
    const uint32_t channels = LoadAt<uint32_t>(sec, kTransportChannels);
    if (channels != 1 && channels != 3) {
      Fail(where + " channel count " + std::to_string(channels) + " is not 1 or 3");
    }
    t.channels = channels;
  }
  if (t.row_count % t.channels != 0) {
    Fail(where + " row count " + std::to_string(t.row_count) +
         " is not a multiple of its channel count " + std::to_string(t.channels));
  }
  t.params.assign(p + kTransportHeaderSize, p + kTransportHeaderSize + params_size);
  t.blocks.reserve(block_count);
  uint64_t next_column = 0;
  uint64_t previous_end = index_offset + index_size;
  for (uint32_t b = 0; b < block_count; ++b) {
    const std::span<const uint8_t> e =
        SliceAt(sec, index_offset + uint64_t(b) * kBlockEntrySize, kBlockEntrySize);
    const std::string bw = where + " block " + std::to_string(b);
    TransportBlockInfo info;
    info.first_column = LoadAt<uint64_t>(e, 0);
    info.column_count = LoadAt<uint32_t>(e, 8);
    info.codec = LoadAt<uint32_t>(e, 12);
    const uint64_t offset = LoadAt<uint64_t>(e, 16);
    info.stored_size = LoadAt<uint64_t>(e, 24);
    info.raw_size = LoadAt<uint64_t>(e, 32);
    info.checksum = LoadAt<uint64_t>(e, 40);
    if (info.first_column != next_column || info.column_count == 0) {
      Fail(bw + " columns are not contiguous with the previous block");
    }
    next_column += info.column_count;
    if (info.codec != uint32_t(Codec::kNone) && info.codec != uint32_t(Codec::kZstd)) {
      Fail(bw + " has unsupported codec " + std::to_string(info.codec));
    }
    if (offset % 64 != 0 || offset < previous_end || !InRange(offset, info.stored_size, n)) {
      Fail(bw + " byte range is misaligned, overlapping or outside the section");
    }
    previous_end = offset + info.stored_size;
    if (info.raw_size > options.max_section_bytes) Fail(bw + " exceeds the decoded-size limit");
    if (info.codec == uint32_t(Codec::kNone) && info.raw_size != info.stored_size) {
      Fail(bw + " is uncompressed but its raw and stored sizes differ");
    }
    info.offset = s.offset + offset;
    t.blocks.push_back(info);
  }
  if (next_column != t.column_count) Fail(where + " blocks do not add up to its column count");
  return t;
}

void PackReader::Impl::Block(const TransportIndex& index, std::size_t b, uint8_t* dst) const {
  const TransportBlockInfo& info = index.blocks[b];
  const std::string what = "transport block " + std::to_string(b);
  // The index may come from another reader: re-check the range against this file.
  if (!InRange(info.offset, info.stored_size, storage->size)) Fail(what + " is outside the file");
  const uint8_t* p = data() + info.offset;
  if (Checksum(p, info.stored_size) != info.checksum) {
    Fail(what + " checksum mismatch: the block is corrupted");
  }
  if (info.codec == uint32_t(Codec::kZstd)) {
    Unzstd(p, info.stored_size, dst, info.raw_size, what);
  } else if (info.raw_size == info.stored_size) {
    if (info.raw_size > 0) std::memcpy(dst, p, info.raw_size);
  } else {
    Fail(what + " is uncompressed but its raw and stored sizes differ");
  }
}

VisibilityBlocks PackReader::Impl::Visibility(std::size_t i) const {
  if (visibility_sections.empty()) Fail("has no VISB (visibility) sections");
  if (i >= visibility_sections.size())
    Fail("visibility of mesh " + std::to_string(i) + " out of range");
  const std::size_t si = visibility_sections[i];
  const SectionInfo& s = sections[si];
  const std::string where = SectionName(si);
  // The mesh's vertex count from its Draco header (cheap; checked against raw_size when read).
  const SectionInfo& mesh = sections[mesh_sections[i]];
  const DracoMeshCounts counts =
      PeekDracoMeshCounts(CheckedBytes(mesh_sections[i]), mesh.stored_size,
                          name + ": " + SectionName(mesh_sections[i]));
  const uint8_t* p = CheckedBytes(si);
  std::vector<uint8_t> raw;
  if (s.codec == uint32_t(Codec::kZstd)) {
    raw.resize(s.raw_size);
    Unzstd(p, s.stored_size, raw.data(), s.raw_size, where);
  } else {
    raw.assign(p, p + s.stored_size);
  }
  VisibilityBlocks v = DecodeVisibilityBlocks(raw, name + ": " + where);
  if (v.vertex_count != counts.points) {
    Fail(where + " holds " + std::to_string(v.vertex_count) + " visibility maps for a mesh of " +
         std::to_string(counts.points) + " vertices");
  }
  return v;
}

GlossyFactorTable PackReader::Impl::Glossy() const {
  if (!has_glossy) Fail("has no GLSY (glossy factors) section");
  const SectionInfo& s = sections[glossy];
  const std::string where = SectionName(glossy);
  const uint8_t* p = CheckedBytes(glossy);
  std::string raw(s.raw_size, '\0');
  if (s.codec == uint32_t(Codec::kZstd)) {
    Unzstd(p, s.stored_size, reinterpret_cast<uint8_t*>(raw.data()), s.raw_size, where);
  } else {
    raw.assign(reinterpret_cast<const char*>(p), s.stored_size);
  }
  GlossyFactorTable t = ParseGlossyFactors(raw, name + ": " + where);
  if (t.mesh_factor.size() != mesh_sections.size())
    Fail(where + " has " + std::to_string(t.mesh_factor.size()) + " meshes for the pack's " +
         std::to_string(mesh_sections.size()));
  uint64_t vertices = 0;
  for (std::size_t m = 0; m < mesh_sections.size(); ++m) {
    const SectionInfo& mesh = sections[mesh_sections[m]];
    vertices += PeekDracoMeshCounts(CheckedBytes(mesh_sections[m]), mesh.stored_size,
                                    name + ": " + SectionName(mesh_sections[m]))
                    .points;
  }
  uint64_t rows = 0;
  if (has_transport) rows = Transport().row_count;
  if (has_cpca) rows = CpcaBytes().row_count;
  if ((has_transport || has_cpca) && rows != vertices * uint64_t(t.terms))
    Fail(where + " has " + std::to_string(t.terms) + " terms × " + std::to_string(vertices) +
         " vertices for " + std::to_string(rows) + " transport rows");
  return t;
}

ImageSamplesInfo PackReader::Impl::Image() const {
  if (!has_image) Fail("has no IMGE (image) section");
  const SectionInfo& s = sections[image];
  const std::string where = SectionName(image);
  const uint8_t* p = CheckedBytes(image);
  std::string raw(s.raw_size, '\0');
  if (s.codec == uint32_t(Codec::kZstd)) {
    Unzstd(p, s.stored_size, reinterpret_cast<uint8_t*>(raw.data()), s.raw_size, where);
  } else {
    raw.assign(reinterpret_cast<const char*>(p), s.stored_size);
  }
  ImageSamplesInfo info =
      ParseImageSamples(raw, name + ": " + where, static_cast<uint32_t>(mesh_sections.size()));
  if (has_transport) {
    const TransportIndex t = Transport();
    if (t.row_count != info.pixels() * t.channels)
      Fail(where + " has " + std::to_string(info.pixels()) + " pixels for " +
           std::to_string(t.row_count) + " rows of " + std::to_string(t.channels) +
           " channel(s) in TRNS");
  }
  if (has_cpca) {
    const CpcaPayload c = CpcaBytes();
    if (c.row_count != info.pixels() * c.channels)
      Fail(where + " has " + std::to_string(info.pixels()) + " pixels for " +
           std::to_string(c.row_count) + " rows of " + std::to_string(c.channels) +
           " channel(s) in CPCA");
  }
  return info;
}

PackReader::Impl::CpcaPayload PackReader::Impl::CpcaBytes() const {
  if (!has_cpca) {
    Fail(has_transport ? "has no CPCA section: its transport is TRNS (compressed columns)"
                       : "has no CPCA (clustered-PCA transport) section");
  }
  const SectionInfo& s = sections[cpca];
  const std::string where = SectionName(cpca);
  const uint8_t* p = CheckedBytes(cpca);
  CpcaPayload c;
  // raw_size ≤ max_section_bytes (Parse); for zstd the frame must declare exactly raw_size.
  if (s.codec == uint32_t(Codec::kZstd)) {
    c.raw.resize(s.raw_size);
    Unzstd(p, s.stored_size, c.raw.data(), s.raw_size, where);
  } else {
    c.raw.assign(p, p + s.stored_size);
  }
  const uint64_t n = c.raw.size();
  if (n < kCpcaHeaderSize) Fail(where + " is too short for its header");
  c.params_size = LoadAt<uint32_t>(c.raw, kCpcaParamsSize);
  const uint32_t params_size = c.params_size;
  c.channels = LoadAt<uint32_t>(c.raw, kCpcaChannels);
  c.row_count = LoadAt<uint64_t>(c.raw, kCpcaRowCount);
  c.clusters = LoadAt<uint32_t>(c.raw, kCpcaClusters);
  c.bases = LoadAt<uint32_t>(c.raw, kCpcaBases);
  const uint64_t body_size = LoadAt<uint64_t>(c.raw, kCpcaBodySize);
  if (!InRange(kCpcaHeaderSize, params_size, n) || body_size != n - kCpcaHeaderSize - params_size) {
    Fail(where + " parameter and body sizes (" + std::to_string(params_size) + " + " +
         std::to_string(body_size) + ") disagree with its size " + std::to_string(n));
  }
  if (c.channels != 1 && c.channels != 3) {
    Fail(where + " channel count " + std::to_string(c.channels) + " is not 1 or 3");
  }
  if (c.row_count % c.channels != 0) {
    Fail(where + " row count " + std::to_string(c.row_count) +
         " is not a multiple of its channel count " + std::to_string(c.channels));
  }
  return c;
}

CpcaTransport PackReader::Impl::Cpca() const {
  const CpcaPayload c = CpcaBytes();
  const std::string where = name + ": " + SectionName(cpca);
  const CompressedTransportHeader h = DecodeHeader(c.params(), where + " parameters");
  if (h.scheme != CompressionScheme::kCpca) {
    throw InputError(where,
                     std::string("parameters are of scheme ") + ToString(h.scheme) + ", not cpca");
  }
  if (h.sample_count != c.row_count || h.channels != c.channels || h.cpca_clusters != c.clusters ||
      h.cpca_bases != c.bases) {
    throw InputError(
        where, "parameters (" + std::to_string(h.sample_count) + " rows, " +
                   std::to_string(h.channels) + " channel(s), " + std::to_string(h.cpca_clusters) +
                   " clusters, " + std::to_string(h.cpca_bases) +
                   " bases) disagree with the section's (" + std::to_string(c.row_count) + ", " +
                   std::to_string(c.channels) + ", " + std::to_string(c.clusters) + ", " +
                   std::to_string(c.bases) + ")");
  }
  return DecodeCpcaBody(h, c.body(), where);
}

PackReader::PackReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PackReader::PackReader(PackReader&&) noexcept = default;
PackReader& PackReader::operator=(PackReader&&) noexcept = default;
PackReader::~PackReader() = default;

PackReader PackReader::OpenFile(const std::string& path, const ReaderOptions& options) {
  auto impl = std::make_unique<Impl>();
  impl->name = path;
  impl->options = options;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw InputError(path, "not a regular file");
  }
  const auto size = static_cast<std::size_t>(st.st_size);
  void* map = size > 0 ? ::mmap(nullptr, size, PROT_READ, MAP_PRIVATE, fd, 0) : MAP_FAILED;
  if (map != MAP_FAILED) {
    impl->storage = std::make_unique<MmapStorage>(map, size);
  } else {
    std::vector<uint8_t> bytes(size);
    std::size_t done = 0;
    while (done < size) {
      const ssize_t r = ::read(fd, bytes.data() + done, size - done);
      if (r <= 0) break;
      done += static_cast<std::size_t>(r);
    }
    bytes.resize(done);
    impl->storage = std::make_unique<VectorStorage>(std::move(bytes));
  }
  ::close(fd);
  impl->Parse();
  return PackReader(std::move(impl));
}

PackReader PackReader::OpenMemory(const void* data, std::size_t size, const std::string& name,
                                  const ReaderOptions& options) {
  auto impl = std::make_unique<Impl>();
  impl->name = name;
  impl->options = options;
  const auto* b = static_cast<const uint8_t*>(data);
  impl->storage = std::make_unique<VectorStorage>(size > 0 ? std::vector<uint8_t>(b, b + size)
                                                           : std::vector<uint8_t>());
  impl->Parse();
  return PackReader(std::move(impl));
}

const std::string& PackReader::name() const {
  return impl_->name;
}
uint16_t PackReader::version_major() const {
  return impl_->major;
}
uint16_t PackReader::version_minor() const {
  return impl_->minor;
}
uint64_t PackReader::file_size() const {
  return impl_->storage->size;
}
const std::vector<SectionInfo>& PackReader::sections() const {
  return impl_->sections;
}
std::size_t PackReader::mesh_count() const {
  return impl_->mesh_sections.size();
}
bool PackReader::has_transport() const {
  return impl_->has_transport;
}

bool PackReader::has_cpca() const {
  return impl_->has_cpca;
}

CpcaTransport PackReader::ReadCpcaTransport() const {
  return impl_->Cpca();
}

bool PackReader::has_visibility() const {
  return !impl_->visibility_sections.empty();
}

bool PackReader::has_glossy() const {
  return impl_->has_glossy;
}

GlossyFactorTable PackReader::ReadGlossy() const {
  return impl_->Glossy();
}

bool PackReader::has_image() const {
  return impl_->has_image;
}

ImageSamplesInfo PackReader::ReadImage() const {
  return impl_->Image();
}

VisibilityBlocks PackReader::ReadVisibility(std::size_t i) const {
  return impl_->Visibility(i);
}

VisibilityBlocks PackReader::ReadAllVisibility() const {
  if (!has_visibility()) impl_->Fail("has no VISB (visibility) sections");
  VisibilityBlocks all = impl_->Visibility(0);
  for (std::size_t m = 1; m < mesh_count(); ++m) {
    const VisibilityBlocks v = impl_->Visibility(m);
    if (v.n != all.n || v.bits != all.bits) {
      impl_->Fail(impl_->SectionName(impl_->visibility_sections[m]) +
                  ": n or bits differ from mesh 0's visibility");
    }
    AppendVisibilityBlocks(all, v);
  }
  return all;
}

std::string PackReader::ReadMetadata() const {
  return impl_->Metadata();
}

UnpackedMesh PackReader::ReadMesh(std::size_t i) const {
  if (i >= mesh_count()) impl_->Fail("mesh index " + std::to_string(i) + " out of range");
  return impl_->Mesh(i);
}

MeshMaterial PackReader::ReadMaterial(std::size_t i) const {
  if (i >= mesh_count()) impl_->Fail("mesh index " + std::to_string(i) + " out of range");
  return impl_->Material(i);
}

TransportIndex PackReader::ReadTransportIndex() const {
  return impl_->Transport();
}

std::vector<uint8_t> PackReader::ReadTransportBlock(const TransportIndex& index,
                                                    std::size_t b) const {
  if (b >= index.blocks.size())
    impl_->Fail("transport block " + std::to_string(b) + " out of range");
  const uint64_t raw = index.blocks[b].raw_size;
  if (raw > impl_->options.max_section_bytes) impl_->Fail("transport block exceeds the limit");
  std::vector<uint8_t> out(raw);
  impl_->Block(index, b, out.data());
  return out;
}

void PackReader::ReadTransportBlockInto(const TransportIndex& index, std::size_t b, void* dst,
                                        std::size_t dst_size) const {
  if (b >= index.blocks.size())
    impl_->Fail("transport block " + std::to_string(b) + " out of range");
  if (dst_size != index.blocks[b].raw_size) {
    impl_->Fail("transport block " + std::to_string(b) + " needs a buffer of " +
                std::to_string(index.blocks[b].raw_size) + " bytes");
  }
  impl_->Block(index, b, static_cast<uint8_t*>(dst));
}

void PackReader::VerifyAll() const {
  for (std::size_t i = 0; i < impl_->sections.size(); ++i) impl_->CheckedBytes(i);
  impl_->Metadata();
  for (std::size_t m = 0; m < mesh_count(); ++m) impl_->Mesh(m);
  if (has_visibility()) ReadAllVisibility();
  if (impl_->has_image) impl_->Image();
  if (impl_->has_glossy) impl_->Glossy();
  if (impl_->has_cpca) impl_->Cpca();
  if (impl_->has_transport) {
    const TransportIndex t = impl_->Transport();
    std::vector<uint8_t> buffer;
    for (std::size_t b = 0; b < t.blocks.size(); ++b) {
      buffer.resize(t.blocks[b].raw_size);
      impl_->Block(t, b, buffer.data());
    }
  }
}

TriangleMesh UnpackedMesh::ToTriangleMesh() const {
  TriangleMesh m;
  m.source = name;
  const std::size_t nv = vertex_count();
  m.positions.resize(nv);
  m.normals.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    m.positions[i] = {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
    m.normals[i] = {normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]};
  }
  m.triangles.resize(triangle_count());
  for (std::size_t t = 0; t < m.triangles.size(); ++t) {
    m.triangles[t] = {triangles[3 * t], triangles[3 * t + 1], triangles[3 * t + 2]};
  }
  return m;
}

}  // namespace prt::pack
