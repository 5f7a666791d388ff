// Environment maps: reading lat-long and cube EXRs and Radiance .hdr files, and resampling an
// environment to the lighting vector L, a cubemap of 6·n·n texels holding the AVERAGE radiance
// over each texel (DESIGN.md, "Conventions"). Directions follow OpenEXR's ImfEnvmap.h exactly;
// docs/conventions.md writes the mappings, the pixel cells and the units down.
//
// Readers are safe on untrusted input: every size is validated before it is used, truncated or
// corrupt files throw prt::InputError naming the file, NaN/Inf pixels throw InputError naming the
// file and the pixel (x, y, channel), and negative radiance is clamped to 0 and counted.
#pragma once

#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

enum class EnvmapLayout {
  kLatLong,  // OpenEXR ENVMAP_LATLONG: width × height, usually 2:1, top row = +Y (zenith)
  kCube,  // OpenEXR ENVMAP_CUBE: faces +X −X +Y −Y +Z −Z stacked vertically, width × 6·width
};

// An environment image in OpenEXR's envmap layout: planar linear float RGB, row-major from the
// top row, pixel (x, y) at index y·width + x. Radiance in the file's units (W·sr⁻¹·m⁻² or any
// consistent relative unit); prtfarm never rescales it.
struct EnvironmentImage {
  EnvmapLayout layout = EnvmapLayout::kLatLong;
  int width = 0;
  int height = 0;
  std::vector<float> r, g, b;

  std::size_t PixelCount() const { return static_cast<std::size_t>(width) * height; }
  std::size_t Index(int x, int y) const { return static_cast<std::size_t>(y) * width + x; }
  const std::vector<float>& Channel(int c) const { return c == 0 ? r : (c == 1 ? g : b); }
  std::vector<float>& Channel(int c) { return c == 0 ? r : (c == 1 ? g : b); }
  // Allocates width·height zero pixels.
  static EnvironmentImage Zero(EnvmapLayout layout, int width, int height);
};

// What a reader found besides the pixels.
struct EnvironmentLoadInfo {
  bool layout_from_attribute = false;  // false: inferred from the aspect ratio (logged)
  std::size_t negatives_clamped = 0;   // pixel channels < 0 set to 0 (logged as a warning)
  double most_negative = 0;            // the smallest value clamped (≤ 0)
};

// Reads an environment: OpenEXR (any compression, half or float, scanline or tiled; R, G, B
// channels, or Y alone as grey) or Radiance RGBE (.hdr/.pic, flat, old-RLE or new-RLE scanlines),
// chosen by the file's magic bytes. The layout comes from the EXR `envmap` attribute; without it
// (and always for .hdr) a 2:1 image is lat-long and a 1:6 image is a cube, and a log line says
// so; any other shape throws InputError. A lat-long map must be at least 2×2 (OpenEXR maps
// pixel 0 and pixel w−1 to the two ends of the longitude range); a cube map must be w × 6w.
EnvironmentImage ReadEnvironment(const std::string& path, EnvironmentLoadInfo* info = nullptr);
EnvironmentImage ReadEnvironmentExr(const std::string& path, EnvironmentLoadInfo* info = nullptr);
EnvironmentImage ReadRadianceHdr(const std::string& path, EnvironmentLoadInfo* info = nullptr);

// Writes float RGB OpenEXR (ZIP) with the `envmap` attribute set from image.layout.
// Throws InputError naming the file when it cannot be written.
void WriteEnvironmentExr(const EnvironmentImage& image, const std::string& path);
// Writes Radiance RGBE ("-Y h +X w"), new-RLE scanlines when rle and 8 ≤ width ≤ 32767, flat
// scanlines otherwise. RGBE keeps 8 bits of mantissa: values round-trip within 1/256 of the
// pixel's largest channel. Negative values are written as 0.
void WriteRadianceHdr(const EnvironmentImage& image, const std::string& path, bool rle = true);

