#include "vocabulary/scene_geometry.h"

namespace prt {

std::size_t SceneGeometry::vertex_count() const {
  std::size_t n = 0;
  for (const SceneMesh& m : meshes) n += m.mesh.positions.size();
  return n;
}

}  // namespace prt
