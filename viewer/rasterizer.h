// Software z-buffer rasteriser for relit meshes: per-vertex radiance is interpolated across each
// triangle with perspective-correct barycentrics, pixels not covered show the environment seen
// through the camera (optional) or black.
//
// Camera model (prt::Camera, vocabulary/scene.h): a pinhole at `eye` looking at `target`, `up`
// fixing the roll, vertical field of view `fov_deg`, square pixels. Pixel (x, y) counts from the
// top-left; its centre is (x + ½, y + ½) and looks along
//   d = forward + ((2(x + ½)/W − 1)·a·t)·right + ((1 − 2(y + ½)/H)·t)·up',  t = tan(fov/2), a =
//   W/H.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "vocabulary/cubemap.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"

namespace prt {

struct RasterImage {
  int width = 0;
  int height = 0;
  std::vector<float> rgb;         // width·height·3, row-major from the top-left
  std::vector<float> depth;       // distance along the view axis; +inf where nothing was drawn
  std::vector<int32_t> triangle;  // index of the visible triangle, −1 for background
};

// Radiance seen along a unit world direction (for the background).
using BackgroundFunction = std::function<Rgb(const Vec3& direction)>;

struct RasterOptions {
  double near = 1e-3;             // near clipping distance along the view axis
  BackgroundFunction background;  // empty: black
};

// The camera's orthonormal frame and projection, shared by the rasteriser and by tests.
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
  // Unit direction through continuous pixel coordinates (px, py) (pixel centres at +½).
  Vec3 PixelDirection(double px, double py) const;
  // View-space coordinates (x right, y up, z forward) of a world point.
  Vec3 ToView(const Vec3& p) const;
  // Continuous pixel coordinates of a view-space point with z > 0.
  void ViewToPixel(const Vec3& v, double& px, double& py) const;

 private:
  Vec3 eye_, forward_, right_, up_;
  int width_, height_;
  double tan_half_, aspect_;
};

// Rasterises triangles with per-vertex colours (3 floats per position, interleaved). Triangles
// are two-sided and clipped against the near plane; coverage follows the top-left rule, so a
// pixel centre on an edge shared by two triangles is drawn once. Parallel over row bands (TBB).
// Throws std::invalid_argument on a colour array of the wrong size or an out-of-range index,
// NumericalError on a NaN/Inf vertex colour or background value (naming the vertex or pixel):
// no pixel is blacked out silently.
RasterImage RasterizeTriangles(const Camera& camera, std::span<const Vec3> positions,
                               std::span<const std::array<uint32_t, 3>> triangles,
                               std::span<const float> vertex_rgb,
                               const RasterOptions& options = {});

// Background lookup into a lighting cubemap (average radiance per texel), nearest texel; the
// returned function keeps its own copy. Throws std::invalid_argument on inconsistent sizes,
// NumericalError on a NaN/Inf texel. prt-view shows the environment image instead
// (environment_background.h); this is for callers that have only the cubemap.
BackgroundFunction CubemapBackground(const CubemapRgb& cube);

}  // namespace prt
