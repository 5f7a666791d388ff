#include "worker/surface_hit.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace prt {

SceneSurfaces::SceneSurfaces(const SceneGeometry& geometry, std::vector<Rgb> albedo)
    : geometry_(geometry), albedo_(std::move(albedo)) {
  if (!albedo_.empty() && albedo_.size() != geometry.meshes.size())
    throw std::invalid_argument("SceneSurfaces: one albedo per mesh");
  uint64_t at = 0;
  first_.reserve(geometry.meshes.size());
  for (const SceneMesh& m : geometry.meshes) {
    first_.push_back(at);
    at += m.mesh.positions.size();
  }
  vertex_edge_.assign(at, 0.0);
  for (std::size_t mi = 0; mi < geometry.meshes.size(); ++mi) {
    const TriangleMesh& mesh = geometry.meshes[mi].mesh;
    for (const auto& t : mesh.triangles) {
      if (t[0] >= mesh.positions.size() || t[1] >= mesh.positions.size() ||
          t[2] >= mesh.positions.size())
        continue;  // EmbreeScene reports it
      for (int i = 0; i < 3; ++i) {
        const double e = Length(mesh.positions[t[(i + 1) % 3]] - mesh.positions[t[i]]);
        for (int k : {i, (i + 1) % 3}) {
          double& slot = vertex_edge_[first_[mi] + t[k]];
          slot = std::max(slot, e);
        }
      }
    }
  }
}

SurfaceHit SceneSurfaces::Resolve(const OcclusionRay& ray, const RayHit& hit) const {
  SurfaceHit h;
  h.mesh = hit.geometry;
  const TriangleMesh& mesh = geometry_.meshes.at(hit.geometry).mesh;
  const auto& tri = mesh.triangles.at(hit.primitive);
  const double u = hit.u, v = hit.v;
  h.weights = {1.0 - u - v, u, v};
  Vec3 ns{};
  Vec3 p{};
  for (int i = 0; i < 3; ++i) {
    h.vertices[i] = first_[hit.geometry] + tri[i];
    p += mesh.positions[tri[i]] * h.weights[i];
    if (tri[i] < mesh.normals.size()) ns += mesh.normals[tri[i]] * h.weights[i];
  }
  for (int i = 0; i < 3; ++i)
    h.max_edge =
        std::max(h.max_edge, Length(mesh.positions[tri[(i + 1) % 3]] - mesh.positions[tri[i]]));
  Vec3 ng = hit.geometric_normal;
  const double ln = Length(ns);
  ns = std::isfinite(ln) && ln > 1e-12 ? ns / ln : ng;
  if (Dot(ng, ns) < 0) ng = -ng;
  const Vec3 d{ray.direction[0], ray.direction[1], ray.direction[2]};
  h.front = Dot(d, ng) < 0;
  h.sample.position = p;
  h.sample.normal = ns;
  h.sample.geometric_normal = ng;
  return h;
}

SceneSurfaces::Outcome SceneSurfaces::Trace(const EmbreeScene& scene, const OcclusionRay& ray,
                                            RayHit& hit, SurfaceHit& out) const {
  if (!scene.Intersect(ray, hit)) return Outcome::kEscaped;
  out = Resolve(ray, hit);
  return out.front ? Outcome::kFront : Outcome::kBackFace;
}

bool HasColouredAlbedo(const SceneGeometry& geometry) {
  for (const SceneMesh& m : geometry.meshes)
    if (m.albedo[0] != m.albedo[1] || m.albedo[1] != m.albedo[2]) return true;
  return false;
}

void OrthonormalFrame(const Vec3& n, Vec3& t, Vec3& b) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double c = n.x * n.y * a;
  t = Vec3{1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x};
  b = Vec3{c, sign + n.y * n.y * a, -n.y};
}

Vec3 CosineDirection(const Vec3& n, const Vec3& t, const Vec3& b, double u1, double u2) {
  const double a = 2 * u1 - 1, c = 2 * u2 - 1;
  double r = 0, phi = 0;
  if (a != 0 || c != 0) {
    if (std::abs(a) > std::abs(c)) {
      r = a;
      phi = (std::numbers::pi / 4) * (c / a);
    } else {
      r = c;
      phi = std::numbers::pi / 2 - (std::numbers::pi / 4) * (a / c);
    }
  }
  const double x = r * std::cos(phi), y = r * std::sin(phi);
  const double z = std::sqrt(std::max(0.0, 1.0 - x * x - y * y));
  return t * x + b * y + n * z;
}

}  // namespace prt
