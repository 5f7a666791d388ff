// The one small layer between prtfarm and Embree 3: scene building from a prt::SceneGeometry,
// the device error callback, robust ray origins and the occlusion query. Only
// worker/embree_scene.cpp includes Embree headers (Embree 4 changes the ray-query signatures;
// keeping them in one file keeps that port small). See docs/transport-sampling.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// One occlusion query in Embree's float layout: hit anything with t in (tnear, tfar)?
struct OcclusionRay {
  float origin[3];
  float tnear;
  float direction[3];  // unit
  float tfar;
};

// The closest hit of a ray (EmbreeScene::Intersect).
struct RayHit {
  float t = 0;
  uint32_t geometry = 0;   // mesh index in the SceneGeometry
  uint32_t primitive = 0;  // triangle index in that mesh
  float u = 0, v = 0;      // barycentrics of vertices 1 and 2 (Embree's convention)
  Vec3 geometric_normal;   // unit, (v1−v0)×(v2−v0) direction (Embree's Ng, normalised)
};

// Robust ray origins (Wächter & Binder, "A Fast and Robust Method for Avoiding
// Self-Intersection", Ray Tracing Gems ch. 6, adapted): the origin is moved off the surface along
// the geometric normal by kRayOffsetUlps float epsilons of the point's float scale
//   δ = kRayOffsetUlps · FLT_EPSILON · max(‖p‖∞, ℓ),
// where ℓ is the largest triangle diameter of the scene (≤ the scene's extent). Every rounding
// error of Embree's ray/triangle test against a triangle passing within δ of p is a few ulps of
// max(‖p‖∞, ℓ), so the offset origin lies strictly outside the surface; tnear stays 0 (a positive
// tnear would only hide real occluders next to the origin, i.e. leak light through thin walls).
inline constexpr double kRayOffsetUlps = 16.0;

class EmbreeScene {
 public:
  // Builds the scene once: one Embree triangle geometry per SceneMesh (geometry id = mesh index),
  // RTC_SCENE_FLAG_ROBUST, build quality high. Throws prt::InputError (naming the mesh source) on
  // non-finite vertices or out-of-range indices, std::runtime_error on an Embree device error.
  explicit EmbreeScene(const SceneGeometry& geometry);
  ~EmbreeScene();
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  std::size_t geometry_count() const;
  std::size_t triangle_count() const;
  // Axis-aligned bounds of all vertices (zero when empty) and its diagonal.
  Vec3 bounds_min() const;
  Vec3 bounds_max() const;
  double extent() const;
  // Largest triangle bounding-box diagonal ℓ, the scene part of the offset scale.
  double max_triangle_diameter() const;

  // Offset distance δ for a ray leaving the surface at p (see kRayOffsetUlps).
  double RayOffset(const Vec3& p) const;
  // The robust origin fl(fl(p) + δ·geometric_normal) for rays leaving the surface at p on the
  // side of the unit geometric normal; writes three floats.
  void RobustOrigin(const Vec3& p, const Vec3& geometric_normal, float origin[3]) const;

  // True when the ray hits any triangle with t in (tnear, tfar). Thread-safe.
  bool Occluded(const OcclusionRay& ray) const;
  // Occluded() for each of up to kPacket rays at once (blocked[i] for rays[i]), traced as one
  // Embree packet: rays from one point in neighbouring directions share most of their traversal
  // (2.3× the throughput of one rtcOccluded1 call per ray on the demo's rays,
  // bench/transport_bench.cpp). Throws std::invalid_argument on more than kPacket rays.
  // Thread-safe; the caller sets flush-to-zero (ScopedFlushDenormals) as for Occluded().
  static constexpr std::size_t kPacket = 16;
  void OccludedPacket(std::span<const OcclusionRay> rays, bool* blocked) const;
  // Closest hit with t in (tnear, tfar), for primary rays (e.g. camera-pixel samples); false
  // when the ray hits nothing. Thread-safe.
  bool Intersect(const OcclusionRay& ray, RayHit& hit) const;
  // A bare rtcOccluded1 loop over the rays (the raw-throughput reference of
  // bench/transport_bench.cpp); returns how many are occluded.
  std::size_t CountOccluded(std::span<const OcclusionRay> rays) const;
  // The same rays kPacket at a time through OccludedPacket (bench/transport_bench.cpp).
  std::size_t CountOccludedInPackets(std::span<const OcclusionRay> rays) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Sets flush-to-zero and denormals-are-zero on the calling thread (as Embree asks of every
// tracing thread) for the lifetime of the object, and restores the previous mode afterwards.
class ScopedFlushDenormals {
 public:
  ScopedFlushDenormals();
  ~ScopedFlushDenormals();
  ScopedFlushDenormals(const ScopedFlushDenormals&) = delete;
  ScopedFlushDenormals& operator=(const ScopedFlushDenormals&) = delete;

 private:
  unsigned saved_ = 0;
};

}  // namespace prt
