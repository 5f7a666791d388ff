#include "vocabulary/cubemap.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace prt {

namespace {
// Antiderivative of the solid angle over the face plane z = 1: ∫∫ (1+u²+v²)^(−3/2) du dv.
double SolidAngleCorner(double u, double v) {
  return std::atan2(u * v, std::sqrt(u * u + v * v + 1.0));
}
}  // namespace

double FaceRectSolidAngle(double u0, double u1, double v0, double v1) {
  return SolidAngleCorner(u1, v1) - SolidAngleCorner(u0, v1) - SolidAngleCorner(u1, v0) +
         SolidAngleCorner(u0, v0);
}

CubemapLayout::CubemapLayout(int n) : n_(n) {
  if (n < 1 || n > 256 || (n & (n - 1)) != 0) {
    throw std::invalid_argument("cubemap resolution must be a power of two in [1, 256], got " +
                                std::to_string(n));
  }
  solid_angle_.resize(face_size());
  const double h = 2.0 / n;
  for (int y = 0; y < n; ++y) {
    for (int x = 0; x < n; ++x) {
      solid_angle_[static_cast<std::size_t>(y) * n + x] =
          FaceRectSolidAngle(-1 + h * x, -1 + h * (x + 1), -1 + h * y, -1 + h * (y + 1));
    }
  }
  corners_.resize(static_cast<std::size_t>(6) * (n + 1) * (n + 1));
  for (int f = 0; f < 6; ++f)
    for (int y = 0; y <= n; ++y)
      for (int x = 0; x <= n; ++x)
        corners_[(static_cast<std::size_t>(f) * (n + 1) + y) * (n + 1) + x] =
            FacePoint(f, -1 + h * x, -1 + h * y);
  vector_irradiance_.resize(texel_count());
  for (int f = 0; f < 6; ++f) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const Vec3 c[4] = {FaceDirection(f, -1 + h * x, -1 + h * y),
                           FaceDirection(f, -1 + h * (x + 1), -1 + h * y),
                           FaceDirection(f, -1 + h * (x + 1), -1 + h * (y + 1)),
                           FaceDirection(f, -1 + h * x, -1 + h * (y + 1))};
        Vec3 phi;
        for (int e = 0; e < 4; ++e) {
          const Vec3& a = c[e];
          const Vec3& b = c[(e + 1) % 4];
          const Vec3 cr = Cross(a, b);
          const double theta = std::atan2(Length(cr), Dot(a, b));
          phi += Normalize(cr) * (0.5 * theta);
        }
        // Orient Φ towards the texel (the corner order above may wind either way per face).
        const Vec3 mid = FaceDirection(f, -1 + h * (x + 0.5), -1 + h * (y + 0.5));
        if (Dot(phi, mid) < 0) phi = -phi;
        vector_irradiance_[Index(f, x, y)] = phi;
      }
    }
  }
}

const std::vector<Vec3>& CubemapLayout::TexelVectorIrradiance() const {
  return vector_irradiance_;
}

std::size_t CubemapLayout::AboveHorizonMask(const Vec3& nrm, uint8_t* mask,
                                            uint8_t* fully_above) const {
  const int n = n_;
  const std::size_t corners = static_cast<std::size_t>(n + 1) * (n + 1);
  thread_local std::vector<double> dots;
  dots.resize(corners);
  std::size_t count = 0;
  for (int f = 0; f < 6; ++f) {
    const Vec3* p = corners_.data() + static_cast<std::size_t>(f) * corners;
    for (std::size_t i = 0; i < corners; ++i) dots[i] = Dot(p[i], nrm);
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const double* r0 = &dots[static_cast<std::size_t>(y) * (n + 1) + x];
        const double* r1 = r0 + (n + 1);
        // Bitwise, not short-circuit: the same answer without a branch per corner.
        const int a = (r0[0] > 0) + (r0[1] > 0) + (r1[0] > 0) + (r1[1] > 0);
        const std::size_t j = Index(f, x, y);
        mask[j] = a > 0 ? 1 : 0;
        count += a > 0;
        if (fully_above != nullptr) fully_above[j] = a == 4 ? 1 : 0;
      }
    }
  }
  return count;
}

TexelCoord CubemapLayout::Coord(std::size_t index) const {
  const std::size_t fs = face_size();
  TexelCoord c;
  c.face = static_cast<int>(index / fs);
  const std::size_t r = index % fs;
  c.y = static_cast<int>(r / n_);
  c.x = static_cast<int>(r % n_);
  return c;
}

Vec3 CubemapLayout::FaceDirection(int face, double u, double v) {
  return Normalize(FacePoint(face, u, v));
}

void CubemapLayout::DirectionToFace(const Vec3& d, int& face, double& u, double& v) {
  const double ax = std::abs(d.x), ay = std::abs(d.y), az = std::abs(d.z);
  if (ax >= ay && ax >= az) {
    if (ax == 0) {
      face = 0;
      u = v = 0;
      return;
    }
    face = d.x > 0 ? 0 : 1;
    u = d.y / ax;
    v = d.z / ax;
  } else if (ay >= az) {
    face = d.y > 0 ? 2 : 3;
    u = d.x / ay;
    v = d.z / ay;
  } else {
    face = d.z > 0 ? 4 : 5;
    u = d.x / az;
    v = d.y / az;
  }
}

Vec3 CubemapLayout::TexelDirection(std::size_t index, double s, double t) const {
  const TexelCoord c = Coord(index);
  const double h = 2.0 / n_;
  return FaceDirection(c.face, -1 + h * (c.x + s), -1 + h * (c.y + t));
}

Vec3 CubemapLayout::TexelCenter(std::size_t index) const {
  return TexelDirection(index, 0.5, 0.5);
}

std::size_t CubemapLayout::TexelOf(const Vec3& d) const {
  int face;
  double u, v;
  DirectionToFace(d, face, u, v);
  auto cell = [&](double w) {
    int i = static_cast<int>(std::floor((w + 1) * 0.5 * n_));
    return i < 0 ? 0 : (i >= n_ ? n_ - 1 : i);
  };
  return Index(face, cell(u), cell(v));
}

bool CubemapLayout::TexelAboveHorizon(std::size_t index, const Vec3& nrm) const {
  const TexelCoord c = Coord(index);
  const std::size_t side = static_cast<std::size_t>(n_) + 1;
  const Vec3* p = corners_.data() + (static_cast<std::size_t>(c.face) * side + c.y) * side + c.x;
  // The corners (x, y), (x+1, y), (x, y+1), (x+1, y+1): FacePoint's values, precomputed.
  return Dot(p[0], nrm) > 0 || Dot(p[1], nrm) > 0 || Dot(p[side], nrm) > 0 ||
         Dot(p[side + 1], nrm) > 0;
}

}  // namespace prt
