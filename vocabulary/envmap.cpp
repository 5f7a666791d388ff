#include "vocabulary/envmap.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "vocabulary/cubemap.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"

namespace prt {

namespace {

constexpr double kPi = std::numbers::pi;
// Largest image a reader accepts (pixels): 2^28 ≈ 16k × 16k, 3 GiB of float RGB.
constexpr std::int64_t kMaxPixels = std::int64_t{1} << 28;

// ---- Shape validation and layout inference ----

void ValidateShape(const std::string& path, EnvmapLayout layout, std::int64_t w, std::int64_t h) {
  if (w <= 0 || h <= 0 || w > (1 << 20) || h > (1 << 20) || w * h > kMaxPixels) {
    throw InputError(path, "image size " + std::to_string(w) + "x" + std::to_string(h) +
                               " is empty or too large");
  }
  if (layout == EnvmapLayout::kLatLong && (w < 2 || h < 2)) {
    throw InputError(path, "a lat-long map needs at least 2x2 pixels, got " + std::to_string(w) +
                               "x" + std::to_string(h));
  }
  if (layout == EnvmapLayout::kCube && h != 6 * w) {
    throw InputError(path, "a cube map must be w x 6w (faces +X -X +Y -Y +Z -Z stacked), got " +
                               std::to_string(w) + "x" + std::to_string(h));
  }
}

EnvmapLayout InferLayout(const std::string& path, std::int64_t w, std::int64_t h) {
  if (w == 2 * h) {
    spdlog::info("{}: no envmap attribute; {}x{} (2:1) taken as a lat-long map", path, w, h);
    return EnvmapLayout::kLatLong;
  }
  if (h == 6 * w) {
    spdlog::info("{}: no envmap attribute; {}x{} (1:6) taken as a cube map", path, w, h);
    return EnvmapLayout::kCube;
  }
  throw InputError(path, "no envmap attribute and the shape " + std::to_string(w) + "x" +
                             std::to_string(h) + " is neither 2:1 (lat-long) nor 1:6 (cube)");
}

// NaN/Inf are rejected with the pixel named; negatives are clamped to 0 and counted.
void CheckAndClamp(const std::string& path, EnvironmentImage& img, EnvironmentLoadInfo& info) {
  static const char* kNames[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& ch = img.Channel(c);
    for (std::size_t i = 0; i < ch.size(); ++i) {
      const float v = ch[i];
      if (!std::isfinite(v)) {
        const int x = static_cast<int>(i % static_cast<std::size_t>(img.width));
        const int y = static_cast<int>(i / static_cast<std::size_t>(img.width));
        throw InputError(path, std::string(std::isnan(v) ? "NaN" : "Inf") +
                                   " at pixel (x=" + std::to_string(x) +
                                   ", y=" + std::to_string(y) + ", channel " + kNames[c] + ")");
      }
      if (v < 0) {
        info.most_negative = std::min(info.most_negative, static_cast<double>(v));
        ++info.negatives_clamped;
        ch[i] = 0;
      }
    }
  }
  if (info.negatives_clamped > 0) {
    spdlog::warn("{}: clamped {} negative pixel values to 0 (most negative {})", path,
                 info.negatives_clamped, info.most_negative);
  }
}

// ---- Pixel cells ----
// OpenEXR places pixel centres on the poles, on both ends of the longitude range and on cube
// face edges. A pixel's cell reaches half way to its neighbours, clipped at those ends; see
// docs/conventions.md.

struct Interval {
  double lo, hi;
};

// Latitude interval of lat-long row y (θ grows upwards; row 0 is the north pole).
Interval LatLongRowCell(int h, int y) {
  const double d = kPi / (h - 1);
  const double c = kPi * (0.5 - static_cast<double>(y) / (h - 1));
  return {std::max(-kPi / 2, c - d / 2), std::min(kPi / 2, c + d / 2)};
}
// Longitude interval of lat-long column x (φ decreases with x from π to −π).
Interval LatLongColumnCell(int w, int x) {
  const double d = 2 * kPi / (w - 1);
  const double c = kPi - 2 * kPi * static_cast<double>(x) / (w - 1);
  return {std::max(-kPi, c - d / 2), std::min(kPi, c + d / 2)};
}

// Cube image pixel → face and integer position in face (Imf::CubeMap::pixelPosition inverted).
void CubePixelToFace(int s, int px, int py, int& face, int& pifx, int& pify) {
  face = py / s;
  const int ly = py - face * s;  // row inside the face's block
  switch (face) {
    case 0:
      pifx = s - 1 - ly;
      pify = px;
      break;
    case 1:
      pifx = s - 1 - ly;
      pify = s - 1 - px;
      break;
    case 2:
      pifx = px;
      pify = s - 1 - ly;
      break;
    case 3:
      pifx = px;
      pify = ly;
      break;
    case 4:
      pifx = s - 1 - px;
      pify = s - 1 - ly;
      break;
    default:
      pifx = px;
      pify = s - 1 - ly;
      break;
  }
}
// Face-coordinate interval (u or v ∈ [−1, 1]) of integer position i on a face of s pixels.
Interval CubeCell(int s, int i) {
  if (s == 1) return {-1.0, 1.0};
  const double k = 2.0 / (s - 1);
  return {std::max(-1.0, -1 + k * (i - 0.5)), std::min(1.0, -1 + k * (i + 0.5))};
}

// ---- Resampling accumulator ----

// Gnomonic frame of a cube face: p = FacePoint(face, u, v) has p[major] = ±1, p[iu] = u,
// p[iv] = v (vocabulary/cubemap.h, Imf::CubeMap::direction).
constexpr int kMajor[6] = {0, 0, 1, 1, 2, 2};
constexpr int kAxisU[6] = {1, 1, 0, 0, 0, 0};
constexpr int kAxisV[6] = {2, 2, 2, 2, 1, 1};

// CDF of X = s·p + t·q with s, t uniform on [−½, ½] and p ≥ q ≥ 0 (a trapezoid): the
// distribution of a face coordinate over a small parallelogram.
double TrapezoidCdf(double x, double p, double q) {
  if (p < q) std::swap(p, q);
  if (p <= 0) return x >= 0 ? 1.0 : 0.0;
  if (q <= 1e-9 * p) return std::clamp(x / p + 0.5, 0.0, 1.0);
  const double a = 0.5 * (p + q), b = 0.5 * (p - q);
  auto r = [](double z) { return z > 0 ? 0.5 * z * z : 0.0; };
  return std::clamp((r(x + a) - r(x + b) - r(x - b) + r(x - a)) / (p * q), 0.0, 1.0);
}

// First moment ∫_{−∞}^{x} t·pdf(t) dt of the same trapezoid distribution.
double TrapezoidMoment(double x, double p, double q) {
  if (p < q) std::swap(p, q);
  if (p <= 0) return 0.0;
  if (q <= 1e-9 * p) {
    const double z = std::clamp(x, -0.5 * p, 0.5 * p);
    return (z * z - 0.25 * p * p) / (2 * p);
  }
  const double a = 0.5 * (p + q), b = 0.5 * (p - q);
  // ∫_{−∞}^{x} t·(t + c)₊ dt = z³/3 − c·z²/2 with z = (x + c)₊.
  auto m = [&](double c) {
    const double z = std::max(0.0, x + c);
    return z * z * z / 3 - c * z * z / 2;
  };
  return (m(a) - m(b) - m(-b) + m(-a)) / (p * q);
}

class TexelAccumulator {
 public:
  explicit TexelAccumulator(const CubemapLayout& layout)
      : layout_(layout), n_(layout.n()), acc_(4 * layout.texel_count(), 0.0) {}

