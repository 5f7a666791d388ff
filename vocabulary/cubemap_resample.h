// Resampling an environment to the lighting vector L: a cubemap of 6·n·n texels holding the
// AVERAGE radiance over each texel (DESIGN.md, "Conventions"), integrated over each texel's solid
// angle (no point sampling, no aliasing of a small bright sun).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "vocabulary/envmap.h"

namespace prt {

// Resamples an environment, rotated by rotation_y radians about +Y (see RotateAboutY), to an
// n×n-per-face cubemap by integrating over each texel's solid angle: every source pixel cell is
// split into leaves small against the target texel, each leaf carries its exact solid angle and
// is shared between the texels it overlaps (first-order exact overlap, see envmap.cpp), and each
// texel divides its accumulated radiance × solid angle by its accumulated solid angle. A constant
// map stays constant; a one-pixel sun keeps its power. n: power of two in [1, 256]
// (std::invalid_argument otherwise). A NaN/Inf pixel throws prt::NumericalError naming it.
// Parallel (vocabulary/parallel.h) and deterministic (independent of the thread count).
CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n, double rotation_y = 0.0);
// The same under a general rotation (row-major 3×3, orthonormal): the map's direction d lights
// from rotation·d, each leaf of the integration rotated as a whole (its point and both edges).
// A rotation about +Y gives ResampleToCubemap(env, n, angle) to rounding.
CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n,
                             const std::array<double, 9>& rotation);

// Diagnostic: the source solid angle credited to each texel by ResampleToCubemap's integration
// (6·n² values). Equals CubemapLayout::TexelSolidAngle up to the integration error, which bounds
// the relative power error of a small sun anywhere in that texel. Sums to 4π.
std::vector<double> ResampledTexelSolidAngles(const EnvironmentImage& env, int n,
                                              double rotation_y = 0.0);

// Fast resampling under rotations about +Y, for interaction (a preview while the user drags:
// runtime/prt_runtime.cpp, prt_runtime_set_preview). The map is first averaged onto a periodic
// lat-long grid of width × width/2 uniform cells (each the exact mean of the map over it, so the
// power is kept; column x spans longitude [π − (x + 1)·2π/width, π − x·2π/width]), whose sparse
// cell → texel weights at rotation 0 are integrated once as ResampleToCubemap integrates a
// pixel. A rotation about +Y by a whole number of cells is the same weights applied to the
// grid's columns shifted cyclically (the grid is periodic, unlike a lat-long map's repeated
// seam column); between whole cells the two neighbouring shifts are blended linearly. A frame is
// one pass over the weights (a few per cell) instead of the leaf integration. Construction
// throws std::invalid_argument for a map that is not lat-long, a width that is not even in
// [4, 65536] or a bad n; the map must be finite (ResampleToCubemap's check is the caller's).
class PeriodicLatLongResampler {
 public:
  // One share of a cell's solid angle in a texel (construction only).
  struct Weight {
    uint32_t texel, cell;
    double omega;
  };
  PeriodicLatLongResampler(const EnvironmentImage& env, int n, int width);
  // The cubemap of texel averages under a rotation of rotation_y radians about +Y (the sense of
  // ResampleToCubemap's); std::invalid_argument if it is not finite.
  CubemapRgb Resample(double rotation_y) const;
  int width() const { return w_; }
  std::size_t weight_count() const { return entries_.size(); }
  std::size_t memory_bytes() const;

 private:
  struct Entry {
    uint32_t row;  // y · width
    uint32_t x;
    float omega;
  };
  int n_, w_, h_;
  std::vector<float> grid_;  // 3 floats per cell, row-major
  std::vector<Entry> entries_;
  std::vector<uint32_t> texel_begin_;  // texel t's entries: [begin[t], begin[t + 1])
  std::vector<double> texel_omega_;    // Σ ω per texel
};

}  // namespace prt
