// Software z-buffer rasteriser for relit meshes: per-vertex radiance is interpolated across each
// triangle with perspective-correct barycentrics, pixels not covered show the environment seen
// through the camera (optional) or black.
//
// Camera model: vocabulary/camera_projection.h (prt::Camera, a pinhole, pixel centres at +½).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "vocabulary/camera_projection.h"
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