  const std::vector<double>& data() const { return acc_; }

  // One leaf of a source pixel cell: centre p (any length, nonzero), edge vectors ta, tb (the
  // derivative of p along the leaf's two parameters times the leaf's extent in them), exact
  // solid angle omega and radiance rgb. The leaf is taken as the parallelogram p ± ta/2 ± tb/2
  // in the gnomonic coordinates of the face holding p; its solid angle is split between texel
  // columns (and rows) in proportion to the parallelogram's area on each side of the grid lines
  // (exact for a parallelogram crossing one line; second-order accurate in the leaf size).
  //
  // With split_extent > 0, a leaf that straddles a grid line and spans more than split_extent
  // in face coordinates is not added; AddLeaf returns false and the caller splits it in four.
  bool AddLeaf(const Vec3& p, const Vec3& ta, const Vec3& tb, double omega, const float* rgb,
               double split_extent) {
    // Face as CubemapLayout::DirectionToFace (largest |component|, ties to x then y), with one
    // division.
    const double ax = std::abs(p.x), ay = std::abs(p.y), az = std::abs(p.z);
    const int face = (ax >= ay && ax >= az) ? (p.x > 0 ? 0 : 1)
                     : (ay >= az)           ? (p.y > 0 ? 2 : 3)
                                            : (p.z > 0 ? 4 : 5);
    const int m = kMajor[face], iu = kAxisU[face], iv = kAxisV[face];
    const double inv = 1.0 / std::abs(p[m]);
    const double sm = (face & 1) ? -1.0 : 1.0;
    const double u = p[iu] * inv, v = p[iv] * inv;
    // d(p_i / |p_m|) = (t_i − u·sign·t_m) / |p_m|
    const double ua = (ta[iu] - u * sm * ta[m]) * inv, ub = (tb[iu] - u * sm * tb[m]) * inv;
    const double va = (ta[iv] - v * sm * ta[m]) * inv, vb = (tb[iv] - v * sm * tb[m]) * inv;
    const double pu = std::abs(ua), qu = std::abs(ub), pv = std::abs(va), qv = std::abs(vb);
    const double eu = 0.5 * (pu + qu), ev = 0.5 * (pv + qv);
    const double half = 0.5 * n_;
    const int c0 = static_cast<int>(std::floor((u - eu + 1) * half));
    const int c1 = static_cast<int>(std::floor((u + eu + 1) * half));
    const int r0 = static_cast<int>(std::floor((v - ev + 1) * half));
    const int r1 = static_cast<int>(std::floor((v + ev + 1) * half));
    if (c0 == c1 && r0 == r1) {
      Add(layout_.Index(face, std::clamp(c0, 0, n_ - 1), std::clamp(r0, 0, n_ - 1)), omega, rgb);
      return true;
    }
    if (split_extent > 0 && 2 * std::max(eu, ev) > split_extent) return false;
    // Split along each axis; a leaf crossing a face edge hands the part beyond it to the
    // neighbouring face through a representative direction (the cube grid lines continue
    // across face edges).
    constexpr int kMaxBins = 8;
    double fu[kMaxBins], fv[kMaxBins], mu[kMaxBins], mv[kMaxBins];
    // The solid angle density on the face plane, (1 + u² + v²)^(−3/2), is taken as linear
    // across the leaf: gradient of its logarithm.
    const double r2 = 1 + u * u + v * v;
    const int nu = Split(u, eu, pu, qu, -3 * u / r2, c0, c1, fu, mu, kMaxBins);
    const int nv = Split(v, ev, pv, qv, -3 * v / r2, r0, r1, fv, mv, kMaxBins);
    for (int i = 0; i < nu; ++i) {
      for (int j = 0; j < nv; ++j) {
        const double f = fu[i] * fv[j];
        if (f <= 0) continue;
        Add(layout_.TexelOf(CubemapLayout::FacePoint(face, mu[i], mv[j])), omega * f, rgb);
      }
    }
    return true;
  }

 private:
  void Add(std::size_t t, double omega, const float* rgb) {
    double* a = &acc_[4 * t];
    a[0] += omega * rgb[0];
    a[1] += omega * rgb[1];
    a[2] += omega * rgb[2];
    a[3] += omega;
  }

  // Fractions of the trapezoid distribution of a coordinate (centre c, half extent e), weighted
  // by the linear density 1 + g·(x − c), falling in grid cells k0..k1, with a representative
  // coordinate inside each part. Normalised to sum 1.
  int Split(double c, double e, double p, double q, double g, int k0, int k1, double* frac,
            double* mid, int max_bins) const {
    if (k1 - k0 + 1 > max_bins) {  // leaves are far smaller than texels; never happens
      frac[0] = 1;
      mid[0] = c;
      return 1;
    }
    double sum = 0, prev_cdf = 0, lo = c - e;
    int count = 0;
    for (int k = k0; k <= k1; ++k) {
      const double hi = k == k1 ? c + e : -1 + 2.0 * (k + 1) / n_;
      const double cdf =
          k == k1 ? 1.0 : TrapezoidCdf(hi - c, p, q) + g * TrapezoidMoment(hi - c, p, q);
      frac[count] = std::max(0.0, cdf - prev_cdf);
      mid[count] = 0.5 * (lo + hi);
      sum += frac[count];
      prev_cdf = cdf;
      lo = hi;
      ++count;
    }
    if (sum > 0) {
      for (int i = 0; i < count; ++i) frac[i] /= sum;
    }
    return count;
  }

