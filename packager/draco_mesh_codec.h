// Order-preserving Draco encoding of one triangle mesh for the MESH section of a .prtpack
// (docs/prtpack-format.md, "MESH"). Internal to packager/: Draco headers stay in the .cpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/mesh.h"

namespace prt::pack {

// A decoded mesh as flat float32/uint32 arrays: 3 floats per vertex, 3 indices per triangle.
struct MeshArrays {
  std::vector<float> positions;
  std::vector<float> normals;
  std::vector<uint32_t> triangles;
  std::size_t vertex_count() const { return positions.size() / 3; }
  std::size_t triangle_count() const { return triangles.size() / 3; }
};

// The counts a MESH payload declares in its Draco and sequential-connectivity headers.
struct DracoMeshCounts {
  uint32_t points = 0;
  uint32_t faces = 0;
};

// Decoded size a MESH section declares as raw_size: 24 bytes per vertex, 12 per triangle.
inline uint64_t MeshRawSize(uint64_t points, uint64_t faces) {
  return 24 * points + 12 * faces;
}

// Encodes `mesh` with Draco's sequential mesh encoder and no deduplication, so that point i of
// the decoded mesh is vertex i of `mesh` and face i is triangle i, corners in the same order.
// Positions are quantised to `position_bits` over the mesh's bounding box, normals to
// `normal_bits` (octahedral). Throws prt::InputError (naming `name`) on an empty mesh, normals
// missing, an index out of range, NaN/Inf, more than 2^31 vertices or a Draco failure.
std::vector<uint8_t> EncodeMeshDraco(const TriangleMesh& mesh, int position_bits, int normal_bits,
                                     const std::string& name);

// Parses only the Draco header and the sequential connectivity header (no allocation).
// Throws prt::InputError (naming `where`) unless the payload is a Draco 2.2 triangular mesh,
// sequentially encoded, without metadata.
DracoMeshCounts PeekDracoMeshCounts(const uint8_t* data, std::size_t size,
                                    const std::string& where);

// Decodes a MESH payload whose header counts the caller has already checked against its limits.
// Safe on untrusted input: throws prt::InputError (naming `where`) if Draco fails, the decoded
// counts differ from `expected`, an attribute is missing or malformed, an index is out of range
// or a value is not finite.
MeshArrays DecodeMeshDraco(const uint8_t* data, std::size_t size, const DracoMeshCounts& expected,
                           const std::string& where);

}  // namespace prt::pack
