// Wavelet lighting: the environment cubemap L in the same orthonormal Haar basis as the rows of
// the transport matrix (vocabulary/wavelets.h, full depth on every face), per colour channel, and
// the non-linear wavelet approximation (NWA) of Ng et al. 2003 that keeps N terms.
//
// A coefficient's "magnitude" is the L1 norm over the three channels, |L_j| = Σ_c |L_j,c|: one
// term carries all three channels, because the three channels share the column T_j.
// Area weighting (Ng et al. 2003 §5; Overbeck et al. 2006 §5.1) ranks a coefficient by
// Area(j)·|L_j|, Area(j) being its support in texels (n² for the scaling function and the
// coarsest wavelets, n²/4 for the next level, … 4 for the finest).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "runtime/relight.h"
#include "vocabulary/envmap.h"

namespace prt {

// Haar coefficients of a lighting cubemap: 6·n² per channel, in the cubemap index layout
// (face·n² + y·n + x), each face transformed to full depth log2 n.
struct WaveletLighting {
  int n = 0;
  std::array<std::vector<double>, 3> coefficient;

  std::size_t size() const { return coefficient[0].size(); }
  // |L_j| = Σ_c |L_j,c|.
  double Magnitude(std::size_t j) const;
};

// Per-coefficient facts for face size n: support area, wavelet level and PBI band.
class HaarLightingBasis {
 public:
  // n: power of two in [1, 256] (std::invalid_argument otherwise).
  explicit HaarLightingBasis(int n);

  int n() const { return n_; }
  std::size_t size() const { return area_.size(); }
  // Support area of coefficient j in texels.
  double Area(std::size_t j) const { return area_[j]; }
  // Wavelet level: 0 = scaling, 1 = coarsest detail … log2 n = finest (vocabulary/wavelets.h).
  int Level(std::size_t j) const { return level_[j]; }
  // PBI band (Overbeck et al. §5.1): wavelets grouped by support area, the scaling function
  // together with the coarsest wavelets; band 0 = area n², band b = area n²/4^b,
  // band_count() = max(1, log2 n).
  int Band(std::size_t j) const { return band_[j]; }
  int band_count() const { return static_cast<int>(members_.size()); }
  // Coefficient indices in band b, increasing.
  const std::vector<uint32_t>& BandMembers(int band) const { return members_[band]; }

 private:
  int n_;
  std::vector<double> area_;
  std::vector<uint8_t> level_;
  std::vector<uint8_t> band_;
  std::vector<std::vector<uint32_t>> members_;
};

// Forward Haar transform of a lighting cubemap (average radiance per texel), computed in double
// from the float texels (no rounding to float on the way: a face's scaling coefficient, n × its
// mean, may exceed the float range, and a 10⁷ sun next to a sky of 1 keeps the sky's digits).
// Throws std::invalid_argument if n is not a power of two in [1, 256] or the channels are not
// 6·n² long, NumericalError naming the texel on a NaN/Inf texel. Every coefficient of a finite
// cubemap is finite.
WaveletLighting ProjectLighting(const CubemapRgb& cube);
// Inverse (in double): texel radiance of a lighting vector, or of a list of terms on an n×n
// cubemap. Throws NumericalError naming the texel when a texel is outside the float range.
CubemapRgb ReconstructLighting(const WaveletLighting& lighting);
CubemapRgb ReconstructLighting(int n, std::span<const LightingTerm> terms);

// Every non-zero coefficient as a term, in index order (exact relighting).
std::vector<LightingTerm> ExactLightingTerms(const WaveletLighting& lighting);

enum class TermRanking {
  kAreaWeighted,  // Area(j)·|L_j| (Ng et al. 2003, the default)
  kMagnitude,     // |L_j|
};

// Non-linear wavelet approximation (Ng et al. 2003; Overbeck et al. 2006 Eq. 2): the `terms`
// non-zero coefficients of largest ranking weight (ties broken by lower index), in index order.
// terms ≥ the number of non-zero coefficients gives ExactLightingTerms.
std::vector<LightingTerm> NonlinearLightingApproximation(
    const WaveletLighting& lighting, const HaarLightingBasis& basis, std::size_t terms,
    TermRanking ranking = TermRanking::kAreaWeighted);

// Indices of the `count` largest weights (weight > 0 only; ties → lower index first), in
// decreasing weight order. Shared by NWA, BI and PBI.
std::vector<uint32_t> SelectLargest(std::span<const double> weights, std::size_t count);

// Relative L2 error ‖L − L̂‖ / ‖L‖ over all channels and coefficients (equal to the texel-space
// error, the transform being orthonormal); 0 when L = 0.
double RelativeLightingError(const WaveletLighting& lighting,
                             std::span<const LightingTerm> approximation);

}  // namespace prt
