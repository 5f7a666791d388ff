// The background of a relit frame: the environment image itself, at its own resolution, seen
// through the camera (docs/viewer.md, "Background"). The lighting cubemap L (6·n² texels, n = 32
// by default) is what the transport sees and is far too coarse to look at; the background shows
// the image L was resampled from, rotated exactly as the lighting is.
#pragma once

#include <memory>
#include <span>
#include <string>

#include "viewer/rasterizer.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene_geometry.h"
#include "vocabulary/vec3.h"

namespace prt {

// Radiance of an environment image along a direction, bilinearly interpolated between the pixel
// centres of OpenEXR's mappings (vocabulary/envmap.h, docs/conventions.md), weights and sum in
// double, the result rounded to float:
//  - lat-long: the four pixels around LatLongPixelPosition(d). Longitude is periodic: OpenEXR
//    puts column 0 and column w−1 on the same meridian (φ = +π and −π), so positions cover
//    [0, w−1] and the seam is interpolated between columns w−2 and w−1 (≡ 0) with no column
//    beyond. Latitude is clamped at the poles (rows 0 and h−1 are the poles themselves).
//  - cube: the four pixels around CubeImagePixelPosition(d) on the face that holds d; a face's
//    pixel centres reach its edges, so the interpolation never reads another face.
// At a pixel centre the lookup returns that pixel's value (the other weights are rounding
// residues, gone when the sum is rounded to float), between centres it is bilinear. Thread-safe.
class EnvironmentLookup {
 public:
  // Throws InputError naming `name` on an image whose shape is not a valid `layout` map
  // (ValidateEnvironmentShape) or whose channels do not hold width·height values, and
  // NumericalError naming `name` and the pixel on a NaN/Inf value (the readers of
  // environment_io.h already refuse those; an image made in memory may not).
  explicit EnvironmentLookup(EnvironmentImage image, const std::string& name = "environment");

  const EnvironmentImage& image() const { return image_; }
  // The unrotated image along `direction` (need not be normalised; the zero vector reads the
  // lat-long image at longitude 0 on the equator's row, or the cube's +X face centre).
  Rgb Radiance(const Vec3& direction) const;
  // Radiance(R(d)) for each d of `directions` into `out` (same size), R the rotation about +Y
  // whose cosine and sine are (cos_y, sin_y) ((1, 0): none): EnvironmentBackground's batch.
  // The lat-long mapping's two atan2 are evaluated four at a time (glibc's libmvec, AVX2) where
  // the CPU and the C library have them, else by std::atan2; libmvec's atan2 is within 4 ulp of
  // std::atan2, which moves a pixel position by ~10⁻¹³ pixels, so the results agree with
  // Radiance to within float rounding (test EnvironmentBackground.BatchAgreesWithRadiance). The
  // cube layout is Radiance per direction.
  void RadianceBatch(std::span<const Vec3> directions, double cos_y, double sin_y,
                     std::span<Rgb> out) const;

 private:
  Rgb Bilinear(double px, double py, int x_lo, int x_hi, int y_lo, int y_hi) const;
  EnvironmentImage image_;
};

// The background for an environment rotated by rotation_y radians about +Y: the direction d shows
// lookup(RotateAboutY(d, −rotation_y)), the radiance that ResampleToCubemap(env, n, rotation_y)
// (the lighting of that frame) integrates over the texel holding d. The function shares
// `lookup` (no copy of the image per frame). Throws std::invalid_argument on a null lookup or a
// non-finite rotation.
BackgroundFunction EnvironmentBackground(std::shared_ptr<const EnvironmentLookup> lookup,
                                         double rotation_y = 0.0);

}  // namespace prt
