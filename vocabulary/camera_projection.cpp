// CameraProjection (vocabulary/camera_projection.h).
#include "vocabulary/camera_projection.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace prt {

CameraProjection::CameraProjection(const Camera& camera)
    : eye_(camera.eye), width_(camera.width), height_(camera.height) {
  if (camera.width <= 0 || camera.height <= 0) {
    throw std::invalid_argument("Camera: non-positive image size");
  }
  if (!(camera.fov_deg > 0.0 && camera.fov_deg < 180.0)) {
    throw std::invalid_argument("Camera: vertical fov must lie in (0, 180) degrees");
  }
  forward_ = Normalize(camera.target - camera.eye);
  right_ = Normalize(Cross(forward_, camera.up));
  if (Length(forward_) == 0.0 || Length(right_) == 0.0 || !IsFinite(forward_) ||
      !IsFinite(right_)) {
    throw std::invalid_argument("Camera: eye equals target or up is parallel to the view");
  }
  up_ = Cross(right_, forward_);
  tan_half_ = std::tan(camera.fov_deg * std::numbers::pi / 360.0);
  aspect_ = static_cast<double>(width_) / height_;
}

Vec3 CameraProjection::ToView(const Vec3& p) const {
  const Vec3 d = p - eye_;
  return {Dot(d, right_), Dot(d, up_), Dot(d, forward_)};
}

void CameraProjection::ViewToPixel(const Vec3& v, double& px, double& py) const {
  px = (v.x / (v.z * aspect_ * tan_half_) + 1.0) * 0.5 * width_;
  py = (1.0 - v.y / (v.z * tan_half_)) * 0.5 * height_;
}

}  // namespace prt
