#include "worker/embree_scene.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"

#if defined(__SSE__) || defined(__x86_64__)
#include <pmmintrin.h>
#include <xmmintrin.h>
#define PRT_HAVE_MXCSR 1
#endif

namespace prt {

namespace {

// Collects Embree device errors; installed on the device before anything else happens.
struct ErrorLog {
  std::mutex mutex;
  std::string first;  // first message since the last check
};

void EmbreeErrorCallback(void* user, RTCError code, const char* message) {
  auto* log = static_cast<ErrorLog*>(user);
  const std::lock_guard<std::mutex> lock(log->mutex);
  if (log->first.empty()) {
    log->first = "Embree error " + std::to_string(static_cast<int>(code)) + ": " +
                 (message != nullptr ? message : "(no message)");
  }
}

std::string MeshLabel(const SceneMesh& m, std::size_t index) {
  if (!m.mesh.source.empty()) return m.mesh.source;
  if (!m.name.empty()) return m.name;
  return "mesh " + std::to_string(index);
}

}  // namespace

struct EmbreeScene::Impl {
  ErrorLog errors;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::size_t geometries = 0;
  std::size_t triangles = 0;
  Vec3 lo{0, 0, 0};
  Vec3 hi{0, 0, 0};
  double max_triangle_diameter = 0;

  // Throws when the callback recorded an error (or the device reports one).
  void Check(const char* what) {
    std::string message;
    {
      const std::lock_guard<std::mutex> lock(errors.mutex);
      message.swap(errors.first);
    }
    const RTCError code = rtcGetDeviceError(device);
    if (message.empty() && code != RTC_ERROR_NONE) {
      message = "Embree error " + std::to_string(static_cast<int>(code));
    }
    if (!message.empty())
      throw std::runtime_error(std::string("EmbreeScene: ") + what + ": " + message);
  }

  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

EmbreeScene::EmbreeScene(const SceneGeometry& geometry) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  // Validate before touching Embree: every error here is the user's input.
  bool any = false;
  for (std::size_t mi = 0; mi < geometry.meshes.size(); ++mi) {
    const TriangleMesh& mesh = geometry.meshes[mi].mesh;
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
      const Vec3& p = mesh.positions[i];
      if (!IsFinite(p) || std::abs(p.x) > FLT_MAX || std::abs(p.y) > FLT_MAX ||
          std::abs(p.z) > FLT_MAX) {
        throw InputError(MeshLabel(geometry.meshes[mi], mi),
                         "vertex " + std::to_string(i) + " is not a finite float coordinate");
      }
    }
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      for (uint32_t v : mesh.triangles[t]) {
        if (v >= mesh.positions.size()) {
          throw InputError(MeshLabel(geometry.meshes[mi], mi),
                           "triangle " + std::to_string(t) + " refers to vertex " +
                               std::to_string(v) + " of " + std::to_string(mesh.positions.size()));
        }
      }
    }
  }

  s.device = rtcNewDevice(nullptr);
  if (s.device == nullptr) {
    throw std::runtime_error("EmbreeScene: rtcNewDevice failed (Embree error " +
                             std::to_string(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
  }
  rtcSetDeviceErrorFunction(s.device, EmbreeErrorCallback, &s.errors);
  s.scene = rtcNewScene(s.device);
  rtcSetSceneFlags(s.scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(s.scene, RTC_BUILD_QUALITY_HIGH);
  s.Check("creating the scene");

  for (std::size_t mi = 0; mi < geometry.meshes.size(); ++mi) {
    const TriangleMesh& mesh = geometry.meshes[mi].mesh;
    if (mesh.triangles.empty() || mesh.positions.empty()) continue;
    RTCGeometry geom = rtcNewGeometry(s.device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
    auto* vertices = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                3 * sizeof(float), mesh.positions.size()));
    auto* indices = static_cast<uint32_t*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(uint32_t), mesh.triangles.size()));
    if (vertices == nullptr || indices == nullptr) {
      rtcReleaseGeometry(geom);
      s.Check("allocating geometry buffers");
      throw std::runtime_error("EmbreeScene: cannot allocate geometry buffers");
    }
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
      const Vec3& p = mesh.positions[i];
      vertices[3 * i + 0] = static_cast<float>(p.x);
      vertices[3 * i + 1] = static_cast<float>(p.y);
      vertices[3 * i + 2] = static_cast<float>(p.z);
      const Vec3 pf{vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
      if (!any) {
        s.lo = s.hi = pf;
        any = true;
      }
      s.lo = {std::min(s.lo.x, pf.x), std::min(s.lo.y, pf.y), std::min(s.lo.z, pf.z)};
      s.hi = {std::max(s.hi.x, pf.x), std::max(s.hi.y, pf.y), std::max(s.hi.z, pf.z)};
    }
    for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
      const auto& tri = mesh.triangles[t];
      Vec3 tlo = mesh.positions[tri[0]], thi = tlo;
      for (int k = 0; k < 3; ++k) {
        indices[3 * t + k] = tri[k];
        const Vec3& p = mesh.positions[tri[k]];
        tlo = {std::min(tlo.x, p.x), std::min(tlo.y, p.y), std::min(tlo.z, p.z)};
        thi = {std::max(thi.x, p.x), std::max(thi.y, p.y), std::max(thi.z, p.z)};
      }
      s.max_triangle_diameter = std::max(s.max_triangle_diameter, Length(thi - tlo));
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(s.scene, geom, static_cast<unsigned>(mi));
    rtcReleaseGeometry(geom);
    s.Check("adding a mesh");
    ++s.geometries;
    s.triangles += mesh.triangles.size();
  }
  rtcCommitScene(s.scene);
  s.Check("building the BVH");
}

