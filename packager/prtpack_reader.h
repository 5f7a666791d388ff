// Reader for .prtpack assets (docs/prtpack-format.md): the scene's meshes, materials, metadata
// and compressed transport: column blocks (TRNS) or clustered PCA (CPCA). No MPI, no Embree, no
// Draco or zstd in this header.
//
// Safe on untrusted input: every offset, size, count and index is validated before use, every
// decoded size is bounded (ReaderOptions::max_section_bytes) before anything is allocated, and
// every failure -- truncation, corruption, an unsupported version, a malicious size -- throws
// prt::InputError naming the file (or "<memory>") and the problem. Nothing aborts or hangs.
//
// Thread safety: a PackReader is immutable after Open; its const methods may run concurrently.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "formats/cpca_transport.h"
#include "formats/glossy_factors.h"
#include "formats/image_file.h"
#include "formats/visibility_blocks.h"
#include "vocabulary/mesh.h"

namespace prt::pack {

struct ReaderOptions {
  // Largest decoded (raw) size accepted for any one section or transport block.
  uint64_t max_section_bytes = uint64_t(2) << 30;
};

// One entry of the section table, as stored.
struct SectionInfo {
  std::string type;  // FourCC, e.g. "MESH" (non-printable bytes shown as '?')
  uint32_t type_code = 0;
  uint32_t flags = 0;
  uint32_t codec = 0;  // 0 none, 1 zstd, 2 draco
  uint32_t id = 0;     // mesh index for MESH and MATL
  uint64_t offset = 0;
  uint64_t stored_size = 0;
  uint64_t raw_size = 0;
  uint64_t checksum = 0;
  bool known = false;  // a section type this reader understands
};

// A mesh as unpacked: point i is vertex i of the mesh that was packed (positions within the
// documented quantisation), triangle i is triangle i with the same corners.
struct UnpackedMesh {
  std::string name;
  std::vector<float> positions;     // 3 per vertex
  std::vector<float> normals;       // 3 per vertex, unit within the normal quantisation
  std::vector<uint32_t> triangles;  // 3 per triangle
  std::array<float, 3> albedo{0.8f, 0.8f, 0.8f};
  bool is_ground = false;
  uint32_t grid_resolution = 0;
  std::size_t vertex_count() const { return positions.size() / 3; }
  std::size_t triangle_count() const { return triangles.size() / 3; }
  // The same mesh as the vocabulary type (double positions, `source` = the pack's name).
  TriangleMesh ToTriangleMesh() const;
};

// A mesh's material (the MATL section), readable without decoding the mesh.
struct MeshMaterial {
  std::string name;
  std::array<float, 3> albedo{0.8f, 0.8f, 0.8f};
  bool is_ground = false;
  uint32_t grid_resolution = 0;
};

// One block of compressed transport columns as indexed in the TRNS section.
struct TransportBlockInfo {
  uint64_t first_column = 0;
  uint32_t column_count = 0;
  uint32_t codec = 0;   // 0 none, 1 zstd
  uint64_t offset = 0;  // absolute, in the file
  uint64_t stored_size = 0;
  uint64_t raw_size = 0;
  uint64_t checksum = 0;
};

// The TRNS section's global parameters and block index.
struct TransportIndex {
  uint32_t encoding = 0;   // the transport encoder's own format version
  uint64_t row_count = 0;  // rows of T: channels × spatial samples
  // Colour channels of T (1 or 3; 1 in every 1.0 pack): row c·V + v is colour channel c of
  // spatial sample v, V = row_count / channels. With 1, one row serves r, g and b.
  uint32_t channels = 1;
  uint64_t column_count = 0;
  std::vector<uint8_t> params;  // opaque global parameters
  std::vector<TransportBlockInfo> blocks;
};

class PackReader {
 public:
  // Opens a file by memory-mapping it (falls back to reading it). Validates the header, the
  // header checksum and the section table's structure; section payloads are checked when read.
  // Throws InputError(path, ...) on: unreadable file, bad magic, unsupported major version
  // ("unsupported .prtpack major version N"), truncation, trailing bytes, a table entry out of
  // range, misaligned or overlapping, an unknown critical section, wrong section multiplicity.
  // The mapping is private and read-only; the file must not be truncated while it is open.
  static PackReader OpenFile(const std::string& path, const ReaderOptions& options = {});
  // Same, over a copy of `size` bytes at `data` (`name` is used in messages).
  static PackReader OpenMemory(const void* data, std::size_t size,
                               const std::string& name = "<memory>",
                               const ReaderOptions& options = {});

  PackReader(PackReader&&) noexcept;
  PackReader& operator=(PackReader&&) noexcept;
  ~PackReader();