  const CubemapLayout& layout_;
  int n_;
  std::vector<double> acc_;  // per texel: Σ ω·R, Σ ω·G, Σ ω·B, Σ ω
};

// Leaves per smallest texel edge: 1 keeps the parallelogram model of a leaf within one texel's
// extent, which is all AddLeaf needs (it splits a leaf between any number of texels); the
// resampling tests bound the resulting solid-angle error per texel.
constexpr double kLeavesPerTexel = 1.0;

// A leaf straddling a texel boundary is split until it spans at most 1/kSplitRatio of a texel
// in face coordinates (or kMaxSplitDepth halvings). The parallelogram model's error (mainly the
// curvature of the leaf's edges in face coordinates, largest near the poles of a lat-long map
// and near cube corners) is second order in the leaf size: measured worst per-texel error of the
// credited solid angle 2.8% at ratio 2, 0.5% at 4, 0.2% at 6, 0.13% at 8 (1024×512 → n = 32,
// 64; 256×128 → 32; 64×32 → 16; cube 128 → 32 rotated).
constexpr double kSplitRatio = 6.0;
constexpr int kMaxSplitDepth = 5;

// Lat-long leaf φ ∈ [f0, f1] (rotation included), θ ∈ [t0, t1], split in four and added.
void RefineLatLongLeaf(TexelAccumulator& a, double f0, double f1, double t0, double t1,
                       const float* rgb, int depth, double split) {
  const double fm = 0.5 * (f0 + f1), tm = 0.5 * (t0 + t1);
  const double quads[4][4] = {
      {f0, fm, t0, tm}, {fm, f1, t0, tm}, {f0, fm, tm, t1}, {fm, f1, tm, t1}};
  for (const auto& q : quads) {
    const double fc = 0.5 * (q[0] + q[1]), tc = 0.5 * (q[2] + q[3]);
    const double sf = std::sin(fc), cf = std::cos(fc), st = std::sin(tc), ct = std::cos(tc);
    const double dw = q[1] - q[0], dh = q[3] - q[2];
    const Vec3 p{sf * ct, st, cf * ct};
    const Vec3 ta{cf * ct * dw, 0, -sf * ct * dw};
    const Vec3 tb{-sf * st * dh, ct * dh, -cf * st * dh};
    const double omega = dw * (std::sin(q[3]) - std::sin(q[2]));
    if (!a.AddLeaf(p, ta, tb, omega, rgb, depth < kMaxSplitDepth ? split : 0)) {
      RefineLatLongLeaf(a, q[0], q[1], q[2], q[3], rgb, depth + 1, split);
    }
  }
}

// Cube leaf [u0, u1] × [v0, v1] of a source face, rotated by rot about +Y, split in four.
void RefineCubeLeaf(TexelAccumulator& a, int face, double u0, double u1, double v0, double v1,
                    double rot, const float* rgb, int depth, double split) {
  const double um = 0.5 * (u0 + u1), vm = 0.5 * (v0 + v1);
  const double quads[4][4] = {
      {u0, um, v0, vm}, {um, u1, v0, vm}, {u0, um, vm, v1}, {um, u1, vm, v1}};
  const Vec3 p00 = CubemapLayout::FacePoint(face, 0, 0);
  const Vec3 eu = CubemapLayout::FacePoint(face, 1, 0) - p00;
  const Vec3 ev = CubemapLayout::FacePoint(face, 0, 1) - p00;
  for (const auto& q : quads) {
    const Vec3 p =
        RotateAboutY(CubemapLayout::FacePoint(face, 0.5 * (q[0] + q[1]), 0.5 * (q[2] + q[3])), rot);
    const Vec3 ta = RotateAboutY(eu * (q[1] - q[0]), rot);
    const Vec3 tb = RotateAboutY(ev * (q[3] - q[2]), rot);
    const double omega = FaceRectSolidAngle(q[0], q[1], q[2], q[3]);
    if (!a.AddLeaf(p, ta, tb, omega, rgb, depth < kMaxSplitDepth ? split : 0)) {
      RefineCubeLeaf(a, face, q[0], q[1], q[2], q[3], rot, rgb, depth + 1, split);
    }
  }
}

// Smallest angular edge length of a texel of an n-cubemap (at a cube corner): 2/n · √2/3.
double MinTexelAngle(int n) {
  return 2.0 / n * std::sqrt(2.0) / 3.0;
}

}  // namespace

EnvironmentImage EnvironmentImage::Zero(EnvmapLayout layout, int width, int height) {
  EnvironmentImage img;
  img.layout = layout;
  img.width = width;
  img.height = height;
  for (int c = 0; c < 3; ++c) img.Channel(c).assign(img.PixelCount(), 0.0f);
  return img;
}

// ---- Directions ----

Vec3 LatLongDirection(int width, int height, double px, double py) {
  const double lat = height > 1 ? -kPi * (py / (height - 1) - 0.5) : 0.0;
  const double lon = width > 1 ? -2 * kPi * (px / (width - 1) - 0.5) : 0.0;
  return {std::sin(lon) * std::cos(lat), std::sin(lat), std::cos(lon) * std::cos(lat)};
}

void LatLongPixelPosition(int width, int height, const Vec3& d, double& px, double& py) {
  const double r = std::sqrt(d.z * d.z + d.x * d.x);
  const double lat = std::atan2(d.y, r);
  const double lon = (d.z == 0 && d.x == 0) ? 0.0 : std::atan2(d.x, d.z);
  px = (lon / (-2 * kPi) + 0.5) * (width - 1);
  py = (lat / -kPi + 0.5) * (height - 1);
}

Vec3 CubeImageDirection(int face_size, double px, double py) {
  const int s = face_size;
  const int face = std::clamp(static_cast<int>(std::floor(py / s)), 0, 5);
  const double ly = py - face * s, m = s - 1;
  double x = 0, y = 0;
  switch (face) {
    case 0:
      x = m - ly;
      y = px;
      break;
    case 1:
      x = m - ly;
      y = m - px;
      break;
    case 2:
      x = px;
      y = m - ly;
      break;
    case 3:
      x = px;
      y = ly;
      break;
    case 4:
      x = m - px;
      y = m - ly;
      break;
    default:
      x = px;
      y = m - ly;
      break;
  }
  const double u = s > 1 ? x / m * 2 - 1 : 0.0, v = s > 1 ? y / m * 2 - 1 : 0.0;
  return CubemapLayout::FacePoint(face, u, v);
}

void CubeImagePixelPosition(int face_size, const Vec3& d, double& px, double& py) {
  const int s = face_size;
  int face;
  double u, v;
  CubemapLayout::DirectionToFace(d, face, u, v);
  const double m = s - 1, x = (u + 1) / 2 * m, y = (v + 1) / 2 * m;
  const double y0 = face * s, y1 = face * s + m;
  switch (face) {
    case 0:
      px = y;
      py = y1 - x;
      break;
    case 1:
      px = m - y;
      py = y1 - x;
      break;
    case 2:
      px = x;
      py = y1 - y;
      break;
    case 3:
      px = x;
      py = y0 + y;
      break;
    case 4:
      px = m - x;
      py = y1 - y;
      break;
    default:
      px = x;
      py = y1 - y;
      break;
  }
}

Vec3 RotateAboutY(const Vec3& d, double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  return {c * d.x + s * d.z, d.y, -s * d.x + c * d.z};
}

double PixelSolidAngle(const EnvironmentImage& image, int x, int y) {
  if (image.layout == EnvmapLayout::kLatLong) {
    const Interval ph = LatLongColumnCell(image.width, x);
    const Interval th = LatLongRowCell(image.height, y);
    return (ph.hi - ph.lo) * (std::sin(th.hi) - std::sin(th.lo));
  }
  int face, i, j;
  CubePixelToFace(image.width, x, y, face, i, j);
  const Interval cu = CubeCell(image.width, i), cv = CubeCell(image.width, j);
  return FaceRectSolidAngle(cu.lo, cu.hi, cv.lo, cv.hi);
}

std::array<double, 3> EnvironmentPower(const EnvironmentImage& image) {
  std::array<double, 3> p{0, 0, 0};
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const double w = PixelSolidAngle(image, x, y);
      for (int c = 0; c < 3; ++c) p[c] += w * image.Channel(c)[image.Index(x, y)];
    }
  }
  return p;
}

