// Geometry operations on triangle meshes: normals, signed volume, winding, topology (mesh.h).
#include "vocabulary/mesh.h"

#include <algorithm>
#include <bit>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string_view>
#include <unordered_map>

#include "vocabulary/errors.h"

namespace prt {

void ComputeAreaWeightedNormals(TriangleMesh& mesh) {
  std::vector<Vec3> sum(mesh.positions.size(), Vec3{});
  for (const auto& t : mesh.triangles) {
    const Vec3& p0 = mesh.positions[t[0]];
    const Vec3 c = Cross(mesh.positions[t[1]] - p0, mesh.positions[t[2]] - p0);
    for (uint32_t v : t) sum[v] += c;
  }
  mesh.normals.resize(mesh.positions.size());
  for (std::size_t v = 0; v < sum.size(); ++v) {
    const Vec3 n = Normalize(sum[v]);
    mesh.normals[v] = (n == Vec3{} || !IsFinite(n)) ? Vec3{0, 1, 0} : n;
  }
}

double SignedVolume(const TriangleMesh& mesh) {
  double volume = 0;
  for (const auto& t : mesh.triangles) {
    volume += Dot(mesh.positions[t[0]], Cross(mesh.positions[t[1]], mesh.positions[t[2]]));
  }
  return volume / 6.0;
}

void FlipWinding(TriangleMesh& mesh) {
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
  for (Vec3& n : mesh.normals) n = -n;
  mesh.report.signed_volume = -mesh.report.signed_volume;
  mesh.report.inward_wound = mesh.report.closed && mesh.report.signed_volume < 0;
}

void AnalyzeTopology(TriangleMesh& mesh) {
  // Directed edges bucketed by their first vertex (counting sort): an edge a→b is matched when
  // b's bucket holds b→a; a repeated directed edge means a non-manifold or inconsistently
  // oriented surface.
  const std::size_t nv = mesh.positions.size();
  std::vector<uint32_t> start(nv + 1, 0);
  for (const auto& t : mesh.triangles) {
    for (uint32_t v : t) ++start[v + 1];
  }
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  std::vector<uint32_t> fill(start.begin(), start.end() - 1);
  std::vector<uint32_t> target(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) target[fill[t[k]]++] = t[(k + 1) % 3];
  }
  bool manifold = true;
  std::size_t boundary = 0;
  for (std::size_t a = 0; a < nv; ++a) {
    for (uint32_t i = start[a]; i < start[a + 1]; ++i) {
      const uint32_t b = target[i];
      for (uint32_t j = i + 1; j < start[a + 1]; ++j) {
        if (target[j] == b) manifold = false;
      }
      bool matched = false;
      for (uint32_t j = start[b]; j < start[b + 1] && !matched; ++j) matched = target[j] == a;
      if (!matched) ++boundary;
    }
  }
  mesh.report.boundary_edges = boundary;
  mesh.report.closed = manifold && boundary == 0 && !mesh.triangles.empty();
  mesh.report.signed_volume = SignedVolume(mesh);
  mesh.report.inward_wound = mesh.report.closed && mesh.report.signed_volume < 0;
}

std::string DescribeImport(const TriangleMesh& mesh) {
  const MeshImportReport& r = mesh.report;
  std::ostringstream s;
  s << mesh.source << ": " << r.format << ", " << mesh.positions.size() << " vertices, "
    << mesh.triangles.size() << " triangles";
  if (r.welded_vertices) s << ", " << r.welded_vertices << " corners welded";
  if (r.polygons_triangulated) s << ", " << r.polygons_triangulated << " polygons fan-triangulated";
  if (r.degenerate_triangles_dropped) {
    s << ", " << r.degenerate_triangles_dropped << " degenerate faces dropped";
  }
  if (r.unreferenced_vertices) {
    s << ", " << r.unreferenced_vertices << " unreferenced vertices kept";
  }
  s << (r.normals_from_file ? ", normals from file" : ", area-weighted normals");
  if (r.normals_against_winding) {
    s << " (" << r.normals_against_winding << " point against the winding)";
  }
  s << (r.closed ? ", closed" : ", open (" + std::to_string(r.boundary_edges) + " boundary edges)");
  if (r.inward_wound) s << ", WOUND INWARD (signed volume " << r.signed_volume << ")";
  return s.str();
}

}  // namespace prt