  const std::string& name() const;
  uint16_t version_major() const;
  uint16_t version_minor() const;
  uint64_t file_size() const;
  // Every section in table order, including unknown (skipped) ones.
  const std::vector<SectionInfo>& sections() const;
  std::size_t mesh_count() const;
  // True when the pack has a TRNS section (compressed columns). A CPCA pack has none.
  bool has_transport() const;
  // True when the pack has a CPCA section (1.3): a clustered-PCA transport instead of TRNS.
  bool has_cpca() const;
  // True when the pack has VISB sections (one per mesh: the reader refuses anything else).
  bool has_visibility() const;
  // True for an image-relighting pack (an IMGE section, 1.2): its rows are pixels, not vertices.
  bool has_image() const;
  // The IMGE section: the camera, image size and each pixel's mesh. Throws InputError when
  // there is none, on a checksum or zstd failure, or on content ParseImageSamples refuses (a
  // pixel naming a mesh the pack does not have included), or a pixel count that is not the
  // transport's (TRNS or CPCA) rows / channels.
  ImageSamplesInfo ReadImage() const;
  // True for a glossy vertex pack (a GLSY section, 1.6; docs/glossy-transport.md): its rows are
  // the vertices once per BRDF term.
  bool has_glossy() const;
  // The GLSY section's factor table (without f). Throws InputError when there is none, on a
  // checksum or zstd failure, on content ParseGlossyFactors refuses, on a mesh count that is not
  // the pack's, or when terms × the vertices is not the transport's (TRNS or CPCA) rows.
  GlossyFactorTable ReadGlossy() const;

  // The META section's JSON text. Verifies the section checksum and the decompressed size;
  // throws InputError if either fails or the text is not a JSON object.
  std::string ReadMetadata() const;
  // Mesh `i` (0 ≤ i < mesh_count()) decoded from its MESH section with its MATL material.
  // Throws InputError on an index out of range, a checksum mismatch, counts that disagree with
  // raw_size or exceed max_section_bytes, a Draco error, non-finite values or bad indices.
  UnpackedMesh ReadMesh(std::size_t i) const;
  // Mesh `i`'s material only (cheap). Same errors as ReadMesh for the MATL section.
  MeshMaterial ReadMaterial(std::size_t i) const;
  // The TRNS header, parameters and block index (validated: blocks contiguous in columns,
  // inside the section, aligned, non-overlapping; in a 1.1 pack a channel count of 1 or 3 that
  // divides the row count). Throws InputError if there is no TRNS section, its checksum fails or
  // the index is inconsistent.
  TransportIndex ReadTransportIndex() const;
  // Block `b`'s bytes, decompressed and bit-identical to what the writer was given. Verifies
  // only this block's own checksum (for streaming); throws InputError on an index out of range,
  // checksum mismatch, a zstd frame whose content size is missing or differs from raw_size, a
  // raw_size above max_section_bytes, or a decompression error.
  std::vector<uint8_t> ReadTransportBlock(const TransportIndex& index, std::size_t b) const;
  // Same, into caller memory of exactly block.raw_size bytes (`dst_size` must equal it).
  void ReadTransportBlockInto(const TransportIndex& index, std::size_t b, void* dst,
                              std::size_t dst_size) const;

  // The CPCA section's clustered-PCA transport, decoded and validated: the section checksum, a
  // zstd frame of exactly raw_size bytes (≤ max_section_bytes), the section's own header (sizes
  // that add up to raw_size), the compressed-transport header of scheme cpca (DecodeHeader) whose
  // rows, channels, clusters and bases equal the section's, and DecodeCpcaBody (safe on hostile
  // bytes: every count bounded by the bytes left before anything is allocated). Throws InputError
  // naming the pack and the section on any failure, or when the pack has no CPCA section.
  CpcaTransport ReadCpcaTransport() const;

  // Mesh `i`'s visibility maps (the VISB section with id i), decoded and validated: checksum,
  // zstd frame of exactly raw_size bytes, DecodeVisibilityBlocks (safe on hostile bytes), and
  // one map per vertex of the mesh (its Draco header's point count). Throws InputError naming
  // the pack and the section on any failure, or when the pack has no visibility.
  VisibilityBlocks ReadVisibility(std::size_t i) const;
  // Every mesh's maps concatenated in mesh order (the spatial-sample order); InputError also when
  // the meshes' n or bits differ.
  VisibilityBlocks ReadAllVisibility() const;

  // Checks every rule of docs/prtpack-format.md ("Verification"): every section checksum and
  // every section decoding. Throws InputError with the first failure's reason.
  void VerifyAll() const;

 private:
  struct Impl;
  explicit PackReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace prt::pack
