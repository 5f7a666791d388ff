// Writer for .prtpack assets (docs/prtpack-format.md) from in-memory inputs: meshes, materials,
// the farm's metadata JSON and the compressed transport's column blocks or its clustered PCA.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "formats/cpca_transport.h"
#include "formats/glossy_factors.h"
#include "formats/image_file.h"
#include "vocabulary/mesh.h"
#include "vocabulary/scene_geometry.h"

namespace prt::pack {

struct PackMeshInput {
  std::string name;
  TriangleMesh mesh;  // positions and unit normals, one per vertex; vertex order is kept
  std::array<float, 3> albedo{0.8f, 0.8f, 0.8f};
  bool is_ground = false;
  uint32_t grid_resolution = 0;
};

// A scene's world-space meshes as pack meshes, in order (names, albedos, the ground's grid).
std::vector<PackMeshInput> PackMeshesOf(const SceneGeometry& geometry);

// One block of compressed transport columns: opaque bytes from the transport encoder, which
// must decode on their own. The packager zstd-compresses each block separately.
struct TransportBlockInput {
  uint32_t column_count = 0;
  std::vector<uint8_t> bytes;
};

struct TransportInput {
  uint32_t encoding = 0;   // the encoder's format version, stored as is
  uint64_t row_count = 0;  // rows of T: channels × spatial samples
  // Colour channels of T, 1 or 3: with 3, row c·V + v is colour channel c of spatial sample v
  // (V = row_count / 3), and the pack is written as version 1.1 (docs/prtpack-format.md, TRNS).
  uint32_t channels = 1;
  std::vector<uint8_t> params;  // opaque global parameters
  std::vector<TransportBlockInput> blocks;
};

// A section this version does not interpret (e.g. a later VISIBILITY), stored as given with
// codec none. Readers that do not know `type` skip it unless `flags` has bit 0 (CRITICAL).
struct ExtraSectionInput {
  std::string type;  // exactly 4 bytes, not META/MESH/MATL/TRNS
  uint32_t flags = 0;
  uint32_t id = 0;
  std::vector<uint8_t> bytes;
};

// Per-mesh visibility cubemaps for glossy triple-product relighting (the VISB sections,
// docs/prtpack-format.md): for mesh i, EncodeVisibilityBlocks (formats/visibility_blocks.h)
// of its vertices' maps in vertex order. The writer zstd-compresses each on its own.
struct VisibilityInput {
  std::vector<std::vector<uint8_t>> per_mesh;
};

struct PackInput {
  // A JSON object (scene, parameters, report ...); the writer adds "format", "writer" and a
  // per-mesh summary "meshes". Empty means {}.
  std::string metadata_json;
  std::vector<PackMeshInput> meshes;
  std::optional<TransportInput> transport;
  // A clustered-PCA transport (the CPCA section, 1.3; docs/cpca.md) instead of `transport`: a
  // pack has at most one of the two.
  std::optional<CpcaTransport> cpca;
  std::optional<VisibilityInput> visibility;      // one entry per mesh when present
  std::vector<ExtraSectionInput> extra_sections;  // written after the materials, before TRNS
  // Image relighting (the IMGE section, 1.2): the rows of T are this image's pixels in raster
  // order, each naming the mesh (material) it sees or background.
  std::optional<ImageSamplesInfo> image;
  // Glossy vertex transport (the GLSY section, 1.6; docs/glossy-transport.md): the factor table
  // whose terms the transport's rows hold (terms × vertices rows). Written without its f tables.
  std::optional<GlossyFactorTable> glossy;
};

struct WriterOptions {
  int position_bits = 16;  // Draco quantisation over each mesh's bounding box
  int normal_bits = 14;    // Draco octahedral quantisation
  int zstd_level = 19;
  uint32_t alignment = 64;  // section alignment: power of two, 64..65536 (4096 for page mmap)
};

// Builds the whole file in memory. Throws prt::InputError (naming the mesh or "metadata") on
// invalid inputs: metadata that is not a JSON object, no meshes, a mesh the codec rejects
// (see draco_mesh_codec.h), a transport block with no columns, visibility that does not decode,
// has not one entry per mesh, a map count other than the mesh's vertex count, or n/bits that
// differ between meshes,
// albedo outside [0, 1], bad options, a transport whose channels is not 1 or 3 or does not divide
// its row count, both a transport and a CPCA transport, a CPCA transport that does not validate
// (ValidateCpcaTransport), an image whose pixel count is not the transport's rows / channels.
std::vector<uint8_t> WritePack(const PackInput& input, const WriterOptions& options = {});
// The CPCA section's decoded payload (docs/prtpack-format.md, "CPCA"): the 32-byte header, the
// encoded CompressedTransportHeader and EncodeCpcaBody. Throws InputError if `t` does not validate.
std::vector<uint8_t> EncodeCpcaSection(const CpcaTransport& t);
// WritePack, then writes the bytes to `path` (via a temporary file renamed into place).
// Throws InputError(path, ...) if the file cannot be written.
void WritePackFile(const std::string& path, const PackInput& input,
                   const WriterOptions& options = {});

}  // namespace prt::pack