// ---- Directions (OpenEXR ImfEnvmap.h, in double precision) ----

// Imf::LatLongMap::direction for a w × h map with data window (0,0)–(w−1,h−1): pixel position
// (px, py) → latitude θ = π(½ − py/(h−1)), longitude φ = −2π(px/(w−1) − ½),
// direction (sin φ cos θ, sin θ, cos φ cos θ). Unit length.
Vec3 LatLongDirection(int width, int height, double px, double py);
// Imf::LatLongMap::pixelPosition(dataWindow, direction): the inverse of LatLongDirection.
void LatLongPixelPosition(int width, int height, const Vec3& d, double& px, double& py);
// Imf::CubeMap: the direction (unnormalised point on the unit cube, as CubeMap::direction) of
// pixel (px, py) of a cube map image with faces of s × s pixels (image s × 6s).
Vec3 CubeImageDirection(int face_size, double px, double py);
// Imf::CubeMap::faceAndPixelPosition followed by CubeMap::pixelPosition: image pixel position.
void CubeImagePixelPosition(int face_size, const Vec3& d, double& px, double& py);

// Rotation of a direction by `angle` radians about +Y, right-handed (+Z turns towards +X): the
// longitude atan2(x, z) grows by angle. Rotating an environment by angle means L'(d) = L(R⁻¹d).
Vec3 RotateAboutY(const Vec3& d, double angle);

// Solid angle of the pixel's cell. OpenEXR's maps put pixel CENTRES on the poles and on both
// ends of the longitude range (and, for cubes, on the face edges), so a pixel's cell reaches half
// way to its neighbours and is clipped there: first/last rows and columns are half cells.
// The cells tile the sphere exactly (they sum to 4π).
double PixelSolidAngle(const EnvironmentImage& image, int x, int y);
// Σ radiance × cell solid angle over the image, per channel (double).
std::array<double, 3> EnvironmentPower(const EnvironmentImage& image);

// ---- The lighting vector ----

// Average radiance over each texel of a cubemap (vocabulary/cubemap.h layout: texel index =
// face·n² + y·n + x, OpenEXR face order), three planar channels of 6·n² floats.
struct CubemapRgb {
  int n = 0;
  std::vector<float> r, g, b;
  std::size_t TexelCount() const { return static_cast<std::size_t>(6) * n * n; }
  const std::vector<float>& Channel(int c) const { return c == 0 ? r : (c == 1 ? g : b); }
  std::vector<float>& Channel(int c) { return c == 0 ? r : (c == 1 ? g : b); }
};
// Σ texel average × exact texel solid angle, per channel (double).
std::array<double, 3> CubemapPower(const CubemapRgb& cube);

// Resamples an environment, rotated by rotation_y radians about +Y (see RotateAboutY), to an
// n×n-per-face cubemap by integrating over each texel's solid angle: every source pixel cell is
// split into leaves small against the target texel, each leaf carries its exact solid angle and
// is shared between the texels it overlaps (first-order exact overlap, see envmap.cpp), and each
// texel divides its accumulated radiance × solid angle by its accumulated solid angle. A constant
// map stays constant; a one-pixel sun keeps its power. n: power of two in [1, 256]
// (std::invalid_argument otherwise). A NaN/Inf pixel throws prt::NumericalError naming it.
// Parallel (TBB) and deterministic (independent of the thread count).
CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n, double rotation_y = 0.0);

// Diagnostic: the source solid angle credited to each texel by ResampleToCubemap's integration
// (6·n² values). Equals CubemapLayout::TexelSolidAngle up to the integration error, which bounds
// the relative power error of a small sun anywhere in that texel. Sums to 4π.
std::vector<double> ResampledTexelSolidAngles(const EnvironmentImage& env, int n,
                                              double rotation_y = 0.0);

// ---- Procedural environments for tests and demos ----

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