std::array<double, 3> CubemapPower(const CubemapRgb& cube) {
  const CubemapLayout layout(cube.n);
  std::array<double, 3> p{0, 0, 0};
  for (std::size_t t = 0; t < layout.texel_count(); ++t) {
    const double w = layout.TexelSolidAngle(t);
    for (int c = 0; c < 3; ++c) p[c] += w * cube.Channel(c)[t];
  }
  return p;
}

// ---- Resampling ----
// The lighting vector holds texel averages L_j = ∫_texel L dω / Ω_j (DESIGN.md, Conventions;
// this is the projection onto the piecewise-constant cubemap basis of Huang et al. 2010 §3 and
// Overbeck et al. 2006 §3). Source pixels are piecewise constant over their cells; each cell is
// cut into leaves no larger than a third of the smallest texel's edge, so each leaf crosses at
// most one grid line per axis, and AddLeaf shares the leaf's exact solid angle between texels.
namespace {

// Σ ω·R, Σ ω·G, Σ ω·B, Σ ω per texel (4 doubles per texel).
std::vector<double> AccumulateTexels(const EnvironmentImage& env, const CubemapLayout& layout,
                                     double rotation_y) {
  const int n = layout.n();
  if (env.width <= 0 || env.height <= 0 || env.r.size() != env.PixelCount() ||
      env.g.size() != env.PixelCount() || env.b.size() != env.PixelCount()) {
    throw std::invalid_argument("ResampleToCubemap: image channels do not match its size");
  }
  if ((env.layout == EnvmapLayout::kLatLong && (env.width < 2 || env.height < 2)) ||
      (env.layout == EnvmapLayout::kCube && env.height != 6 * env.width)) {
    throw std::invalid_argument("ResampleToCubemap: image shape does not fit its layout");
  }
  if (!std::isfinite(rotation_y)) throw std::invalid_argument("ResampleToCubemap: rotation");
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& ch = env.Channel(c);
    for (std::size_t i = 0; i < ch.size(); ++i) {
      if (!std::isfinite(ch[i])) {
        throw NumericalError("ResampleToCubemap: non-finite radiance at pixel (x=" +
                             std::to_string(i % static_cast<std::size_t>(env.width)) +
                             ", y=" + std::to_string(i / static_cast<std::size_t>(env.width)) +
                             ", channel " + std::to_string(c) + ")");
      }
    }
  }
  const double leaf_max = MinTexelAngle(n) / kLeavesPerTexel;
  const double split = 2.0 / n / kSplitRatio;
  const int w = env.width, h = env.height;

  // Fixed row chunks, each with its own accumulator, summed in order: deterministic results.
  const std::size_t per_chunk_bytes = 4 * layout.texel_count() * sizeof(double);
  const int max_chunks =
      static_cast<int>(std::clamp<std::size_t>((std::size_t{96} << 20) / per_chunk_bytes, 1, 16));
  const int chunks = std::clamp(h / 16, 1, max_chunks);
  std::vector<std::unique_ptr<TexelAccumulator>> acc(chunks);

