// The world-space geometry of a scene: its meshes with their materials, the ground grid last,
// and the bounds. What BuildSceneGeometry (scene.h) makes of a scene description and what
// geometry.prtg (formats/geometry_file.h) stores; every stage after setup works from it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vocabulary/mesh.h"
#include "vocabulary/vec3.h"

namespace prt {

// Linear RGB (albedo, radiance), channel order r, g, b.
using Rgb = std::array<float, 3>;

// One world-space mesh of the scene with its material.
struct SceneMesh {
  std::string name;
  TriangleMesh mesh;  // world space; normals unit
  Rgb albedo{0.8f, 0.8f, 0.8f};
  bool is_ground = false;
  int grid_resolution = 0;  // ground only: grid vertices per side
};

struct SceneGeometry {
  std::vector<SceneMesh> meshes;  // scene meshes in file order, ground plane last
  Vec3 bounds_min{0, 0, 0};
  Vec3 bounds_max{0, 0, 0};
  std::size_t vertex_count() const;
  // Each mesh's vertex count, in order (the spatial samples of each mesh, scene.h's order).
  std::vector<uint64_t> MeshVertexCounts() const;
  // The mesh holding global vertex (spatial sample) `vertex`; meshes.size() beyond the last.
  std::size_t MeshOfVertex(uint64_t vertex) const;
  double diagonal() const { return Length(bounds_max - bounds_min); }
};

}  // namespace prt
