// Incremental relighting under animated lighting (Overbeck, Ben-Artzi, Ramamoorthi & Grinspun
// 2006): each frame spends a budget of N lighting terms on the CHANGE of the lighting instead of
// the lighting itself, B^new = B^old + T·ΔL (Eq. 3–6), touching only N columns of T.
//
//   BasicIncrementalRelighter    BI, §3: ΔL = Approx(L^new − L̃) with N area-weighted terms.
//   PerBandIncrementalRelighter  PBI, §5 / Figure 6: bands by wavelet level (lighting.h), each
//                                band updated incrementally or reset by the L1 test of §5.2.2, one
//                                image per band, a global budget of N terms per frame ranked by
//                                Area(j)·|ΔL_j| in incremental bands and Area(j)·|L_j^new| in
//                                reset bands.
//
// No drift: L̃ holds the exact coefficients currently represented (each chosen coefficient is set
// to L^new_j, never accumulated), and the images accumulate T·ΔL in double, so B stays T·L̃ to
// rounding (≈1e-12 relative after 10⁴ frames); Rederive() recomputes the images from L̃ when a
// caller wants a hard guarantee. With static lighting both converge to the exact T·L in at most
// ⌈(non-zero coefficients) / N⌉ frames (PBI: no band is ever reset while L is static).
//
// The transport passed in must outlive the relighter. Not thread-safe; Accumulate inside is
// parallel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "runtime/lighting.h"
#include "runtime/relight.h"

namespace prt {

// What one frame did.
struct IncrementalFrame {
  std::size_t terms = 0;            // lighting terms applied (≤ the budget)
  std::vector<uint8_t> band_reset;  // PBI: 1 for a band updated non-incrementally (Fig. 6 l. 14)
  bool exact = false;               // L̃ equals L^new in every coefficient after the frame
};

// One frame's decisions apart from its work on the images, so that a host can split the work
// into ranges of samples across its threads (prt_runtime_relight_range): Plan chooses the terms
// and moves L̃ (on one thread); Apply then updates the images for samples [first, first + count)
// (concurrently for disjoint ranges; every sample exactly once per plan). Update is Plan then
// Apply over every sample, with the whole-frame operator (the same numbers as before the split).
struct IncrementalStep {
  IncrementalFrame frame;
  std::vector<std::vector<LightingTerm>> band_terms;  // ΔL per band (BI: one band)
};

class BasicIncrementalRelighter {
 public:
  // n: cubemap face size of the lighting; transport.coefficient_count() must be 6·n².
  BasicIncrementalRelighter(const TransportOperator& transport, int n, std::size_t terms_per_frame);

  // L̃ = L and B = T·L (the paper's frame 0, a full multiply).
  void Initialize(const WaveletLighting& lighting);
  // L̃ = 0, B = 0.
  void Clear();
  // One frame: Eq. 5, 6, 4, 3.
  IncrementalFrame Update(const WaveletLighting& lighting);
  // Eq. 5 and 6 (the terms, L̃ += ΔL), then Eq. 4 and 3 for a range (B += T·ΔL there).
  IncrementalStep Plan(const WaveletLighting& lighting);
  void Apply(const IncrementalStep& step, std::size_t first, std::size_t count);
  // Recomputes B = T·L̃ from scratch.
  void Rederive();

  const SampleRadiance& Radiance() const { return image_; }
  const WaveletLighting& Represented() const { return represented_; }
  std::size_t terms_per_frame() const { return budget_; }

 private:
  const TransportOperator& transport_;
  HaarLightingBasis basis_;
  std::size_t budget_;
  WaveletLighting represented_;
  SampleRadiance image_;
};

class PerBandIncrementalRelighter {
 public:
  PerBandIncrementalRelighter(const TransportOperator& transport, int n,
                              std::size_t terms_per_frame);

  void Initialize(const WaveletLighting& lighting);
  void Clear();
  // One frame of Figure 6 with the simple per-band L1 test (§5.2.2).
  IncrementalFrame Update(const WaveletLighting& lighting);
  // Figure 6's decisions (bands reset, the N terms, L̃), then its image work for a range: reset
  // bands' images zeroed there, B_i += T·ΔL_i there, and B = Σ_i B_i composed there (Composed()).
  IncrementalStep Plan(const WaveletLighting& lighting);
  void Apply(const IncrementalStep& step, std::size_t first, std::size_t count);
  // B as the last Apply calls composed it (valid in the ranges they covered).
  const SampleRadiance& Composed() const { return composed_; }
  // Recomputes every band image B_i = T·L̃_{band i} from scratch.
  void Rederive();

  // B = Σ_i B_i (Figure 6 line 20), composed when first asked for after an update.
  const SampleRadiance& Radiance();
  const SampleRadiance& BandImage(int band) const { return band_image_[band]; }
  const WaveletLighting& Represented() const { return represented_; }
  const HaarLightingBasis& basis() const { return basis_; }
  std::size_t terms_per_frame() const { return budget_; }

 private:
  const TransportOperator& transport_;
  HaarLightingBasis basis_;
  std::size_t budget_;
  WaveletLighting represented_;
  std::vector<SampleRadiance> band_image_;
  SampleRadiance composed_;
  bool composed_valid_ = false;
};

}  // namespace prt
