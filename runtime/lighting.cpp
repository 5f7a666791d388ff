// Wavelet lighting and its non-linear approximation (Ng et al. 2003 §5, "non-linear wavelet
// lighting approximation" with area-weighted selection; Overbeck et al. 2006 §3 Eq. 2, §5.1).
#include "runtime/lighting.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"
#include "vocabulary/wavelets.h"

namespace prt {

namespace {

int CheckFaceSize(int n) {
  if (n < 1 || n > 256 || !std::has_single_bit(static_cast<unsigned>(n))) {
    throw std::invalid_argument("lighting: face size " + std::to_string(n) +
                                " is not a power of two in [1, 256]");
  }
  return std::countr_zero(static_cast<unsigned>(n));  // full depth log2 n
}

// The orthonormal Haar transform of one n×n face to full depth, in double throughout: the
// same steps as vocabulary/wavelets.h's ForwardHaarFace (its ForwardHaarStep2D: one pass over
// 2×2 blocks, LL = (p+q+r+s)/2, HL = (p−q+r−s)/2, LH = (p+q−r−s)/2, HH = (p−q−r+s)/2, the next
// step on LL), without its final rounding to float. A face's scaling coefficient is n × the
// face's mean, which passes the float range once texels exceed FLT_MAX / n (a coefficient the
// float transform would store as Inf); and the lighting is double from here on (WaveletLighting),
// so keeping the float rounding would only add error. `tmp` holds n² doubles.
void ForwardHaarFaceDouble(double* face, int n, double* tmp) {
  for (int m = n; m >= 2; m /= 2) {
    const int h = m / 2;
    for (int j = 0; j < h; ++j) {
      const double* r0 = face + static_cast<std::ptrdiff_t>(2 * j) * n;
      const double* r1 = r0 + n;
      double* ll = tmp + static_cast<std::ptrdiff_t>(j) * n;
      double* lh = tmp + static_cast<std::ptrdiff_t>(h + j) * n;
      for (int i = 0; i < h; ++i) {
        const double p = r0[2 * i], q = r0[2 * i + 1], r = r1[2 * i], t = r1[2 * i + 1];
        const double top = p + q, bottom = r + t, left = p + r, right = q + t;
        ll[i] = 0.5 * (top + bottom);
        ll[h + i] = 0.5 * (left - right);
        lh[i] = 0.5 * (top - bottom);
        lh[h + i] = 0.5 * ((p - q) - (r - t));
      }
    }
    for (int y = 0; y < m; ++y)
      std::copy_n(tmp + static_cast<std::ptrdiff_t>(y) * n, m,
                  face + static_cast<std::ptrdiff_t>(y) * n);
  }
}

// The inverse of ForwardHaarFaceDouble (wavelets.cpp's InverseHaarStep2D, in double).
void InverseHaarFaceDouble(double* face, int n, double* tmp) {
  for (int m = 2; m <= n; m *= 2) {
    const int h = m / 2;
    for (int j = 0; j < h; ++j) {
      const double* ll = face + static_cast<std::ptrdiff_t>(j) * n;
      const double* lh = face + static_cast<std::ptrdiff_t>(h + j) * n;
      double* r0 = tmp + static_cast<std::ptrdiff_t>(2 * j) * n;
      double* r1 = r0 + n;
      for (int i = 0; i < h; ++i) {
        const double sum_l = ll[i] + lh[i], dif_l = ll[i] - lh[i];
        const double sum_h = ll[h + i] + lh[h + i], dif_h = ll[h + i] - lh[h + i];
        r0[2 * i] = 0.5 * (sum_l + sum_h);
        r0[2 * i + 1] = 0.5 * (sum_l - sum_h);
        r1[2 * i] = 0.5 * (dif_l + dif_h);
        r1[2 * i + 1] = 0.5 * (dif_l - dif_h);
      }
    }
    for (int y = 0; y < m; ++y)
      std::copy_n(tmp + static_cast<std::ptrdiff_t>(y) * n, m,
                  face + static_cast<std::ptrdiff_t>(y) * n);
  }
}

// A value for an error message: 7 significant digits (std::to_string writes 1e39 in full).
std::string Number(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.7g", v);
  return b;
}

const char* ChannelName(int c) {
  return c == 0 ? "R" : (c == 1 ? "G" : "B");
}

}  // namespace

double WaveletLighting::Magnitude(std::size_t j) const {
  return std::abs(coefficient[0][j]) + std::abs(coefficient[1][j]) + std::abs(coefficient[2][j]);
}

HaarLightingBasis::HaarLightingBasis(int n) : n_(n) {
  const int depth = CheckFaceSize(n);
  const std::size_t face = static_cast<std::size_t>(n) * n;
  area_.resize(6 * face);
  level_.resize(6 * face);
  band_.resize(6 * face);
  members_.resize(static_cast<std::size_t>(std::max(1, depth)));
  std::vector<uint8_t> levels(face);
  CoefficientLevelMap2D(n, n, depth, levels.data());
  for (std::size_t f = 0; f < 6; ++f) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const std::size_t local = static_cast<std::size_t>(y) * n + x;
        const std::size_t j = f * face + local;
        area_[j] = static_cast<double>(HaarSupportTexels(n, depth, x, y));
        level_[j] = levels[local];
        band_[j] = static_cast<uint8_t>(std::max<int>(levels[local], 1) - 1);
      }
    }
  }
  for (std::size_t j = 0; j < area_.size(); ++j) {
    members_[band_[j]].push_back(static_cast<uint32_t>(j));
  }
}

