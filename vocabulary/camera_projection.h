// The pinhole camera of prt::Camera (vocabulary/scene.h): its orthonormal frame, the direction
// through a pixel and the projection of a point. Shared by the viewer's rasteriser, the farm's
// camera samples (image relighting, worker/camera_samples.h) and the viewer's image packs, so that
// a pixel means the same ray everywhere.
//
// Camera model: a pinhole at `eye` looking at `target`, `up` fixing the roll, vertical field of
// view `fov_deg`, square pixels. Pixel (x, y) counts from the top-left; its centre is
// (x + ½, y + ½) and looks along
//   d = forward + ((2(x + ½)/W − 1)·a·t)·right + ((1 − 2(y + ½)/H)·t)·up',  t = tan(fov/2), a =
//   W/H.
#pragma once

#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

// The camera's orthonormal frame and projection, shared by the rasteriser, the camera samples and
// tests.
class CameraProjection {
 public:
  // Throws std::invalid_argument for a degenerate camera (eye == target, up ∥ view, fov outside
  // (0, 180), non-positive size).
  explicit CameraProjection(const Camera& camera);

  const Vec3& eye() const { return eye_; }
  const Vec3& forward() const { return forward_; }
  const Vec3& right() const { return right_; }
  const Vec3& up() const { return up_; }
  int width() const { return width_; }
  int height() const { return height_; }
  // Unit direction through continuous pixel coordinates (px, py) (pixel centres at +½). Inline:
  // the rasteriser calls it for every background pixel.
  Vec3 PixelDirection(double px, double py) const {
    const double sx = (2.0 * px / width_ - 1.0) * aspect_ * tan_half_;
    const double sy = (1.0 - 2.0 * py / height_) * tan_half_;
    return Normalize(forward_ + sx * right_ + sy * up_);
  }
  // View-space coordinates (x right, y up, z forward) of a world point.
  Vec3 ToView(const Vec3& p) const;
  // Continuous pixel coordinates of a view-space point with z > 0.
  void ViewToPixel(const Vec3& v, double& px, double& py) const;

 private:
  Vec3 eye_, forward_, right_, up_;
  int width_, height_;
  double tan_half_, aspect_;
};

}  // namespace prt
