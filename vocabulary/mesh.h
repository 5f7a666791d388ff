// Triangle meshes as prtfarm's spatial samples: the order of vertices in the file is the order
// of spatial samples everywhere downstream (rows of T, packed assets, --radiance-out).
// See docs/mesh-import.md for how each format is read, how unreferenced vertices and STL
// welding are treated, and what counts as an error.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

struct MeshImportReport {
  std::size_t degenerate_triangles_dropped = 0;  // zero-area or repeated-index triangles
  std::size_t unreferenced_vertices = 0;         // kept (they are still spatial samples)
  std::size_t welded_vertices = 0;               // STL: corners merged into shared vertices
  bool normals_from_file = false;
  bool inward_wound = false;  // closed mesh with negative signed volume (reported, not changed)
  double signed_volume = 0;
};

struct TriangleMesh {
  std::string source;                          // file it came from (for messages)
  std::vector<Vec3> positions;                 // file order
  std::vector<Vec3> normals;                   // unit, one per position
  std::vector<std::array<uint32_t, 3>> triangles;
  MeshImportReport report;
};

// Reads PLY (ascii and binary), OBJ, OFF or STL (ascii and binary) by file extension.
// Vertex order is preserved; normals come from the file when present, else area-weighted.
// Throws prt::InputError naming the file and the problem on: missing/unreadable file, unknown
// format, empty mesh, NaN/Inf coordinates, out-of-range indices.
TriangleMesh LoadMesh(const std::string& path);

// Recomputes area-weighted vertex normals from the triangles (vertices without a triangle get +Y).
void ComputeAreaWeightedNormals(TriangleMesh& mesh);

// Signed volume of a (closed) mesh by the divergence theorem; negative means inward winding.
double SignedVolume(const TriangleMesh& mesh);

}  // namespace prt