WaveletLighting ProjectLighting(const CubemapRgb& cube) {
  CheckFaceSize(cube.n);
  const std::size_t texels = cube.TexelCount();
  const std::size_t face = static_cast<std::size_t>(cube.n) * cube.n;
  WaveletLighting out;
  out.n = cube.n;
  std::vector<double> tmp(face);
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& src = cube.Channel(c);
    if (src.size() != texels) {
      throw std::invalid_argument("ProjectLighting: channel " + std::to_string(c) + " has " +
                                  std::to_string(src.size()) + " texels, expected " +
                                  std::to_string(texels));
    }
    std::vector<double>& dst = out.coefficient[c];
    dst.resize(texels);
    for (std::size_t j = 0; j < texels; ++j) {
      // ResampleToCubemap's texels are finite (it refuses NaN/Inf pixels, and a texel is a
      // weighted average of pixels); a cubemap made otherwise is checked here.
      if (!std::isfinite(src[j]))
        throw NumericalError("ProjectLighting: lighting texel " + std::to_string(j) + " (face " +
                             std::to_string(j / face) + ") channel " + ChannelName(c) + " is " +
                             (std::isnan(src[j]) ? "NaN" : "Inf"));
      dst[j] = src[j];
    }
    // Finite: each coefficient is a sum of at most n² finite floats times 2^−k, at most
    // n·FLT_MAX ≤ 256·3.4e38 in magnitude, far inside the double range.
    for (std::size_t f = 0; f < 6; ++f)
      ForwardHaarFaceDouble(dst.data() + f * face, cube.n, tmp.data());
  }
  return out;
}

CubemapRgb ReconstructLighting(const WaveletLighting& lighting) {
  CheckFaceSize(lighting.n);
  CubemapRgb cube;
  cube.n = lighting.n;
  const std::size_t face = static_cast<std::size_t>(cube.n) * cube.n;
  std::vector<double> work, tmp(face);
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& dst = cube.Channel(c);
    dst.resize(cube.TexelCount());
    if (lighting.coefficient[c].size() != dst.size()) {
      throw std::invalid_argument("ReconstructLighting: wrong coefficient count");
    }
    work = lighting.coefficient[c];
    for (std::size_t f = 0; f < 6; ++f)
      InverseHaarFaceDouble(work.data() + f * face, cube.n, tmp.data());
    for (std::size_t j = 0; j < dst.size(); ++j) {
      // Texel radiance of a lighting vector (or of an approximation: sums of its terms) need not
      // fit in float even when every coefficient is finite; that is an error, not an Inf texel.
      if (!(std::abs(work[j]) <= std::numeric_limits<float>::max()))
        throw NumericalError("ReconstructLighting: texel " + std::to_string(j) + " channel " +
                             ChannelName(c) + " = " + Number(work[j]) +
                             " is outside the float range");
      dst[j] = static_cast<float>(work[j]);
    }
  }
  return cube;
}