  if (env.layout == EnvmapLayout::kLatLong) {
    // Longitude leaves for a given subdivision count k, rotation folded into φ.
    struct PhiLeaf {
      double sin_c, cos_c, width, phi_lo;
      int x;
    };
    const double dphi = 2 * kPi / (w - 1);
    std::vector<std::vector<PhiLeaf>> phi_tables(1);
    auto phi_table = [&](int k) -> const std::vector<PhiLeaf>& { return phi_tables[k]; };
    int k_phi_max = static_cast<int>(std::ceil(dphi / leaf_max));
    phi_tables.resize(k_phi_max + 1);
    for (int k = 1; k <= k_phi_max; ++k) {
      std::vector<PhiLeaf>& t = phi_tables[k];
      t.reserve(static_cast<std::size_t>(w) * k);
      for (int x = 0; x < w; ++x) {
        const Interval cell = LatLongColumnCell(w, x);
        const double lw = (cell.hi - cell.lo) / k;
        for (int i = 0; i < k; ++i) {
          const double phi = cell.lo + (i + 0.5) * lw + rotation_y;
          t.push_back({std::sin(phi), std::cos(phi), lw, cell.lo + i * lw + rotation_y, x});
        }
      }
    }
    const int k_theta = std::max(1, static_cast<int>(std::ceil(kPi / (h - 1) / leaf_max)));
    tbb::parallel_for(0, chunks, [&](int chunk) {
      auto a = std::make_unique<TexelAccumulator>(layout);
      const int y0 = static_cast<int>(static_cast<std::int64_t>(h) * chunk / chunks);
      const int y1 = static_cast<int>(static_cast<std::int64_t>(h) * (chunk + 1) / chunks);
      for (int y = y0; y < y1; ++y) {
        const Interval th = LatLongRowCell(h, y);
        const double cos_max =
            th.lo <= 0 && th.hi >= 0 ? 1.0 : std::max(std::cos(th.lo), std::cos(th.hi));
        const int k_phi =
            std::clamp(static_cast<int>(std::ceil(dphi * cos_max / leaf_max)), 1, k_phi_max);
        const std::vector<PhiLeaf>& leaves = phi_table(k_phi);
        const float* row_r = &env.r[env.Index(0, y)];
        const float* row_g = &env.g[env.Index(0, y)];
        const float* row_b = &env.b[env.Index(0, y)];
        const double lh = (th.hi - th.lo) / k_theta;
        for (int j = 0; j < k_theta; ++j) {
          const double t_lo = th.lo + j * lh, t_hi = t_lo + lh, tc = 0.5 * (t_lo + t_hi);
          const double st = std::sin(tc), ct = std::cos(tc);
          const double band = std::sin(t_hi) - std::sin(t_lo);
          for (const PhiLeaf& l : leaves) {
            const float rgb[3] = {row_r[l.x], row_g[l.x], row_b[l.x]};
            // d(φ, θ) = (sin φ cos θ, sin θ, cos φ cos θ); ∂d/∂φ and ∂d/∂θ times the extents.
            const Vec3 p{l.sin_c * ct, st, l.cos_c * ct};
            const Vec3 dphi_v{l.cos_c * ct * l.width, 0, -l.sin_c * ct * l.width};
            const Vec3 dth_v{-l.sin_c * st * lh, ct * lh, -l.cos_c * st * lh};
            if (!a->AddLeaf(p, dphi_v, dth_v, l.width * band, rgb, split)) {
              RefineLatLongLeaf(*a, l.phi_lo, l.phi_lo + l.width, t_lo, t_hi, rgb, 1, split);
            }
          }
        }
      }
      acc[chunk] = std::move(a);
    });
  } else {
    const int s = w;
    const double cell = s > 1 ? 2.0 / (s - 1) : 2.0;
    const int k = std::max(1, static_cast<int>(std::ceil(cell / leaf_max)));
    tbb::parallel_for(0, chunks, [&](int chunk) {
      auto a = std::make_unique<TexelAccumulator>(layout);
      const int y0 = static_cast<int>(static_cast<std::int64_t>(h) * chunk / chunks);
      const int y1 = static_cast<int>(static_cast<std::int64_t>(h) * (chunk + 1) / chunks);
      for (int y = y0; y < y1; ++y) {
        for (int x = 0; x < w; ++x) {
          int face, i, j;
          CubePixelToFace(s, x, y, face, i, j);
          const Interval cu = CubeCell(s, i), cv = CubeCell(s, j);
          const float rgb[3] = {env.r[env.Index(x, y)], env.g[env.Index(x, y)],
                                env.b[env.Index(x, y)]};
          const double du = (cu.hi - cu.lo) / k, dv = (cv.hi - cv.lo) / k;
          Vec3 eu, ev;  // ∂FacePoint/∂u and ∂/∂v
          const Vec3 p00 = CubemapLayout::FacePoint(face, 0, 0);
          eu = CubemapLayout::FacePoint(face, 1, 0) - p00;
          ev = CubemapLayout::FacePoint(face, 0, 1) - p00;
          const Vec3 ta = RotateAboutY(eu * du, rotation_y);
          const Vec3 tb = RotateAboutY(ev * dv, rotation_y);
          for (int jv = 0; jv < k; ++jv) {
            const double v0 = cv.lo + jv * dv;
            for (int iu = 0; iu < k; ++iu) {
              const double u0 = cu.lo + iu * du;
              const double omega = FaceRectSolidAngle(u0, u0 + du, v0, v0 + dv);
              const Vec3 p = RotateAboutY(
                  CubemapLayout::FacePoint(face, u0 + 0.5 * du, v0 + 0.5 * dv), rotation_y);
              if (!a->AddLeaf(p, ta, tb, omega, rgb, split)) {
                RefineCubeLeaf(*a, face, u0, u0 + du, v0, v0 + dv, rotation_y, rgb, 1, split);
              }
            }
          }
        }
      }
      acc[chunk] = std::move(a);
    });
  }

  std::vector<double> total(4 * layout.texel_count(), 0.0);
  for (const auto& a : acc) {
    const std::vector<double>& d = a->data();
    for (std::size_t i = 0; i < total.size(); ++i) total[i] += d[i];
  }
  return total;
}

}  // namespace

std::vector<double> ResampledTexelSolidAngles(const EnvironmentImage& env, int n,
                                              double rotation_y) {
  const CubemapLayout layout(n);
  const std::vector<double> total = AccumulateTexels(env, layout, rotation_y);
  std::vector<double> w(layout.texel_count());
  for (std::size_t t = 0; t < w.size(); ++t) w[t] = total[4 * t + 3];
  return w;
}

CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n, double rotation_y) {
  const CubemapLayout layout(n);
  const std::vector<double> total = AccumulateTexels(env, layout, rotation_y);
  const int w = env.width, h = env.height;
  CubemapRgb out;
  out.n = n;
  for (int c = 0; c < 3; ++c) out.Channel(c).assign(layout.texel_count(), 0.0f);
  for (std::size_t t = 0; t < layout.texel_count(); ++t) {
    const double* s = &total[4 * t];
    if (s[3] > 0) {
      for (int c = 0; c < 3; ++c) out.Channel(c)[t] = static_cast<float>(s[c] / s[3]);
    } else {
      // Unreachable with leaves smaller than texels; point-sample the nearest pixel.
      const Vec3 d = RotateAboutY(layout.TexelCenter(t), -rotation_y);
      double px, py;
      if (env.layout == EnvmapLayout::kLatLong) {
        LatLongPixelPosition(w, h, d, px, py);
      } else {
        CubeImagePixelPosition(w, d, px, py);
      }
      const int ix = std::clamp(static_cast<int>(std::lround(px)), 0, w - 1);
      const int iy = std::clamp(static_cast<int>(std::lround(py)), 0, h - 1);
      for (int c = 0; c < 3; ++c) out.Channel(c)[t] = env.Channel(c)[env.Index(ix, iy)];
    }
  }
  return out;
}

