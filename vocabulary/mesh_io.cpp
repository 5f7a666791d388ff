// Mesh import: the format by extension, the strict readers (mesh_formats.h), the common checks.
//
// Strict, order-preserving readers for PLY, OBJ, OFF and STL (docs/mesh-import.md).
//
// Why not Assimp (libassimp 5.2.5, probed on the project's real meshes): its OBJ and STL
// importers emit one vertex per face corner (bunny_npm_lowres.obj: 11,022 vertices instead of
// 1,839); aiProcess_JoinIdenticalVertices then renumbers them in order of first use (vertex 0
// becomes the file's vertex 3) and, for STL, keeps corners with different facet normals apart
// (pig.stl: 33,890 instead of 8,642); its OFF importer silently replaces an out-of-range index
// and crashes on a truncated file. The order of vertices is the order of spatial samples
// downstream, so a reordering importer cannot be used, and these formats are small enough to
// read exactly.
//
// Safety on untrusted input: every declared count is checked against the bytes that are left
// before anything is reserved, every index against the vertex count, every number for NaN/Inf
// and float32 range; nothing is read past the end of the buffer.
#include "vocabulary/mesh_io.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "vocabulary/errors.h"
#include "vocabulary/mesh_formats.h"

namespace prt {

using namespace mesh_import;

namespace {

// ---------------------------------------------------------------------------------------------
// Common finishing: drop degenerate triangles, count unreferenced vertices, normals, topology.

TriangleMesh Finish(RawMesh raw, const std::string& name) {
  TriangleMesh mesh;
  mesh.source = name;
  mesh.report = raw.report;
  if (raw.positions.empty()) throw InputError(name, "empty mesh: no vertices");
  mesh.positions = std::move(raw.positions);
  mesh.triangles.reserve(raw.triangles.size());
  for (const auto& t : raw.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++mesh.report.degenerate_triangles_dropped;
      continue;
    }
    const Vec3 c = Cross(mesh.positions[t[1]] - mesh.positions[t[0]],
                         mesh.positions[t[2]] - mesh.positions[t[0]]);
    if (c == Vec3{0, 0, 0}) {
      ++mesh.report.degenerate_triangles_dropped;
      continue;
    }
    mesh.triangles.push_back(t);
  }
  if (mesh.triangles.empty()) {
    throw InputError(name, "empty mesh: no triangles (" + std::to_string(mesh.positions.size()) +
                               " vertices, " +
                               std::to_string(mesh.report.degenerate_triangles_dropped) +
                               " degenerate faces dropped)");
  }
  std::vector<bool> used(mesh.positions.size(), false);
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) used[v] = true;
  }
  mesh.report.unreferenced_vertices =
      static_cast<std::size_t>(std::count(used.begin(), used.end(), false));

  ComputeAreaWeightedNormals(mesh);
  if (!raw.file_normals.empty()) {
    mesh.report.normals_from_file = true;
    for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
      const Vec3 n = Normalize(raw.file_normals[v]);
      if (n == Vec3{}) continue;  // zero-length file normal: keep the area-weighted one
      if (used[v] && Dot(n, mesh.normals[v]) < 0) ++mesh.report.normals_against_winding;
      mesh.normals[v] = n;
    }
  }
  AnalyzeTopology(mesh);
  return mesh;
}

std::string LowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

}  // namespace

TriangleMesh ParseMesh(const std::string& bytes, const std::string& name) {
  const std::string ext = LowerExtension(name);
  RawMesh raw;
  if (ext == ".ply") {
    raw = ReadPly(bytes, name);
  } else if (ext == ".obj") {
    raw = ReadObj(bytes, name);
  } else if (ext == ".off") {
    raw = ReadOff(bytes, name);
  } else if (ext == ".stl") {
    raw = ReadStl(bytes, name);
  } else {
    throw InputError(
        name, "unknown mesh format '" + ext + "' (supported extensions: .ply, .obj, .off, .stl)");
  }
  return Finish(std::move(raw), name);
}

TriangleMesh LoadMesh(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path, "no such file");
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a directory");
  const std::string ext = LowerExtension(path);
  if (ext != ".ply" && ext != ".obj" && ext != ".off" && ext != ".stl") {
    throw InputError(
        path, "unknown mesh format '" + ext + "' (supported extensions: .ply, .obj, .off, .stl)");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "cannot open for reading");
  std::string bytes;
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw InputError(path, "cannot determine the file size");
  bytes.resize(static_cast<std::size_t>(size));
  in.seekg(0, std::ios::beg);
  in.read(bytes.data(), size);
  if (!in) throw InputError(path, "read error");
  return ParseMesh(bytes, path);
}

}  // namespace prt