CubemapRgb ReconstructLighting(int n, std::span<const LightingTerm> terms) {
  CheckFaceSize(n);
  WaveletLighting l;
  l.n = n;
  const std::size_t size = static_cast<std::size_t>(6) * n * n;
  for (auto& c : l.coefficient) c.assign(size, 0.0);
  for (const LightingTerm& t : terms) {
    if (t.index >= size) throw std::out_of_range("ReconstructLighting: term index out of range");
    for (int c = 0; c < 3; ++c) l.coefficient[c][t.index] += t.value[c];
  }
  return ReconstructLighting(l);
}

std::vector<LightingTerm> ExactLightingTerms(const WaveletLighting& lighting) {
  std::vector<LightingTerm> terms;
  for (std::size_t j = 0; j < lighting.size(); ++j) {
    if (lighting.Magnitude(j) == 0.0) continue;
    terms.push_back(
        {static_cast<uint32_t>(j),
         {lighting.coefficient[0][j], lighting.coefficient[1][j], lighting.coefficient[2][j]}});
  }
  return terms;
}

std::vector<uint32_t> SelectLargest(std::span<const double> weights, std::size_t count) {
  std::vector<uint32_t> candidates;
  candidates.reserve(weights.size());
  for (std::size_t j = 0; j < weights.size(); ++j) {
    if (weights[j] > 0.0) candidates.push_back(static_cast<uint32_t>(j));
  }
  const auto before = [&](uint32_t a, uint32_t b) {
    return weights[a] > weights[b] || (weights[a] == weights[b] && a < b);
  };
  if (count < candidates.size()) {
    std::nth_element(candidates.begin(), candidates.begin() + static_cast<std::ptrdiff_t>(count),
                     candidates.end(), before);
    candidates.resize(count);
  }
  std::sort(candidates.begin(), candidates.end(), before);
  return candidates;
}

std::vector<LightingTerm> NonlinearLightingApproximation(const WaveletLighting& lighting,
                                                         const HaarLightingBasis& basis,
                                                         std::size_t terms, TermRanking ranking) {
  if (basis.n() != lighting.n || basis.size() != lighting.size()) {
    throw std::invalid_argument("NonlinearLightingApproximation: basis and lighting differ in n");
  }
  std::vector<double> weight(lighting.size());
  for (std::size_t j = 0; j < weight.size(); ++j) {
    const double m = lighting.Magnitude(j);
    weight[j] = ranking == TermRanking::kAreaWeighted ? basis.Area(j) * m : m;
  }
  std::vector<uint32_t> chosen = SelectLargest(weight, terms);
  std::sort(chosen.begin(), chosen.end());
  std::vector<LightingTerm> out;
  out.reserve(chosen.size());
  for (uint32_t j : chosen) {
    out.push_back(
        {j, {lighting.coefficient[0][j], lighting.coefficient[1][j], lighting.coefficient[2][j]}});
  }
  return out;
}

double RelativeLightingError(const WaveletLighting& lighting,
                             std::span<const LightingTerm> approximation) {
  std::array<std::vector<double>, 3> diff = lighting.coefficient;
  for (const LightingTerm& t : approximation) {
    if (t.index >= lighting.size()) {
      throw std::out_of_range("RelativeLightingError: term index out of range");
    }
    for (int c = 0; c < 3; ++c) diff[c][t.index] -= t.value[c];
  }
  double num = 0.0, den = 0.0;
  for (int c = 0; c < 3; ++c) {
    for (std::size_t j = 0; j < lighting.size(); ++j) {
      num += diff[c][j] * diff[c][j];
      den += lighting.coefficient[c][j] * lighting.coefficient[c][j];
    }
  }
  return den > 0.0 ? std::sqrt(num / den) : 0.0;
}

}  // namespace prt
