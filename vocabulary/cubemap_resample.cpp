// Resampling an environment to the lighting vector L (see cubemap_resample.h).
#include "vocabulary/cubemap_resample.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/cubemap.h"
#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace prt {

namespace {

constexpr double kPi = std::numbers::pi;

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

  // Recording instead of accumulating (PeriodicLatLongResampler): every share of a leaf's solid
  // angle becomes an entry (texel, cell, ω) of `record`, for the cell set before its leaves.
  void Record(std::vector<PeriodicLatLongResampler::Weight>* record) { record_ = record; }
  void SetCell(uint32_t cell) { cell_ = cell; }

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
    if (record_ != nullptr) {
      record_->push_back({static_cast<uint32_t>(t), cell_, omega});
      return;
    }
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
  std::vector<PeriodicLatLongResampler::Weight>* record_ = nullptr;
  uint32_t cell_ = 0;
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

// A general rotation (row-major 3×3) applied to a direction; `r` null: the identity.
Vec3 Rotate(const double* r, const Vec3& v) {
  if (r == nullptr) return v;
  return {r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
          r[6] * v.x + r[7] * v.y + r[8] * v.z};
}

// Lat-long leaf φ ∈ [f0, f1] (a rotation about +Y included), θ ∈ [t0, t1], split in four and
// added; `r` (nullable) a general rotation applied after.
void RefineLatLongLeaf(TexelAccumulator& a, double f0, double f1, double t0, double t1,
                       const float* rgb, int depth, double split, const double* r) {
  const double fm = 0.5 * (f0 + f1), tm = 0.5 * (t0 + t1);
  const double quads[4][4] = {
      {f0, fm, t0, tm}, {fm, f1, t0, tm}, {f0, fm, tm, t1}, {fm, f1, tm, t1}};
  for (const auto& q : quads) {
    const double fc = 0.5 * (q[0] + q[1]), tc = 0.5 * (q[2] + q[3]);
    const double sf = std::sin(fc), cf = std::cos(fc), st = std::sin(tc), ct = std::cos(tc);
    const double dw = q[1] - q[0], dh = q[3] - q[2];
    const Vec3 p = Rotate(r, {sf * ct, st, cf * ct});
    const Vec3 ta = Rotate(r, {cf * ct * dw, 0, -sf * ct * dw});
    const Vec3 tb = Rotate(r, {-sf * st * dh, ct * dh, -cf * st * dh});
    const double omega = dw * (std::sin(q[3]) - std::sin(q[2]));
    if (!a.AddLeaf(p, ta, tb, omega, rgb, depth < kMaxSplitDepth ? split : 0)) {
      RefineLatLongLeaf(a, q[0], q[1], q[2], q[3], rgb, depth + 1, split, r);
    }
  }
}

// Cube leaf [u0, u1] × [v0, v1] of a source face, rotated by rot about +Y, split in four.
void RefineCubeLeaf(TexelAccumulator& a, int face, double u0, double u1, double v0, double v1,
                    double rot, const float* rgb, int depth, double split, const double* r) {
  const double um = 0.5 * (u0 + u1), vm = 0.5 * (v0 + v1);
  const double quads[4][4] = {
      {u0, um, v0, vm}, {um, u1, v0, vm}, {u0, um, vm, v1}, {um, u1, vm, v1}};
  const Vec3 p00 = CubemapLayout::FacePoint(face, 0, 0);
  const Vec3 eu = CubemapLayout::FacePoint(face, 1, 0) - p00;
  const Vec3 ev = CubemapLayout::FacePoint(face, 0, 1) - p00;
  for (const auto& q : quads) {
    const Vec3 p = Rotate(
        r, RotateAboutY(CubemapLayout::FacePoint(face, 0.5 * (q[0] + q[1]), 0.5 * (q[2] + q[3])),
                        rot));
    const Vec3 ta = Rotate(r, RotateAboutY(eu * (q[1] - q[0]), rot));
    const Vec3 tb = Rotate(r, RotateAboutY(ev * (q[3] - q[2]), rot));
    const double omega = FaceRectSolidAngle(q[0], q[1], q[2], q[3]);
    if (!a.AddLeaf(p, ta, tb, omega, rgb, depth < kMaxSplitDepth ? split : 0)) {
      RefineCubeLeaf(a, face, q[0], q[1], q[2], q[3], rot, rgb, depth + 1, split, r);
    }
  }
}

// Smallest angular edge length of a texel of an n-cubemap (at a cube corner): 2/n · √2/3.
double MinTexelAngle(int n) {
  return 2.0 / n * std::sqrt(2.0) / 3.0;
}

}  // namespace

