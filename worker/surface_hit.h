// Where a ray lands on the scene's surfaces, in the terms the transport needs (no MPI here): the
// global vertices of the hit triangle with their barycentric weights, the mesh (its albedo), the
// interpolated shading normal, and which side was hit. Both interreflection estimators use it
// (worker/bounce_gather.h, worker/path_trace_reference.h; docs/interreflection.md).
//
// Sidedness (docs/interreflection.md, "Back faces"): every surface occludes from both sides, but
// only its front side, the side its vertex normals face, reflects light. A ray that reaches a
// back face (dot(ω, n_g) ≥ 0 with n_g the hit triangle's geometric normal turned to the side of
// its interpolated shading normal) is absorbed: it brings no bounce light. A closed mesh's back
// faces are inside it, where no light is; an open mesh (the ground) is lit on its front only.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "vocabulary/scene_geometry.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

namespace prt {

struct SurfaceHit {
  SpatialSample sample;                // the hit point, its shading and geometric normals
  uint32_t mesh = 0;                   // index into SceneGeometry::meshes
  std::array<uint64_t, 3> vertices{};  // global sample indices of the triangle's vertices
  std::array<double, 3> weights{};     // barycentric weights (1 − u − v, u, v), sum 1
  bool front = false;                  // the ray arrived on the reflecting side
  double max_edge = 0;                 // the hit triangle's longest edge
};

// The scene's surfaces for hit resolution; keeps a reference to the geometry, which must
// outlive it. Thread-safe after construction.
class SceneSurfaces {
 public:
  // `albedo` (optional, one per mesh): the reflectance a bounce ray sees at each mesh instead of
  // the mesh's albedo (an image run's glossy meshes, worker/glossy_pixels.h BounceAlbedo).
  explicit SceneSurfaces(const SceneGeometry& geometry, std::vector<Rgb> albedo = {});

  // Resolves Embree's closest hit `hit` of `ray` (EmbreeScene::Intersect). The shading normal is
  // the barycentric interpolation of the vertex normals (the geometric normal where they cancel).
  SurfaceHit Resolve(const OcclusionRay& ray, const RayHit& hit) const;
  // Traces `ray` to its closest hit in `scene` (built from this geometry) and resolves it:
  // kEscaped (nothing hit), kBackFace (absorbed) or kFront (`out` and `hit` hold the hit).
  enum class Outcome { kEscaped, kBackFace, kFront };
  Outcome Trace(const EmbreeScene& scene, const OcclusionRay& ray, RayHit& hit,
                SurfaceHit& out) const;
  // Global sample index of vertex `local` of mesh `mesh`.
  uint64_t GlobalVertex(uint32_t mesh, uint32_t local) const { return first_[mesh] + local; }
  const Rgb& albedo(uint32_t mesh) const {
    return albedo_.empty() ? geometry_.meshes[mesh].albedo : albedo_[mesh];
  }
  // The longest edge of the triangles around global vertex `vertex` (its tessellation's scale).
  double VertexEdge(uint64_t vertex) const { return vertex_edge_[vertex]; }
  const SceneGeometry& geometry() const { return geometry_; }

 private:
  const SceneGeometry& geometry_;
  std::vector<uint64_t> first_;  // first global sample index of each mesh
  std::vector<double> vertex_edge_;
  std::vector<Rgb> albedo_;  // empty: the meshes' albedos
};

// Whether a scene needs one transport row per colour channel once light bounces: some albedo
// is not grey.
bool HasColouredAlbedo(const SceneGeometry& geometry);

// An orthonormal frame around unit n: t, b with (t, b, n) right-handed (Duff et al. 2017,
// "Building an Orthonormal Basis, Revisited").
void OrthonormalFrame(const Vec3& n, Vec3& t, Vec3& b);

// Cosine-weighted direction about unit n from a point (u1, u2) of the unit square, by Shirley &
// Chiu's concentric map to the disk lifted to the hemisphere (pdf cos θ / π). Stratifying
// (u1, u2) stratifies the projected solid angle.
Vec3 CosineDirection(const Vec3& n, const Vec3& t, const Vec3& b, double u1, double u2);

}  // namespace prt