// ---- OpenEXR ----

EnvironmentImage ReadEnvironmentExr(const std::string& path, EnvironmentLoadInfo* info_out) {
  EnvironmentLoadInfo info;
  EnvironmentImage img;
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i dw = header.dataWindow();
    const std::int64_t w = std::int64_t{dw.max.x} - dw.min.x + 1;
    const std::int64_t h = std::int64_t{dw.max.y} - dw.min.y + 1;
    ValidateShape(path, EnvmapLayout::kLatLong, std::max<std::int64_t>(w, 2),
                  std::max<std::int64_t>(h, 2));  // size limits only
    EnvmapLayout layout;
    if (Imf::hasEnvmap(header)) {
      const Imf::Envmap e = Imf::envmapAttribute(header).value();
      if (e == Imf::ENVMAP_LATLONG) {
        layout = EnvmapLayout::kLatLong;
      } else if (e == Imf::ENVMAP_CUBE) {
        layout = EnvmapLayout::kCube;
      } else {
        throw InputError(path, "unknown envmap attribute value " + std::to_string(int{e}));
      }
      info.layout_from_attribute = true;
    } else {
      layout = InferLayout(path, w, h);
    }
    ValidateShape(path, layout, w, h);
    if (!file.isComplete()) throw InputError(path, "file is truncated (missing pixel data)");

    img = EnvironmentImage::Zero(layout, static_cast<int>(w), static_cast<int>(h));
    const Imf::ChannelList& channels = header.channels();
    const bool rgb =
        channels.findChannel("R") && channels.findChannel("G") && channels.findChannel("B");
    const bool grey = !rgb && channels.findChannel("Y");
    if (!rgb && !grey) {
      std::string names;
      for (auto it = channels.begin(); it != channels.end(); ++it) {
        names += std::string(names.empty() ? "" : ", ") + it.name();
      }
      throw InputError(path, "no R, G, B (or Y) channels; found: " + names);
    }
    Imf::FrameBuffer fb;
    const std::size_t xs = sizeof(float), ys = sizeof(float) * static_cast<std::size_t>(w);
    if (rgb) {
      fb.insert("R", Imf::Slice::Make(Imf::FLOAT, img.r.data(), dw, xs, ys));
      fb.insert("G", Imf::Slice::Make(Imf::FLOAT, img.g.data(), dw, xs, ys));
      fb.insert("B", Imf::Slice::Make(Imf::FLOAT, img.b.data(), dw, xs, ys));
    } else {
      fb.insert("Y", Imf::Slice::Make(Imf::FLOAT, img.r.data(), dw, xs, ys));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    if (grey) {
      img.g = img.r;
      img.b = img.r;
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, std::string("cannot read OpenEXR: ") + e.what());
  }
  CheckAndClamp(path, img, info);
  if (info_out) *info_out = info;
  return img;
}

void WriteEnvironmentExr(const EnvironmentImage& image, const std::string& path) {
  if (image.width <= 0 || image.height <= 0 || image.r.size() != image.PixelCount() ||
      image.g.size() != image.PixelCount() || image.b.size() != image.PixelCount()) {
    throw std::invalid_argument("WriteEnvironmentExr: image channels do not match its size");
  }
  try {
    Imf::Header header(image.width, image.height);
    header.compression() = Imf::ZIP_COMPRESSION;
    Imf::addEnvmap(header,
                   image.layout == EnvmapLayout::kCube ? Imf::ENVMAP_CUBE : Imf::ENVMAP_LATLONG);
    for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(path.c_str(), header);
    Imf::FrameBuffer fb;
    const Imath::Box2i dw = header.dataWindow();
    const std::size_t xs = sizeof(float), ys = sizeof(float) * image.width;
    fb.insert("R", Imf::Slice::Make(Imf::FLOAT, image.r.data(), dw, xs, ys));
    fb.insert("G", Imf::Slice::Make(Imf::FLOAT, image.g.data(), dw, xs, ys));
    fb.insert("B", Imf::Slice::Make(Imf::FLOAT, image.b.data(), dw, xs, ys));
    file.setFrameBuffer(fb);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    throw InputError(path, std::string("cannot write OpenEXR: ") + e.what());
  }
}

// ---- Radiance RGBE ----
// Format: Greg Ward, "Real Pixels" (Graphics Gems II, 1991) and the Radiance file format notes:
// a text header ending in an empty line, a resolution line, then scanlines of 4-byte RGBE
// pixels, either flat (with old-style (1,1,1,n) repeat runs) or "new" run-length encoded
// (2, 2, width>>8, width&255, then each channel run-length coded separately).

namespace {

float RgbeComponent(std::uint8_t c, std::uint8_t e) {
  return e == 0 ? 0.0f : static_cast<float>(std::ldexp(c + 0.5, static_cast<int>(e) - 136));
}

class ByteReader {
 public:
  ByteReader(const std::string& path, const std::string& data) : path_(path), data_(data) {}
  bool AtEnd() const { return pos_ >= data_.size(); }
  std::size_t Remaining() const { return data_.size() - pos_; }
  std::uint8_t Byte(const char* what) {
    if (pos_ >= data_.size()) throw InputError(path_, std::string("truncated in ") + what);
    return static_cast<std::uint8_t>(data_[pos_++]);
  }
  std::uint8_t Peek(std::size_t k) const { return static_cast<std::uint8_t>(data_[pos_ + k]); }
  // One header line without its '\n'; lines longer than 64 KiB are corrupt.
  std::string Line() {
    const std::size_t end = data_.find('\n', pos_);
    if (end == std::string::npos) throw InputError(path_, "truncated header");
    if (end - pos_ > 65536) throw InputError(path_, "header line too long");
    std::string line = data_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return line;
  }

 private:
  const std::string& path_;
  const std::string& data_;
  std::size_t pos_ = 0;
};

}  // namespace

