// Resampling an environment to the lighting vector L: a cubemap of 6·n·n texels holding the
// AVERAGE radiance over each texel (DESIGN.md, "Conventions"), integrated over each texel's solid
// angle (no point sampling, no aliasing of a small bright sun).
#pragma once

#include <array>
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

}  // namespace prt
