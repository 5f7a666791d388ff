// Triangle meshes as prtfarm's spatial samples: the order of vertices in the file is the order
// of spatial samples everywhere downstream (rows of T, packed assets, --radiance-out).
// See docs/mesh-import.md for how each format is read, how unreferenced vertices and STL
// welding are treated, and what counts as an error.
//
// The readers are prtfarm's own small strict parsers (not Assimp: it reorders OBJ/STL vertices,
// silently accepts out-of-range indices and crashes on truncated files; docs/mesh-import.md).
// They are meant to be safe on untrusted input: every count is checked against the bytes that
// are left, every index against the vertex count, every number for NaN/Inf.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

struct MeshImportReport {
  std::string format;                     // "ply-ascii", "ply-binary-le", "obj", "stl-binary"…
  std::size_t file_vertices = 0;          // vertices as written (STL: triangle corners)
  std::size_t file_faces = 0;             // faces/polygons as written
  std::size_t polygons_triangulated = 0;  // faces with > 3 corners, fan-triangulated
  std::size_t degenerate_triangles_dropped = 0;  // zero-area or repeated-index triangles
  std::size_t unreferenced_vertices = 0;         // kept (they are still spatial samples)
  std::size_t welded_vertices = 0;               // STL: corners merged into shared vertices
  bool normals_from_file = false;
  // File normals pointing against the winding (dot with the area-weighted normal < 0).
  std::size_t normals_against_winding = 0;
  bool closed = false;             // every edge used once in each direction (watertight, oriented)
  std::size_t boundary_edges = 0;  // directed edges without their reverse
  bool inward_wound = false;  // closed mesh with negative signed volume (reported, not changed)
  double signed_volume = 0;
};

struct TriangleMesh {
  std::string source;           // file it came from (for messages)
  std::vector<Vec3> positions;  // file order
  std::vector<Vec3> normals;    // unit, one per position
  std::vector<std::array<uint32_t, 3>> triangles;
  MeshImportReport report;
};

// Recomputes area-weighted vertex normals from the triangles: n_v = normalize(Σ (p1−p0)×(p2−p0))
// over the triangles using v (each term is twice the triangle's area times its unit normal).
// Vertices without a triangle (or whose sum vanishes) get +Y.
void ComputeAreaWeightedNormals(TriangleMesh& mesh);

// Signed volume of a (closed) mesh by the divergence theorem, Σ p0·(p1×p2)/6; negative means
// inward winding. Only meaningful for closed meshes (report.closed).
double SignedVolume(const TriangleMesh& mesh);

// Reverses every triangle's winding and negates the normals (scene key flip_winding).
void FlipWinding(TriangleMesh& mesh);

// Fills report.closed, boundary_edges, signed_volume and inward_wound from the triangles.
void AnalyzeTopology(TriangleMesh& mesh);

// One line summarising the import report (for logs).
std::string DescribeImport(const TriangleMesh& mesh);

}  // namespace prt
