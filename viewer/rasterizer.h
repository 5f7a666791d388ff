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
#include <type_traits>
#include <utility>
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

// Radiance seen along unit world directions (for the background): a function of one direction
// and, optionally, the same function over a run of directions at once, which the rasteriser
// calls with the rays of the uncovered pixels of a tile row (EnvironmentBackground's evaluates
// four atan2 at a time). Without a batch function, the batch call applies the one-direction
// function to each direction. Converts from any callable Rgb(const Vec3&), so a lambda is a
// background; default-constructed or from nullptr it is empty (a black background).
class BackgroundFunction {
 public:
  using One = std::function<Rgb(const Vec3& direction)>;
  // Writes out[i] for directions[i], i < directions.size() (== out.size()).
  using Batch = std::function<void(std::span<const Vec3> directions, std::span<Rgb> out)>;

  BackgroundFunction() = default;
  BackgroundFunction(std::nullptr_t) {}  // NOLINT: as std::function
  template <typename F>
  requires(!std::is_same_v<std::decay_t<F>, BackgroundFunction> &&
           !std::is_same_v<std::decay_t<F>, std::nullptr_t> && std::is_constructible_v<One, F>)
      BackgroundFunction(F&& one)
      : one_(std::forward<F>(one)) {}  // NOLINT: implicit, as a lambda
  // `batch` must give what `one` gives for each direction (up to the rounding of its own
  // arithmetic, which its maker documents); an empty `one` makes an empty background.
  BackgroundFunction(One one, Batch batch) : one_(std::move(one)), batch_(std::move(batch)) {
    if (!one_) batch_ = nullptr;
  }

  explicit operator bool() const { return static_cast<bool>(one_); }
  Rgb operator()(const Vec3& direction) const { return one_(direction); }
  void operator()(std::span<const Vec3> directions, std::span<Rgb> out) const {
    if (batch_) {
      batch_(directions, out);
      return;
    }
    for (std::size_t i = 0; i < directions.size(); ++i) out[i] = one_(directions[i]);
  }

 private:
  One one_;
  Batch batch_;
};

struct RasterOptions {
  double near = 1e-3;             // near clipping distance along the view axis
  BackgroundFunction background;  // empty: black
  // Draw one pixel at a time even where the CPU has AVX2 (the result is the same bit for bit;
  // for tests and benchmarks).
  bool scalar = false;
};

// Rasterises triangles with per-vertex colours (3 floats per position, interleaved). Triangles
// are two-sided and clipped against the near plane; coverage follows the top-left rule, so a
// pixel centre on an edge shared by two triangles is drawn once. Parallel over 64×32-pixel tiles
// (TBB); the result does not depend on the thread count or on AVX2 (bitwise: docs/viewer.md,
// "Rasteriser"). The calling thread keeps the working arrays (~8 MB for 83k triangles) for its
// next call. Throws std::invalid_argument on a colour array of the wrong size, an out-of-range
// index or 2³¹ or more vertices or triangles, NumericalError on a NaN/Inf vertex colour or
// background value (naming the vertex, or the first such pixel in row-major order): no pixel is
// blacked out silently.
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
