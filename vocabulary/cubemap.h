// Cubemap layout: the lighting vector L and every row of the transport matrix T are functions on
// 6·n·n cubemap texels. Face order and axes follow OpenEXR's envmap convention (ImfEnvmap.h):
// faces +X −X +Y −Y +Z −Z, +Y up. A texel is a small square area of its face (not a point):
// texel (face, x, y) covers face coordinates u ∈ [−1 + 2x/n, −1 + 2(x+1)/n] and likewise v with y,
// and its direction is, as in Imf::CubeMap::direction,
//   +X: ( 1, u, v)   −X: (−1, u, v)   +Y: (u,  1, v)   −Y: (u, −1, v)   +Z: (u, v,  1)   −Z: (u, v,
//   −1)
// Texel index = face·n² + y·n + x. See docs/conventions.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "vocabulary/vec3.h"

namespace prt {

enum class CubeFace : int { kPosX = 0, kNegX = 1, kPosY = 2, kNegY = 3, kPosZ = 4, kNegZ = 5 };

struct TexelCoord {
  int face = 0;
  int x = 0;
  int y = 0;
};

class CubemapLayout {
 public:
  // n must be a power of two in [1, 256]; throws std::invalid_argument otherwise.
  explicit CubemapLayout(int n);

  int n() const { return n_; }
  std::size_t texel_count() const { return static_cast<std::size_t>(6) * n_ * n_; }
  std::size_t face_size() const { return static_cast<std::size_t>(n_) * n_; }

  std::size_t Index(int face, int x, int y) const {
    return (static_cast<std::size_t>(face) * n_ + y) * n_ + x;
  }
  TexelCoord Coord(std::size_t index) const;

  // Unit direction through face coordinates (u, v) ∈ [−1, 1]² of a face.
  static Vec3 FaceDirection(int face, double u, double v);
  // Unnormalised point on the unit cube for (face, u, v).
  // Defined here so that per-ray loops (the transport sampler's directions) inline it.
  static Vec3 FacePoint(int face, double u, double v) {
    switch (face) {
      case 0:
        return {1, u, v};
      case 1:
        return {-1, u, v};
      case 2:
        return {u, 1, v};
      case 3:
        return {u, -1, v};
      case 4:
        return {u, v, 1};
      default:
        return {u, v, -1};
    }
  }
  // Face and face coordinates (u, v) ∈ [−1, 1]² hit by a direction (need not be normalised).
  static void DirectionToFace(const Vec3& d, int& face, double& u, double& v);

  // Unit direction through the centre of a texel.
  Vec3 TexelCenter(std::size_t index) const;
  // Unit direction through a point of a texel, (s, t) ∈ [0, 1]² across the texel.
  Vec3 TexelDirection(std::size_t index, double s, double t) const;
  // Index of the texel containing a direction.
  std::size_t TexelOf(const Vec3& d) const;

  // Exact solid angle of a texel (closed form of the projected square, double precision).
  double TexelSolidAngle(std::size_t index) const { return solid_angle_[index % face_size()]; }
  const std::vector<double>& FaceSolidAngles() const { return solid_angle_; }

  // True when some direction of the texel is strictly above the plane with normal nrm
  // (the texel meets the open upper hemisphere). Exact: the hemisphere cuts a face in a
  // half-plane, so it suffices to test the texel's four corners.
  bool TexelAboveHorizon(std::size_t index, const Vec3& nrm) const;

  // The same test for every texel at once (mask[j] = 1 above, 0 below), sharing each face's
  // (n+1)² corner dot products; writes texel_count() bytes and returns how many are above.
  // fully_above (optional, texel_count() bytes) marks texels whose four corners are all
  // strictly above, i.e. entirely in the upper hemisphere.
  std::size_t AboveHorizonMask(const Vec3& nrm, uint8_t* mask,
                               uint8_t* fully_above = nullptr) const;

  // Vector irradiance of each texel: Φ_j = ∫_texel ω dω (Arvo 1995: for a spherical polygon
  // with vertices v_i, Φ = ½ Σ_i θ_i · normalize(v_i × v_{i+1}), θ_i the arc length of edge i).
  // For a texel entirely above the plane with normal n, ∫_texel max(0, n·ω) dω = n·Φ_j exactly.
  const std::vector<Vec3>& TexelVectorIrradiance() const;

 private:
  int n_;
  std::vector<double> solid_angle_;      // one face; every face has the same texel solid angles
  std::vector<Vec3> vector_irradiance_;  // all faces
  // FacePoint of every texel corner, face by face, (n+1)² each: AboveHorizonMask's dot products
  // (one per corner and normal) without rebuilding the points for every sparse vertex.
  std::vector<Vec3> corners_;
};

// Solid angle subtended on the unit sphere by the face rectangle [u0,u1]×[v0,v1] at distance 1.
double FaceRectSolidAngle(double u0, double u1, double v0, double v1);

}  // namespace prt