EmbreeScene::~EmbreeScene() = default;

std::size_t EmbreeScene::geometry_count() const {
  return impl_->geometries;
}
std::size_t EmbreeScene::triangle_count() const {
  return impl_->triangles;
}
Vec3 EmbreeScene::bounds_min() const {
  return impl_->lo;
}
Vec3 EmbreeScene::bounds_max() const {
  return impl_->hi;
}
double EmbreeScene::extent() const {
  return Length(impl_->hi - impl_->lo);
}
double EmbreeScene::max_triangle_diameter() const {
  return impl_->max_triangle_diameter;
}

double EmbreeScene::RayOffset(const Vec3& p) const {
  const double m = std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)});
  const double scale = std::max(m, impl_->max_triangle_diameter);
  // FLT_MIN keeps the offset a normal float for a point at the origin of an empty scene.
  return std::max(kRayOffsetUlps * static_cast<double>(FLT_EPSILON) * scale,
                  static_cast<double>(FLT_MIN) * 1024.0);
}

void EmbreeScene::RobustOrigin(const Vec3& p, const Vec3& geometric_normal, float origin[3]) const {
  // The surface point as Embree stores it (float), then the offset in double, rounded once.
  const Vec3 pf{static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)};
  const Vec3 o = pf + geometric_normal * RayOffset(p);
  origin[0] = static_cast<float>(o.x);
  origin[1] = static_cast<float>(o.y);
  origin[2] = static_cast<float>(o.z);
}

namespace {
inline bool OccludedOne(RTCScene scene, const OcclusionRay& r) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay ray;
  ray.org_x = r.origin[0];
  ray.org_y = r.origin[1];
  ray.org_z = r.origin[2];
  ray.tnear = r.tnear;
  ray.dir_x = r.direction[0];
  ray.dir_y = r.direction[1];
  ray.dir_z = r.direction[2];
  ray.time = 0.0f;
  ray.tfar = r.tfar;
  ray.mask = std::numeric_limits<unsigned>::max();
  ray.id = 0;
  ray.flags = 0;
  rtcOccluded1(scene, &context, &ray);
  return ray.tfar < 0.0f;  // Embree sets tfar = −inf on a hit
}
}  // namespace

