// Wavelet lighting and its non-linear approximation (Ng et al. 2003 §5, "non-linear wavelet
// lighting approximation" with area-weighted selection; Overbeck et al. 2006 §3 Eq. 2, §5.1).
#include "viewer/lighting.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <stdexcept>
#include <string>

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
  const int depth = CheckFaceSize(cube.n);
  const std::size_t texels = cube.TexelCount();
  WaveletLighting out;
  out.n = cube.n;
  std::vector<float> work;
  for (int c = 0; c < 3; ++c) {
    const std::vector<float>& src = cube.Channel(c);
    if (src.size() != texels) {
      throw std::invalid_argument("ProjectLighting: channel " + std::to_string(c) + " has " +
                                  std::to_string(src.size()) + " texels, expected " +
                                  std::to_string(texels));
    }
    work.assign(src.begin(), src.end());
    ForwardHaarCubemap(work.data(), cube.n, depth);
    out.coefficient[c].resize(texels);
    for (std::size_t j = 0; j < texels; ++j) {
      out.coefficient[c][j] = std::isfinite(work[j]) ? static_cast<double>(work[j]) : 0.0;
    }
  }
  return out;
}

CubemapRgb ReconstructLighting(const WaveletLighting& lighting) {
  const int depth = CheckFaceSize(lighting.n);
  CubemapRgb cube;
  cube.n = lighting.n;
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& dst = cube.Channel(c);
    dst.resize(cube.TexelCount());
    if (lighting.coefficient[c].size() != dst.size()) {
      throw std::invalid_argument("ReconstructLighting: wrong coefficient count");
    }
    for (std::size_t j = 0; j < dst.size(); ++j) {
      dst[j] = static_cast<float>(lighting.coefficient[c][j]);
    }
    InverseHaarCubemap(dst.data(), cube.n, depth);
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