EnvironmentImage ReadRadianceHdr(const std::string& path, EnvironmentLoadInfo* info_out) {
  const std::string data = ReadWholeFile(path);
  ByteReader in(path, data);
  const std::string magic = in.Line();
  if (magic.rfind("#?", 0) != 0) throw InputError(path, "not a Radiance file (no #? line)");
  for (;;) {
    const std::string line = in.Line();
    if (line.empty() || line == "\r") break;
    if (line.rfind("FORMAT=", 0) == 0) {
      const std::string f = line.substr(7);
      if (f.rfind("32-bit_rle_rgbe", 0) != 0) {
        throw InputError(path, "unsupported Radiance FORMAT '" + f + "' (only 32-bit_rle_rgbe)");
      }
    } else if (line.rfind("EXPOSURE=", 0) == 0) {
      // Radiance says pixel = radiance × EXPOSURE; like most tools we keep the stored values.
      spdlog::debug("{}: {} (ignored)", path, line);
    }
  }
  const std::string res = in.Line();
  std::istringstream rs(res);
  std::string ys, xs;
  long long h = 0, w = 0;
  if (!(rs >> ys >> h >> xs >> w) || (ys != "-Y" && ys != "+Y") || (xs != "+X" && xs != "-X")) {
    throw InputError(path, "unsupported resolution line '" + res +
                               "' (expected -Y h +X w; transposed images are not supported)");
  }
  EnvironmentLoadInfo info;
  const EnvmapLayout layout = InferLayout(path, w, h);
  ValidateShape(path, layout, w, h);
  EnvironmentImage img = EnvironmentImage::Zero(layout, static_cast<int>(w), static_cast<int>(h));
  const int W = img.width;
  std::vector<std::uint8_t> scan(static_cast<std::size_t>(W) * 4);
  for (int y = 0; y < img.height; ++y) {
    const std::string where = "scanline " + std::to_string(y);
    const bool new_rle = W >= 8 && W < 32768 && in.Remaining() >= 4 && in.Peek(0) == 2 &&
                         in.Peek(1) == 2 && (in.Peek(2) & 0x80) == 0;
    if (new_rle) {
      in.Byte(where.c_str());
      in.Byte(where.c_str());
      const int enc_w = (in.Byte(where.c_str()) << 8) | in.Byte(where.c_str());
      if (enc_w != W) {
        throw InputError(path, where + ": RLE width " + std::to_string(enc_w) +
                                   " does not match the image width " + std::to_string(W));
      }
      for (int c = 0; c < 4; ++c) {
        int x = 0;
        while (x < W) {
          int count = in.Byte(where.c_str());
          if (count > 128) {
            count -= 128;
            if (count > W - x) throw InputError(path, where + ": RLE run overflows the scanline");
            const std::uint8_t v = in.Byte(where.c_str());
            for (int i = 0; i < count; ++i) scan[4 * static_cast<std::size_t>(x++) + c] = v;
          } else {
            if (count == 0 || count > W - x) {
              throw InputError(path, where + ": bad RLE literal count " + std::to_string(count));
            }
            for (int i = 0; i < count; ++i) {
              scan[4 * static_cast<std::size_t>(x++) + c] = in.Byte(where.c_str());
            }
          }
        }
      }
    } else {
      int x = 0, shift = 0;
      while (x < W) {
        std::uint8_t p[4];
        for (auto& b : p) b = in.Byte(where.c_str());
        if (p[0] == 1 && p[1] == 1 && p[2] == 1) {  // old-style run: repeat the previous pixel
          if (x == 0) throw InputError(path, where + ": repeat run with no previous pixel");
          if (shift > 16) throw InputError(path, where + ": repeat run too long");
          const long long count = static_cast<long long>(p[3]) << shift;
          if (count > W - x) throw InputError(path, where + ": repeat run overflows scanline");
          for (long long i = 0; i < count; ++i, ++x) {
            std::memcpy(&scan[4 * static_cast<std::size_t>(x)],
                        &scan[4 * static_cast<std::size_t>(x - 1)], 4);
          }
          shift += 8;
        } else {
          std::memcpy(&scan[4 * static_cast<std::size_t>(x)], p, 4);
          ++x;
          shift = 0;
        }
      }
    }
    const int row = ys == "-Y" ? y : img.height - 1 - y;
    for (int x = 0; x < W; ++x) {
      const int col = xs == "+X" ? x : W - 1 - x;
      const std::uint8_t* p = &scan[4 * static_cast<std::size_t>(x)];
      const std::size_t i = img.Index(col, row);
      img.r[i] = RgbeComponent(p[0], p[3]);
      img.g[i] = RgbeComponent(p[1], p[3]);
      img.b[i] = RgbeComponent(p[2], p[3]);
    }
  }
  CheckAndClamp(path, img, info);
  if (info_out) *info_out = info;
  return img;
}

void WriteRadianceHdr(const EnvironmentImage& image, const std::string& path, bool rle) {
  if (image.width <= 0 || image.height <= 0 || image.r.size() != image.PixelCount() ||
      image.g.size() != image.PixelCount() || image.b.size() != image.PixelCount()) {
    throw std::invalid_argument("WriteRadianceHdr: image channels do not match its size");
  }
  std::string out = "#?RADIANCE\n# Written by prtfarm\nFORMAT=32-bit_rle_rgbe\n\n-Y " +
                    std::to_string(image.height) + " +X " + std::to_string(image.width) + "\n";
  const int W = image.width;
  const bool use_rle = rle && W >= 8 && W < 32768;
  std::vector<std::uint8_t> scan(static_cast<std::size_t>(W) * 4);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t i = image.Index(x, y);
      double c[3] = {image.r[i], image.g[i], image.b[i]};
      for (double& v : c) v = std::isfinite(v) ? std::clamp(v, 0.0, 1.7e38) : 0.0;
      const double m = std::max({c[0], c[1], c[2]});
      std::uint8_t* p = &scan[4 * static_cast<std::size_t>(x)];
      if (m < 1e-32) {
        p[0] = p[1] = p[2] = p[3] = 0;
      } else {
        int e;
        const double scale = std::frexp(m, &e) * 256.0 / m;
        for (int k = 0; k < 3; ++k) {
          p[k] = static_cast<std::uint8_t>(std::min(255.0, std::floor(c[k] * scale)));
        }
        p[3] = static_cast<std::uint8_t>(e + 128);
      }
    }
    if (!use_rle) {
      out.append(reinterpret_cast<const char*>(scan.data()), scan.size());
      continue;
    }
    out.push_back(2);
    out.push_back(2);
    out.push_back(static_cast<char>(W >> 8));
    out.push_back(static_cast<char>(W & 255));
    for (int c = 0; c < 4; ++c) {
      auto at = [&](int x) { return scan[4 * static_cast<std::size_t>(x) + c]; };
      int x = 0;
      while (x < W) {
        int run = 1;
        while (x + run < W && run < 127 && at(x + run) == at(x)) ++run;
        if (run >= 4) {
          out.push_back(static_cast<char>(128 + run));
          out.push_back(static_cast<char>(at(x)));
          x += run;
          continue;
        }
        const int start = x;
        int len = 0;
        while (x < W && len < 128) {
          int r = 1;
          while (x + r < W && r < 4 && at(x + r) == at(x)) ++r;
          if (r >= 4) break;
          ++x;
          ++len;
        }
        out.push_back(static_cast<char>(len));
        for (int i = start; i < start + len; ++i) out.push_back(static_cast<char>(at(i)));
      }
    }
  }
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw InputError(path, "cannot open for writing");
  f.write(out.data(), static_cast<std::streamsize>(out.size()));
  f.close();
  if (!f) throw InputError(path, "write failed");
}

