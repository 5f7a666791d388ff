// Reading meshes from files: PLY, OBJ, OFF and STL, order-preserving and strict
// (docs/mesh-import.md). The types are mesh.h's.
#pragma once

#include <string>

#include "vocabulary/mesh.h"

namespace prt {

// Reads PLY (ascii, binary little and big endian), OBJ, OFF or STL (ascii and binary), chosen by
// the file extension (case-insensitive). Vertex order is preserved (STL: welded in order of first
// appearance); polygons are fan-triangulated; degenerate triangles are dropped and counted;
// normals come from the file when present (PLY nx ny nz, OFF NOFF, OBJ vn when consistent per
// position), else area-weighted. Throws prt::InputError naming the file and the line (text) or
// element (binary) on: missing/unreadable file, unknown extension or format, truncated file,
// NaN/Inf numbers, out-of-range indices, empty mesh (no vertices or no triangles).
TriangleMesh LoadMesh(const std::string& path);

// Same, from bytes already in memory; `name` (a file name) picks the format by extension and
// names the source in error messages.
TriangleMesh ParseMesh(const std::string& bytes, const std::string& name);

}  // namespace prt
