// Primary rays of image relighting (worker/camera_samples.h).
#include "worker/camera_samples.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <optional>
#include <stdexcept>

#include "vocabulary/camera_projection.h"
#include "vocabulary/errors.h"

namespace prt {

CameraSamples ComputeCameraSamples(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                                   const Camera& camera, const std::string& name) {
  if (!IsFinite(camera.eye) || !IsFinite(camera.target) || !IsFinite(camera.up))
    throw InputError(name, "the camera's eye, target and up must be finite");
  std::optional<CameraProjection> projection;
  try {
    projection.emplace(camera);
  } catch (const std::invalid_argument& e) {
    throw InputError(name, e.what());
  }
  const CameraProjection& cam = *projection;
  CameraSamples out;
  out.width = camera.width;
  out.height = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * camera.height;
  out.samples.resize(pixels);
  out.pixel_mesh.assign(pixels, kImageBackground);
  out.pixel_edge.assign(pixels, 0.0f);
  const double far = 100.0 * std::max(surfaces.geometry().diagonal(), 1.0);
  tbb::parallel_for(0, camera.height, [&](int y) {
    for (int x = 0; x < camera.width; ++x) {
      const std::size_t p = static_cast<std::size_t>(y) * camera.width + x;
      const Vec3 d = cam.PixelDirection(x + 0.5, y + 0.5);
      OcclusionRay ray;
      for (int i = 0; i < 3; ++i) {
        ray.origin[i] = static_cast<float>(camera.eye[i]);
        ray.direction[i] = static_cast<float>(d[i]);
      }
      ray.tnear = 0.0f;
      ray.tfar = std::numeric_limits<float>::infinity();
      RayHit hit;
      SurfaceHit s;
      const SceneSurfaces::Outcome o = surfaces.Trace(scene, ray, hit, s);
      SpatialSample& sample = out.samples[p];
      if (o == SceneSurfaces::Outcome::kEscaped) {
        sample.position = camera.eye + d * far;
        sample.normal = -d;
        sample.geometric_normal = -d;
        sample.background = true;
        continue;
      }
      sample = s.sample;
      if (o == SceneSurfaces::Outcome::kBackFace) {  // two-sided for the eye
        sample.normal = -sample.normal;
        sample.geometric_normal = -sample.geometric_normal;
      }
      out.pixel_mesh[p] = s.mesh;
      out.pixel_edge[p] = static_cast<float>(s.max_edge);
    }
  });
  return out;
}

}  // namespace prt
