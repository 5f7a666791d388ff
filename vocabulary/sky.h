// A procedural sky with a sun disc, for tests, demos and benchmarks.
#pragma once

#include <array>
#include <functional>

#include "vocabulary/envmap.h"

namespace prt {

struct SkySunParams {
  Vec3 sun_direction{0.3, 0.5, 0.8};   // need not be normalised
  double sun_angular_radius = 0.0232;  // radians (≈ 1.33°)
  std::array<float, 3> sun_radiance{5000.f, 4700.f, 4200.f};
  std::array<float, 3> zenith{0.15f, 0.3f, 0.8f};
  std::array<float, 3> horizon{0.8f, 0.85f, 0.9f};
  std::array<float, 3> ground{0.25f, 0.2f, 0.15f};
};
// Smooth sky radiance (zenith → horizon gradient above, ground below) without the sun.
std::array<float, 3> SkyRadiance(const SkySunParams& p, const Vec3& d);
// Lat-long (width × height) or cube (width × 6·width) image of sky plus sun disc. The sky is
// sampled at the pixel direction; the sun disc is box-filtered over the pixel cell with
// supersamples × supersamples samples, so its power is right even when it is under a pixel.
EnvironmentImage MakeSkyWithSun(EnvmapLayout layout, int width, int height,
                                const SkySunParams& params, int supersamples = 8);
// Samples f at each pixel's direction (OpenEXR mapping).
EnvironmentImage SampleEnvironment(EnvmapLayout layout, int width, int height,
                                   const std::function<std::array<float, 3>(const Vec3&)>& f);

}  // namespace prt