EnvironmentImage ReadEnvironment(const std::string& path, EnvironmentLoadInfo* info) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path, "cannot open for reading");
  char magic[4] = {0, 0, 0, 0};
  f.read(magic, 4);
  if (f.gcount() == 4 && static_cast<unsigned char>(magic[0]) == 0x76 &&
      static_cast<unsigned char>(magic[1]) == 0x2f &&
      static_cast<unsigned char>(magic[2]) == 0x31 &&
      static_cast<unsigned char>(magic[3]) == 0x01) {
    return ReadEnvironmentExr(path, info);
  }
  if (f.gcount() >= 2 && magic[0] == '#' && magic[1] == '?') return ReadRadianceHdr(path, info);
  throw InputError(path, "neither OpenEXR nor Radiance .hdr (unrecognised magic bytes)");
}

// ---- Procedural sky ----

std::array<float, 3> SkyRadiance(const SkySunParams& p, const Vec3& dir) {
  const Vec3 d = Normalize(dir);
  const Vec3 sun = Normalize(p.sun_direction);
  std::array<float, 3> out;
  const double glow = std::pow(std::max(0.0, Dot(d, sun)), 4.0);
  for (int c = 0; c < 3; ++c) {
    double v;
    if (d.y >= 0) {
      const double t = (1 - std::exp(-3 * d.y)) / (1 - std::exp(-3.0));
      v = p.horizon[c] + (p.zenith[c] - p.horizon[c]) * t;
    } else {
      v = p.ground[c] + (p.horizon[c] - p.ground[c]) * std::exp(8 * d.y);
    }
    v *= 1 + 0.5 * glow;
    out[c] = static_cast<float>(v);
  }
  return out;
}

EnvironmentImage SampleEnvironment(EnvmapLayout layout, int width, int height,
                                   const std::function<std::array<float, 3>(const Vec3&)>& f) {
  ValidateShape("<procedural>", layout, width, height);
  EnvironmentImage img = EnvironmentImage::Zero(layout, width, height);
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const Vec3 d = layout == EnvmapLayout::kLatLong ? LatLongDirection(width, height, x, y)
                                                      : CubeImageDirection(width, x, y);
      const std::array<float, 3> v = f(Normalize(d));
      for (int c = 0; c < 3; ++c) img.Channel(c)[img.Index(x, y)] = v[c];
    }
  });
  return img;
}

EnvironmentImage MakeSkyWithSun(EnvmapLayout layout, int width, int height,
                                const SkySunParams& params, int supersamples) {
  EnvironmentImage img = SampleEnvironment(layout, width, height,
                                           [&](const Vec3& d) { return SkyRadiance(params, d); });
  const Vec3 sun = Normalize(params.sun_direction);
  const double cos_r = std::cos(params.sun_angular_radius);
  const int ss = std::max(1, supersamples);
  // Bound on a pixel cell's angular radius, to skip pixels far from the disc.
  const double cell = layout == EnvmapLayout::kLatLong
                          ? 2 * kPi / (width - 1) + kPi / (height - 1)
                          : 2.0 * (width > 1 ? 2.0 / (width - 1) : 2.0);
  tbb::parallel_for(0, height, [&](int y) {
    for (int x = 0; x < width; ++x) {
      const Vec3 c =
          Normalize(layout == EnvmapLayout::kLatLong ? LatLongDirection(width, height, x, y)
                                                     : CubeImageDirection(width, x, y));
      if (std::acos(std::clamp(Dot(c, sun), -1.0, 1.0)) > params.sun_angular_radius + cell)
        continue;
      // Box filter over the cell: fraction of the cell's solid angle inside the disc.
      double in = 0, all = 0;
      if (layout == EnvmapLayout::kLatLong) {
        const Interval ph = LatLongColumnCell(width, x), th = LatLongRowCell(height, y);
        for (int j = 0; j < ss; ++j) {
          const double t = th.lo + (j + 0.5) * (th.hi - th.lo) / ss;
          for (int i = 0; i < ss; ++i) {
            const double f = ph.lo + (i + 0.5) * (ph.hi - ph.lo) / ss;
            const Vec3 d{std::sin(f) * std::cos(t), std::sin(t), std::cos(f) * std::cos(t)};
            all += std::cos(t);
            if (Dot(d, sun) >= cos_r) in += std::cos(t);
          }
        }
      } else {
        int face, fi, fj;
        CubePixelToFace(width, x, y, face, fi, fj);
        const Interval cu = CubeCell(width, fi), cv = CubeCell(width, fj);
        for (int j = 0; j < ss; ++j) {
          const double v = cv.lo + (j + 0.5) * (cv.hi - cv.lo) / ss;
          for (int i = 0; i < ss; ++i) {
            const double u = cu.lo + (i + 0.5) * (cu.hi - cu.lo) / ss;
            const double wgt = std::pow(1 + u * u + v * v, -1.5);
            all += wgt;
            if (Dot(CubemapLayout::FaceDirection(face, u, v), sun) >= cos_r) in += wgt;
          }
        }
      }
      if (in <= 0) continue;
      const double frac = in / all;
      for (int ch = 0; ch < 3; ++ch) {
        img.Channel(ch)[img.Index(x, y)] += static_cast<float>(frac * params.sun_radiance[ch]);
      }
    }
  });
  return img;
}

}  // namespace prt