bool EmbreeScene::Occluded(const OcclusionRay& ray) const {
  return OccludedOne(impl_->scene, ray);
}

void EmbreeScene::OccludedPacket(std::span<const OcclusionRay> rays, bool* blocked) const {
  if (rays.size() > kPacket) {
    throw std::invalid_argument("EmbreeScene::OccludedPacket: " + std::to_string(rays.size()) +
                                " rays, at most " + std::to_string(kPacket));
  }
  if (rays.empty()) return;
  alignas(64) RTCRay16 packet;
  alignas(64) int valid[kPacket];
  for (std::size_t i = 0; i < kPacket; ++i) {
    // Lanes past the rays repeat the first one, masked off.
    const OcclusionRay& r = rays[i < rays.size() ? i : 0];
    valid[i] = i < rays.size() ? -1 : 0;
    packet.org_x[i] = r.origin[0];
    packet.org_y[i] = r.origin[1];
    packet.org_z[i] = r.origin[2];
    packet.tnear[i] = r.tnear;
    packet.dir_x[i] = r.direction[0];
    packet.dir_y[i] = r.direction[1];
    packet.dir_z[i] = r.direction[2];
    packet.time[i] = 0.0f;
    packet.tfar[i] = r.tfar;
    packet.mask[i] = std::numeric_limits<unsigned>::max();
    packet.id[i] = static_cast<unsigned>(i);
    packet.flags[i] = 0;
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcOccluded16(valid, impl_->scene, &context, &packet);
  for (std::size_t i = 0; i < rays.size(); ++i) blocked[i] = packet.tfar[i] < 0.0f;
}

bool EmbreeScene::Intersect(const OcclusionRay& r, RayHit& hit) const {
  const ScopedFlushDenormals ftz;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = r.origin[0];
  rh.ray.org_y = r.origin[1];
  rh.ray.org_z = r.origin[2];
  rh.ray.tnear = r.tnear;
  rh.ray.dir_x = r.direction[0];
  rh.ray.dir_y = r.direction[1];
  rh.ray.dir_z = r.direction[2];
  rh.ray.time = 0.0f;
  rh.ray.tfar = r.tfar;
  rh.ray.mask = std::numeric_limits<unsigned>::max();
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  hit.t = rh.ray.tfar;
  hit.geometry = rh.hit.geomID;
  hit.primitive = rh.hit.primID;
  hit.u = rh.hit.u;
  hit.v = rh.hit.v;
  hit.geometric_normal = Normalize(Vec3{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z});
  return true;
}

std::size_t EmbreeScene::CountOccluded(std::span<const OcclusionRay> rays) const {
  const ScopedFlushDenormals ftz;
  std::size_t hits = 0;
  for (const OcclusionRay& r : rays) hits += OccludedOne(impl_->scene, r) ? 1 : 0;
  return hits;
}

std::size_t EmbreeScene::CountOccludedInPackets(std::span<const OcclusionRay> rays) const {
  const ScopedFlushDenormals ftz;
  std::size_t hits = 0;
  bool blocked[kPacket];
  for (std::size_t i = 0; i < rays.size(); i += kPacket) {
    const std::size_t count = std::min(kPacket, rays.size() - i);
    OccludedPacket(rays.subspan(i, count), blocked);
    for (std::size_t j = 0; j < count; ++j) hits += blocked[j] ? 1 : 0;
  }
  return hits;
}

ScopedFlushDenormals::ScopedFlushDenormals() {
#ifdef PRT_HAVE_MXCSR
  saved_ = _mm_getcsr();
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
#endif
}

ScopedFlushDenormals::~ScopedFlushDenormals() {
#ifdef PRT_HAVE_MXCSR
  _mm_setcsr(saved_);
#endif
}

}  // namespace prt
