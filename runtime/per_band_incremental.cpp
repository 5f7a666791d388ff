// Basic incremental (BI, Overbeck et al. 2006 §3, Eq. 3–6) and per-band incremental (PBI, §5,
// Figure 6, with the simple per-band L1 test of §5.2.2) wavelet lighting for relighting.
#include "runtime/per_band_incremental.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "vocabulary/parallel.h"

namespace prt {

namespace {

void CheckSizes(const TransportOperator& transport, int n) {
  const std::size_t expected = static_cast<std::size_t>(6) * n * n;
  if (transport.coefficient_count() != expected) {
    throw std::invalid_argument(
        "incremental relighting: transport has " + std::to_string(transport.coefficient_count()) +
        " columns, lighting n = " + std::to_string(n) + " needs " + std::to_string(expected));
  }
}

void CheckLighting(const WaveletLighting& l, const HaarLightingBasis& basis) {
  if (l.n != basis.n() || l.size() != basis.size() || l.coefficient[1].size() != l.size() ||
      l.coefficient[2].size() != l.size()) {
    throw std::invalid_argument("incremental relighting: lighting n = " + std::to_string(l.n) +
                                ", relighter built for n = " + std::to_string(basis.n()));
  }
}

WaveletLighting ZeroLighting(int n) {
  WaveletLighting l;
  l.n = n;
  for (auto& c : l.coefficient) c.assign(static_cast<std::size_t>(6) * n * n, 0.0);
  return l;
}

// Σ_c |a_c − b_c| for coefficient j.
double DifferenceMagnitude(const WaveletLighting& a, const WaveletLighting& b, std::size_t j) {
  return std::abs(a.coefficient[0][j] - b.coefficient[0][j]) +
         std::abs(a.coefficient[1][j] - b.coefficient[1][j]) +
         std::abs(a.coefficient[2][j] - b.coefficient[2][j]);
}

bool SameLighting(const WaveletLighting& a, const WaveletLighting& b) {
  return a.coefficient == b.coefficient;
}

// Terms T·L̃ restricted to the given coefficients (non-zero ones only).
std::vector<LightingTerm> TermsOf(const WaveletLighting& l, const std::vector<uint32_t>& which) {
  std::vector<LightingTerm> terms;
  for (uint32_t j : which) {
    if (l.Magnitude(j) == 0.0) continue;
    terms.push_back({j, {l.coefficient[0][j], l.coefficient[1][j], l.coefficient[2][j]}});
  }
  return terms;
}

}  // namespace

// ---- BI ------------------------------------------------------------------------------------

BasicIncrementalRelighter::BasicIncrementalRelighter(const TransportOperator& transport, int n,
                                                     std::size_t terms_per_frame)
    : transport_(transport), basis_(n), budget_(terms_per_frame) {
  CheckSizes(transport, n);
  Clear();
}

void BasicIncrementalRelighter::Clear() {
  represented_ = ZeroLighting(basis_.n());
  image_ = SampleRadiance(transport_.sample_count());
}

void BasicIncrementalRelighter::Initialize(const WaveletLighting& lighting) {
  CheckLighting(lighting, basis_);
  represented_ = lighting;
  Rederive();
}

void BasicIncrementalRelighter::Rederive() {
  image_ = transport_.Apply(ExactLightingTerms(represented_));
}

IncrementalStep BasicIncrementalRelighter::Plan(const WaveletLighting& lighting) {
  CheckLighting(lighting, basis_);
  // Eq. 5: ΔL = Approx(L^new − L̃), the N largest area-weighted differences.
  std::vector<double> weight(basis_.size());
  for (std::size_t j = 0; j < weight.size(); ++j) {
    weight[j] = basis_.Area(j) * DifferenceMagnitude(lighting, represented_, j);
  }
  std::vector<uint32_t> chosen = SelectLargest(weight, budget_);
  std::sort(chosen.begin(), chosen.end());
  IncrementalStep step;
  step.band_terms.resize(1);
  std::vector<LightingTerm>& delta = step.band_terms[0];
  delta.reserve(chosen.size());
  for (uint32_t j : chosen) {
    LightingTerm t{j, {}};
    for (int c = 0; c < 3; ++c) {
      t.value[c] = lighting.coefficient[c][j] - represented_.coefficient[c][j];
      // Eq. 6, L̃ += ΔL, written as an assignment so that L̃ holds L^new_j exactly.
      represented_.coefficient[c][j] = lighting.coefficient[c][j];
    }
    delta.push_back(t);
  }
  step.frame.terms = delta.size();
  step.frame.exact = SameLighting(represented_, lighting);
  return step;
}

void BasicIncrementalRelighter::Apply(const IncrementalStep& step, std::size_t first,
                                      std::size_t count) {
  // Eq. 4 and 3: B += T·ΔL on the range.
  if (!step.band_terms.empty() && !step.band_terms[0].empty())
    transport_.AccumulateRange(step.band_terms[0], image_, first, count, false);
}

IncrementalFrame BasicIncrementalRelighter::Update(const WaveletLighting& lighting) {
  const IncrementalStep step = Plan(lighting);
  // Eq. 4 and 3: B += T·ΔL.
  transport_.Accumulate(step.band_terms[0], image_);
  return step.frame;
}

// ---- PBI -----------------------------------------------------------------------------------

PerBandIncrementalRelighter::PerBandIncrementalRelighter(const TransportOperator& transport, int n,
                                                         std::size_t terms_per_frame)
    : transport_(transport), basis_(n), budget_(terms_per_frame) {
  CheckSizes(transport, n);
  Clear();
}

void PerBandIncrementalRelighter::Clear() {
  represented_ = ZeroLighting(basis_.n());
  band_image_.assign(static_cast<std::size_t>(basis_.band_count()),
                     SampleRadiance(transport_.sample_count()));
  composed_valid_ = false;
}

void PerBandIncrementalRelighter::Initialize(const WaveletLighting& lighting) {
  CheckLighting(lighting, basis_);
  represented_ = lighting;
  Rederive();
}

void PerBandIncrementalRelighter::Rederive() {
  for (int b = 0; b < basis_.band_count(); ++b) {
    band_image_[b] = transport_.Apply(TermsOf(represented_, basis_.BandMembers(b)));
  }
  composed_valid_ = false;
}

IncrementalStep PerBandIncrementalRelighter::Plan(const WaveletLighting& lighting) {
  CheckLighting(lighting, basis_);
  const int bands = basis_.band_count();
  IncrementalStep step;
  IncrementalFrame& frame = step.frame;
  frame.band_reset.assign(static_cast<std::size_t>(bands), 0);

  // SetupBands(), Figure 6 lines 1–4. IsIncr_i (§5.2.2): incremental when the band is closer, in
  // the L1 norm, to the current approximation than to zero: ‖L^new − L̃‖₁ ≤ ‖L^new‖₁.
  for (int b = 0; b < bands; ++b) {
    double change = 0.0, value = 0.0;
    for (uint32_t j : basis_.BandMembers(b)) {
      change += DifferenceMagnitude(lighting, represented_, j);
      value += lighting.Magnitude(j);
    }
    frame.band_reset[b] = change > value ? 1 : 0;
  }
  // W^i: one global budget of N terms, ranked by Area(j)·|ΔL_j| in incremental bands and by
  // Area(j)·|L^new_j| in bands being reset (§5.1).
  std::vector<double> weight(basis_.size());
  for (std::size_t j = 0; j < weight.size(); ++j) {
    const double m = frame.band_reset[basis_.Band(j)]
                         ? lighting.Magnitude(j)
                         : DifferenceMagnitude(lighting, represented_, j);
    weight[j] = basis_.Area(j) * m;
  }
  std::vector<uint32_t> chosen = SelectLargest(weight, budget_);
  std::sort(chosen.begin(), chosen.end());
  frame.terms = chosen.size();

  // Lines 13–14: a reset band starts again from zero (its lights here, its image in Apply).
  for (int b = 0; b < bands; ++b) {
    if (!frame.band_reset[b]) continue;
    for (uint32_t j : basis_.BandMembers(b)) {
      for (int c = 0; c < 3; ++c) represented_.coefficient[c][j] = 0.0;
    }
  }
  // Lines 8–11 (incremental: ΔL_j = L^new_j − L̃_j) and 15–17 (reset: L̃_j was just zeroed, so
  // the same difference is L^new_j); then L̃_j = L^new_j (lines 10, 16).
  std::vector<std::vector<LightingTerm>>& band_terms = step.band_terms;
  band_terms.resize(static_cast<std::size_t>(bands));
  for (uint32_t j : chosen) {
    LightingTerm t{j, {}};
    for (int c = 0; c < 3; ++c) {
      t.value[c] = lighting.coefficient[c][j] - represented_.coefficient[c][j];
      represented_.coefficient[c][j] = lighting.coefficient[c][j];
    }
    band_terms[basis_.Band(j)].push_back(t);
  }
  composed_valid_ = false;
  const std::size_t samples = transport_.sample_count();
  if (composed_.size() != samples) composed_ = SampleRadiance(samples);
  frame.exact = SameLighting(represented_, lighting);
  return step;
}

void PerBandIncrementalRelighter::Apply(const IncrementalStep& step, std::size_t first,
                                        std::size_t count) {
  const int bands = basis_.band_count();
  for (int b = 0; b < bands; ++b) {
    SampleRadiance& image = band_image_[b];
    // Line 14 on the range, then lines 11 and 17: B_i += T_j ΔL_j (written over a reset band).
    const bool reset = step.frame.band_reset[b] != 0;
    if (!step.band_terms[b].empty()) {
      transport_.AccumulateRange(step.band_terms[b], image, first, count, reset);
    } else if (reset) {
      for (auto& c : image.channel) std::fill_n(c.data() + first, count, 0.0);
    }
  }
  // Line 20 on the range: B = Σ_i B_i.
  for (int c = 0; c < 3; ++c) {
    double* __restrict out = composed_.channel[c].data();
    for (std::size_t s = first; s != first + count; ++s) out[s] = 0.0;
    for (const SampleRadiance& band : band_image_) {
      const double* __restrict in = band.channel[c].data();
      for (std::size_t s = first; s != first + count; ++s) out[s] += in[s];
    }
  }
}

IncrementalFrame PerBandIncrementalRelighter::Update(const WaveletLighting& lighting) {
  const IncrementalStep step = Plan(lighting);
  for (int b = 0; b < basis_.band_count(); ++b) {
    // Line 14: a reset band's image starts again from zero; lines 11 and 17: B_i += T_j ΔL_j.
    if (step.frame.band_reset[b]) band_image_[b].SetZero();
    if (!step.band_terms[b].empty()) transport_.Accumulate(step.band_terms[b], band_image_[b]);
  }
  return step.frame;
}

const SampleRadiance& PerBandIncrementalRelighter::Radiance() {
  if (composed_valid_) return composed_;
  const std::size_t samples = transport_.sample_count();
  if (composed_.size() != samples) composed_ = SampleRadiance(samples);
  // Line 20: B = Σ_i B_i.
  ParallelForRange(0, samples, 4096, [&](std::size_t range_begin, std::size_t range_end) {
    for (int c = 0; c < 3; ++c) {
      double* __restrict out = composed_.channel[c].data();
      for (std::size_t s = range_begin; s != range_end; ++s) out[s] = 0.0;
      for (const SampleRadiance& band : band_image_) {
        const double* __restrict in = band.channel[c].data();
        for (std::size_t s = range_begin; s != range_end; ++s) out[s] += in[s];
      }
    }
  });
  composed_valid_ = true;
  return composed_;
}

}  // namespace prt
