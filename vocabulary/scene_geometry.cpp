#include "vocabulary/scene_geometry.h"

namespace prt {

std::size_t SceneGeometry::vertex_count() const {
  std::size_t n = 0;
  for (const SceneMesh& m : meshes) n += m.mesh.positions.size();
  return n;
}

std::vector<uint64_t> SceneGeometry::MeshVertexCounts() const {
  std::vector<uint64_t> counts;
  for (const SceneMesh& m : meshes) counts.push_back(m.mesh.positions.size());
  return counts;
}

std::size_t SceneGeometry::MeshOfVertex(uint64_t vertex) const {
  std::size_t m = 0;
  for (uint64_t first = 0; m < meshes.size(); ++m) {
    first += meshes[m].mesh.positions.size();
    if (vertex < first) break;
  }
  return m;
}

}  // namespace prt