// ---- Resampling ----
// The lighting vector holds texel averages L_j = ∫_texel L dω / Ω_j (DESIGN.md, Conventions;
// this is the projection onto the piecewise-constant cubemap basis of Huang et al. 2010 §3 and
// Overbeck et al. 2006 §3). Source pixels are piecewise constant over their cells; each cell is
// cut into leaves no larger than a third of the smallest texel's edge, so each leaf crosses at
// most one grid line per axis, and AddLeaf shares the leaf's exact solid angle between texels.
namespace {

// Σ ω·R, Σ ω·G, Σ ω·B, Σ ω per texel (4 doubles per texel).
// `r` (nullable): a general rotation applied after the one about +Y.
std::vector<double> AccumulateTexels(const EnvironmentImage& env, const CubemapLayout& layout,
                                     double rotation_y, const double* r) {
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
        const PixelInterval cell = LatLongColumnCell(w, x);
        const double lw = (cell.hi - cell.lo) / k;
        for (int i = 0; i < k; ++i) {
          const double phi = cell.lo + (i + 0.5) * lw + rotation_y;
          t.push_back({std::sin(phi), std::cos(phi), lw, cell.lo + i * lw + rotation_y, x});
        }
      }
    }
    const int k_theta = std::max(1, static_cast<int>(std::ceil(kPi / (h - 1) / leaf_max)));
    ParallelFor(static_cast<std::size_t>(chunks), [&](std::size_t chunk_index) {
      const int chunk = static_cast<int>(chunk_index);
      auto a = std::make_unique<TexelAccumulator>(layout);
      const int y0 = static_cast<int>(static_cast<std::int64_t>(h) * chunk / chunks);
      const int y1 = static_cast<int>(static_cast<std::int64_t>(h) * (chunk + 1) / chunks);
      for (int y = y0; y < y1; ++y) {
        const PixelInterval th = LatLongRowCell(h, y);
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
            const Vec3 p = Rotate(r, {l.sin_c * ct, st, l.cos_c * ct});
            const Vec3 dphi_v = Rotate(r, {l.cos_c * ct * l.width, 0, -l.sin_c * ct * l.width});
            const Vec3 dth_v = Rotate(r, {-l.sin_c * st * lh, ct * lh, -l.cos_c * st * lh});
            if (!a->AddLeaf(p, dphi_v, dth_v, l.width * band, rgb, split)) {
              RefineLatLongLeaf(*a, l.phi_lo, l.phi_lo + l.width, t_lo, t_hi, rgb, 1, split, r);
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
    ParallelFor(static_cast<std::size_t>(chunks), [&](std::size_t chunk_index) {
      const int chunk = static_cast<int>(chunk_index);
      auto a = std::make_unique<TexelAccumulator>(layout);
      const int y0 = static_cast<int>(static_cast<std::int64_t>(h) * chunk / chunks);
      const int y1 = static_cast<int>(static_cast<std::int64_t>(h) * (chunk + 1) / chunks);
      for (int y = y0; y < y1; ++y) {
        for (int x = 0; x < w; ++x) {
          int face, i, j;
          CubePixelToFace(s, x, y, face, i, j);
          const PixelInterval cu = CubeCell(s, i), cv = CubeCell(s, j);
          const float rgb[3] = {env.r[env.Index(x, y)], env.g[env.Index(x, y)],
                                env.b[env.Index(x, y)]};
          const double du = (cu.hi - cu.lo) / k, dv = (cv.hi - cv.lo) / k;
          Vec3 eu, ev;  // ∂FacePoint/∂u and ∂/∂v
          const Vec3 p00 = CubemapLayout::FacePoint(face, 0, 0);
          eu = CubemapLayout::FacePoint(face, 1, 0) - p00;
          ev = CubemapLayout::FacePoint(face, 0, 1) - p00;
          const Vec3 ta = Rotate(r, RotateAboutY(eu * du, rotation_y));
          const Vec3 tb = Rotate(r, RotateAboutY(ev * dv, rotation_y));
          for (int jv = 0; jv < k; ++jv) {
            const double v0 = cv.lo + jv * dv;
            for (int iu = 0; iu < k; ++iu) {
              const double u0 = cu.lo + iu * du;
              const double omega = FaceRectSolidAngle(u0, u0 + du, v0, v0 + dv);
              const Vec3 p = Rotate(
                  r, RotateAboutY(CubemapLayout::FacePoint(face, u0 + 0.5 * du, v0 + 0.5 * dv),
                                  rotation_y));
              if (!a->AddLeaf(p, ta, tb, omega, rgb, split)) {
                RefineCubeLeaf(*a, face, u0, u0 + du, v0, v0 + dv, rotation_y, rgb, 1, split, r);
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
  const std::vector<double> total = AccumulateTexels(env, layout, rotation_y, nullptr);
  std::vector<double> w(layout.texel_count());
  for (std::size_t t = 0; t < w.size(); ++t) w[t] = total[4 * t + 3];
  return w;
}

namespace {

CubemapRgb Resample(const EnvironmentImage& env, int n, double rotation_y, const double* r) {
  const CubemapLayout layout(n);
  const std::vector<double> total = AccumulateTexels(env, layout, rotation_y, r);
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
      Vec3 d = layout.TexelCenter(t);
      if (r != nullptr)  // Rᵀ·d
        d = {r[0] * d.x + r[3] * d.y + r[6] * d.z, r[1] * d.x + r[4] * d.y + r[7] * d.z,
             r[2] * d.x + r[5] * d.y + r[8] * d.z};
      d = RotateAboutY(d, -rotation_y);
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

}  // namespace

CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n, double rotation_y) {
  return Resample(env, n, rotation_y, nullptr);
}

CubemapRgb ResampleToCubemap(const EnvironmentImage& env, int n,
                             const std::array<double, 9>& rotation) {
  for (double v : rotation)
    if (!std::isfinite(v)) throw std::invalid_argument("ResampleToCubemap: rotation");
  return Resample(env, n, 0.0, rotation.data());
}

// ---- Rotations about +Y from a periodic grid ----

PeriodicLatLongResampler::PeriodicLatLongResampler(const EnvironmentImage& env, int n, int width)
    : n_(n), w_(width), h_(width / 2) {
  if (env.layout != EnvmapLayout::kLatLong || env.width < 2 || env.height < 2 ||
      env.r.size() != env.PixelCount() || env.g.size() != env.PixelCount() ||
      env.b.size() != env.PixelCount())
    throw std::invalid_argument("PeriodicLatLongResampler: a lat-long map is needed");
  if (width < 4 || width % 2 != 0 || width > 65536)
    throw std::invalid_argument("PeriodicLatLongResampler: width " + std::to_string(width));
  const CubemapLayout layout(n);  // checks n
  const double dphi = 2 * kPi / w_, dth = kPi / h_;
  // The grid: each cell the exact mean of the map over it (separable: the overlap of the
  // pixels' longitude intervals times that of their sin-latitude intervals), so the power is
  // kept. Both partitions cover [−π, π] × [−π/2, π/2] (the map's end columns are half cells).
  struct Piece {
    int cell;
    double weight;
  };
  std::vector<std::vector<Piece>> cols(static_cast<std::size_t>(env.width));
  for (int xs = 0; xs < env.width; ++xs) {
    const PixelInterval c = LatLongColumnCell(env.width, xs);
    const double lo = std::min(c.lo, c.hi), hi = std::max(c.lo, c.hi);
    // Grid column x spans φ ∈ [π − (x + 1)·Δ, π − x·Δ].
    const int x0 = std::clamp(static_cast<int>(std::floor((kPi - hi) / dphi)), 0, w_ - 1);
    const int x1 = std::clamp(static_cast<int>(std::floor((kPi - lo) / dphi)), 0, w_ - 1);
    for (int x = x0; x <= x1; ++x) {
      const double a = std::max(lo, kPi - (x + 1) * dphi), b = std::min(hi, kPi - x * dphi);
      if (b > a) cols[xs].push_back({x, b - a});
    }
  }
  std::vector<std::vector<Piece>> rows(static_cast<std::size_t>(env.height));
  for (int ys = 0; ys < env.height; ++ys) {
    const PixelInterval c = LatLongRowCell(env.height, ys);
    const double lo = std::min(c.lo, c.hi), hi = std::max(c.lo, c.hi);
    // Grid row y spans θ ∈ [π/2 − (y + 1)·δ, π/2 − y·δ].
    const int y0 = std::clamp(static_cast<int>(std::floor((kPi / 2 - hi) / dth)), 0, h_ - 1);
    const int y1 = std::clamp(static_cast<int>(std::floor((kPi / 2 - lo) / dth)), 0, h_ - 1);
    for (int y = y0; y <= y1; ++y) {
      const double a = std::max(lo, kPi / 2 - (y + 1) * dth);
      const double b = std::min(hi, kPi / 2 - y * dth);
      if (b > a) rows[ys].push_back({y, std::sin(b) - std::sin(a)});
    }
  }
  const std::size_t cells = static_cast<std::size_t>(w_) * h_;
  std::vector<double> sum(3 * cells, 0.0), area(cells, 0.0);
  std::vector<double> row_sum(3 * static_cast<std::size_t>(w_)), row_area(w_);
  for (int ys = 0; ys < env.height; ++ys) {
    std::fill(row_sum.begin(), row_sum.end(), 0.0);
    std::fill(row_area.begin(), row_area.end(), 0.0);
    for (int xs = 0; xs < env.width; ++xs) {
      const std::size_t i = env.Index(xs, ys);
      const double v[3] = {env.r[i], env.g[i], env.b[i]};
      for (const Piece& c : cols[xs]) {
        for (int k = 0; k < 3; ++k) row_sum[3 * c.cell + k] += c.weight * v[k];
        row_area[c.cell] += c.weight;
      }
    }
    for (const Piece& r : rows[ys])
      for (int x = 0; x < w_; ++x) {
        const std::size_t cell = static_cast<std::size_t>(r.cell) * w_ + x;
        for (int k = 0; k < 3; ++k) sum[3 * cell + k] += r.weight * row_sum[3 * x + k];
        area[cell] += r.weight * row_area[x];
      }
  }
  grid_.resize(3 * cells);
  for (std::size_t c = 0; c < cells; ++c)
    for (int k = 0; k < 3; ++k)
      grid_[3 * c + k] = area[c] > 0 ? static_cast<float>(sum[3 * c + k] / area[c]) : 0.0f;

  // The weights at rotation 0: every cell cut into leaves and refined as AccumulateTexels does
  // a pixel, the shares recorded instead of accumulated; per row chunk, then merged.
  const double leaf_max = MinTexelAngle(n) / kLeavesPerTexel;
  const double split = 2.0 / n / kSplitRatio;
  const int k_theta = std::max(1, static_cast<int>(std::ceil(dth / leaf_max)));
  const int chunks = std::clamp(h_ / 8, 1, 32);
  std::vector<std::vector<Weight>> parts(static_cast<std::size_t>(chunks));
  const float dummy[3] = {0, 0, 0};
  ParallelFor(static_cast<std::size_t>(chunks), [&](std::size_t chunk) {
    TexelAccumulator a(layout);
    a.Record(&parts[chunk]);
    const int y0 = static_cast<int>(static_cast<std::int64_t>(h_) * chunk / chunks);
    const int y1 = static_cast<int>(static_cast<std::int64_t>(h_) * (chunk + 1) / chunks);
    for (int y = y0; y < y1; ++y) {
      const double t_top = kPi / 2 - y * dth, t_bottom = t_top - dth;
      const double cos_max =
          t_bottom <= 0 && t_top >= 0 ? 1.0 : std::max(std::cos(t_bottom), std::cos(t_top));
      const int k_phi = std::max(1, static_cast<int>(std::ceil(dphi * cos_max / leaf_max)));
      const double lw = dphi / k_phi, lh = dth / k_theta;
      for (int x = 0; x < w_; ++x) {
        a.SetCell(static_cast<uint32_t>(y * w_ + x));
        const double f_lo = kPi - (x + 1) * dphi;
        for (int j = 0; j < k_theta; ++j) {
          const double t_lo = t_bottom + j * lh, t_hi = t_lo + lh, tc = 0.5 * (t_lo + t_hi);
          const double st = std::sin(tc), ct = std::cos(tc);
          const double band = std::sin(t_hi) - std::sin(t_lo);
          for (int i = 0; i < k_phi; ++i) {
            const double f0 = f_lo + i * lw, fc = f0 + 0.5 * lw;
            const double sf = std::sin(fc), cf = std::cos(fc);
            const Vec3 p{sf * ct, st, cf * ct};
            const Vec3 dphi_v{cf * ct * lw, 0, -sf * ct * lw};
            const Vec3 dth_v{-sf * st * lh, ct * lh, -cf * st * lh};
            if (!a.AddLeaf(p, dphi_v, dth_v, lw * band, dummy, split))
              RefineLatLongLeaf(a, f0, f0 + lw, t_lo, t_hi, dummy, 1, split, nullptr);
          }
        }
      }
    }
  });
  std::vector<Weight> all;
  std::size_t total = 0;
  for (const auto& p : parts) total += p.size();
  all.reserve(total);
  for (auto& p : parts) {
    all.insert(all.end(), p.begin(), p.end());
    std::vector<Weight>().swap(p);
  }
  std::sort(all.begin(), all.end(), [](const Weight& a, const Weight& b) {
    return a.texel != b.texel ? a.texel < b.texel : a.cell < b.cell;
  });
  // One entry per (texel, cell); per texel its entries' range and Σ ω.
  texel_begin_.assign(layout.texel_count() + 1, 0);
  texel_omega_.assign(layout.texel_count(), 0.0);
  for (std::size_t i = 0; i < all.size();) {
    std::size_t j = i;
    double omega = 0;
    for (; j < all.size() && all[j].texel == all[i].texel && all[j].cell == all[i].cell; ++j)
      omega += all[j].omega;
    const uint32_t cell = all[i].cell;
    entries_.push_back({static_cast<uint32_t>(cell / w_) * static_cast<uint32_t>(w_),
                        static_cast<uint32_t>(cell % w_), static_cast<float>(omega)});
    texel_omega_[all[i].texel] += omega;
    texel_begin_[all[i].texel + 1] = static_cast<uint32_t>(entries_.size());
    i = j;
  }
  for (std::size_t t = 1; t < texel_begin_.size(); ++t)
    texel_begin_[t] = std::max(texel_begin_[t], texel_begin_[t - 1]);
}

CubemapRgb PeriodicLatLongResampler::Resample(double rotation_y) const {
  if (!std::isfinite(rotation_y)) throw std::invalid_argument("PeriodicLatLongResampler: rotation");
  // The rotation in cells: k whole cells and a fraction f; the map's cell x then lies at grid
  // cell x − k − f (φ decreases with x), so cell x' receives (1 − f)·g[x' + k] + f·g[x' + k + 1].
  const double cells = rotation_y / (2 * kPi) * w_;
  const double whole = std::floor(cells);
  const auto f = static_cast<float>(cells - whole);
  const auto w = static_cast<int64_t>(w_);
  const auto k = static_cast<uint32_t>(((static_cast<int64_t>(whole) % w) + w) % w);
  const auto uw = static_cast<uint32_t>(w_);
  CubemapRgb out;
  out.n = n_;
  const std::size_t texels = texel_omega_.size();
  for (int c = 0; c < 3; ++c) out.Channel(c).assign(texels, 0.0f);
  const float* g = grid_.data();
  for (std::size_t t = 0; t < texels; ++t) {
    float s0 = 0, s1 = 0, s2 = 0;
    for (uint32_t e = texel_begin_[t]; e < texel_begin_[t + 1]; ++e) {
      const Entry& en = entries_[e];
      uint32_t x = en.x + k;
      if (x >= uw) x -= uw;
      uint32_t x1 = x + 1;
      if (x1 >= uw) x1 -= uw;
      const float* a = g + 3 * static_cast<std::size_t>(en.row + x);
      const float* b = g + 3 * static_cast<std::size_t>(en.row + x1);
      s0 += en.omega * (a[0] + f * (b[0] - a[0]));
      s1 += en.omega * (a[1] + f * (b[1] - a[1]));
      s2 += en.omega * (a[2] + f * (b[2] - a[2]));
    }
    const double o = texel_omega_[t];
    if (o > 0) {
      out.r[t] = static_cast<float>(s0 / o);
      out.g[t] = static_cast<float>(s1 / o);
      out.b[t] = static_cast<float>(s2 / o);
    }
  }
  return out;
}

std::size_t PeriodicLatLongResampler::memory_bytes() const {
  return sizeof(float) * grid_.capacity() + sizeof(Entry) * entries_.capacity() +
         sizeof(uint32_t) * texel_begin_.capacity() + sizeof(double) * texel_omega_.capacity();
}

}  // namespace prt
