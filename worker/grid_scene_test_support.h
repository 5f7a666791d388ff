// Test support (worker tests only): small scenes of parallelogram grids, for tests that need
// closed-form geometry (a ground, a wall, a patch) rather than a mesh file.
#pragma once

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "vocabulary/scene.h"

namespace prt::grid_scenes {

// A res×res grid over the parallelogram corner + s·e1 + t·e2, every vertex with normal `normal`.
inline SceneMesh Grid(const std::string& name, Vec3 corner, Vec3 e1, Vec3 e2, Vec3 normal, int res,
                      Rgb albedo) {
  SceneMesh m;
  m.name = name;
  m.mesh.source = name;
  m.albedo = albedo;
  for (int j = 0; j < res; ++j)
    for (int i = 0; i < res; ++i) {
      m.mesh.positions.push_back(corner + e1 * (double(i) / (res - 1)) +
                                 e2 * (double(j) / (res - 1)));
      m.mesh.normals.push_back(Normalize(normal));
    }
  for (int j = 0; j + 1 < res; ++j)
    for (int i = 0; i + 1 < res; ++i) {
      const uint32_t a = j * res + i, b = a + 1, c = a + res, d = c + 1;
      m.mesh.triangles.push_back({a, b, d});
      m.mesh.triangles.push_back({a, d, c});
    }
  return m;
}

// The meshes as a scene's geometry, with its bounding box.
inline SceneGeometry Scene(std::vector<SceneMesh> meshes) {
  SceneGeometry g;
  g.meshes = std::move(meshes);
  g.bounds_min = {1e30, 1e30, 1e30};
  g.bounds_max = {-1e30, -1e30, -1e30};
  for (const SceneMesh& m : g.meshes)
    for (const Vec3& p : m.mesh.positions) {
      g.bounds_min = {std::min(g.bounds_min.x, p.x), std::min(g.bounds_min.y, p.y),
                      std::min(g.bounds_min.z, p.z)};
      g.bounds_max = {std::max(g.bounds_max.x, p.x), std::max(g.bounds_max.y, p.y),
                      std::max(g.bounds_max.z, p.z)};
    }
  return g;
}

}  // namespace prt::grid_scenes
