// Relighting B = albedo ⊙ (T·L̂) (Ng et al. 2003 Eq. 1; Overbeck et al. 2006 Eq. 1–4) for a light
// transport T given in the orthonormal Haar basis of the lighting cubemap (vocabulary/wavelets.h):
// since the transform is orthonormal, T·L over texels equals (T Wᵀ)·(W L) over coefficients.
//
// T is albedo-free (worker/transport_sampler.h): radiance per sample is (T·L̂) per colour channel,
// and the albedo multiplies it at the end (ShadeSamples). A lighting approximation L̂ is a short
// list of terms (coefficient index, RGB value); every operator applies only the columns its terms
// name, so an incremental update B += T·ΔL̂ costs N columns, not the whole matrix.
//
// TransportOperator is the seam where other representations plug in: DenseTransport and
// SparseTransport here, CompressedTransportOperator for the adaptive 4D compressed columns of
// runtime/compressed_relight.h (Cheslack-Postava et al. 2008 Eq. 8).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "runtime/compressed_relight.h"
#include "vocabulary/scene.h"

namespace prt {

// One term of a lighting approximation: a Haar coefficient index and its value per channel.
struct LightingTerm {
  uint32_t index = 0;
  std::array<double, 3> value{0.0, 0.0, 0.0};
};

// Outgoing radiance per spatial sample, one array per colour channel, accumulated in double so
// that long sums of incremental updates do not drift.
struct SampleRadiance {
  std::array<std::vector<double>, 3> channel;

  SampleRadiance() = default;
  explicit SampleRadiance(std::size_t samples);
  std::size_t size() const { return channel[0].size(); }
  void SetZero();
  SampleRadiance& operator+=(const SampleRadiance& other);
};

// A light transport operator: sample_count() spatial samples, coefficient_count() Haar columns.
// T has one row per sample (one colour channel: the same row for r, g and b) or, with 3 colour
// channels, one row per sample and channel (channel-major: row c·samples + s is channel c of
// sample s); either way its radiance is per sample, channel c lit by lighting channel c.
class TransportOperator {
 public:
  virtual ~TransportOperator() = default;
  virtual std::size_t sample_count() const = 0;
  virtual std::size_t coefficient_count() const = 0;

  // out.channel[c][s] += Σ_k T_c[s][terms[k].index] · terms[k].value[c] for every sample s,
  // T_c[s] the row of sample s (one channel) or of its colour channel c (three channels).
  // out must have sample_count() samples; every index must be < coefficient_count() (throws
  // std::out_of_range otherwise). Repeated indices are allowed (their values add).
  virtual void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const = 0;

  // out = T·L̂: out is resized to sample_count() and its previous values are overwritten, not
  // read (a frame loop that keeps `out` pays no clearing pass). Same checks as Accumulate.
  virtual void Assign(std::span<const LightingTerm> terms, SampleRadiance& out) const;

  // T·L̂ for a lighting approximation, from zero.
  SampleRadiance Apply(std::span<const LightingTerm> terms) const;

  // Samples [first, first + count) only (out already has sample_count() samples; the rest is
  // neither read nor written): added, or with `assign` written. The same values as Accumulate /
  // Assign there, to float rounding. Concurrent calls with disjoint ranges of one `out` are
  // safe. This default computes every sample and keeps the range; the compressed and CPCA
  // operators override it with work proportional to the range (prt_runtime_relight_range).
  virtual void AccumulateRange(std::span<const LightingTerm> terms, SampleRadiance& out,
                               std::size_t first, std::size_t count, bool assign) const;
};

// Dense rows: T stored in blocks of kBlockSamples samples, column-major inside a block, so that
// applying one term is a contiguous, vectorisable axpy over the block. Blocks run in parallel
// (vocabulary/parallel.h).
class DenseTransport final : public TransportOperator {
 public:
  static constexpr std::size_t kBlockSamples = 256;

  // rows: channels × samples × coefficients floats, row-major (one Haar-transformed row per
  // sample, or with channels = 3 per sample and colour channel, row c·samples + s).
  // Throws std::invalid_argument on a size mismatch, channels other than 1 or 3, or a NaN/Inf.
  DenseTransport(std::span<const float> rows, std::size_t samples, std::size_t coefficients,
                 uint32_t channels = 1);

  std::size_t sample_count() const override { return samples_; }
  std::size_t coefficient_count() const override { return coefficients_; }
  uint32_t channels() const { return channels_; }
  void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const override;

 private:
  std::size_t samples_;
  std::size_t coefficients_;
  uint32_t channels_;
  // [channel][block][coefficient][sample in block], zero-padded
  std::vector<float> blocks_;
};

// Sparse rows (CSR: row_offsets has samples + 1 entries, indices/values hold the non-zeros of each
// row). Stored as one compressed-column block per kBlockSamples samples, so a term visits only the
// non-zeros of its column; blocks run in parallel (vocabulary/parallel.h).
class SparseTransport final : public TransportOperator {
 public:
  static constexpr std::size_t kBlockSamples = 1024;

  // With channels = 3 the rows are channel-major (row c·samples + s), row_offsets has
  // 3·samples + 1 entries. Throws std::invalid_argument on inconsistent offsets, a row count
  // that is not a multiple of channels (1 or 3), an index ≥ coefficients, or NaN/Inf.
  SparseTransport(std::span<const uint64_t> row_offsets, std::span<const uint32_t> indices,
                  std::span<const float> values, std::size_t coefficients, uint32_t channels = 1);

  std::size_t sample_count() const override { return samples_; }
  std::size_t coefficient_count() const override { return coefficients_; }
  std::size_t nonzero_count() const { return values_.size(); }
  uint32_t channels() const { return channels_; }
  void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const override;

 private:
  std::size_t samples_;
  std::size_t coefficients_;
  uint32_t channels_;
  // [(channel · blocks + block) · (coefficients + 1) + column]
  std::vector<uint64_t> column_start_;
  std::vector<uint16_t> local_sample_;  // sample within its block
  std::vector<float> values_;
};

// Relighting straight from adaptively compressed columns (Cheslack-Postava et al. 2008 §4.5,
// Eq. 8) through runtime/compressed_relight.h. The relighter must outlive the operator and
// its row wavelet must be Haar (the lighting basis here; std::invalid_argument otherwise).
// Lighting values pass to the compressed path in float, and its radiance comes back in float:
// expect 1–2e-7 relative rounding per Accumulate of tens of terms, ~2e-6 for all 6,144 of n = 32
// (the incremental state stays in double; docs/viewer.md, "High dynamic range"). A term
// whose value is outside the float range, or a relight that overflows the relighter's float
// accumulation, throws NumericalError naming the relighter's name() (the pack); after that
// exception `out` may hold non-finite values and must be discarded.
// A 3-channel compressed transport relights channel c of each sample from its channel-c row
// (sample_count() is the relighter's V, not its rows).
// Its outputs are in the relighter's sample order `order` (runtime/compressed_relight.h):
// kSamples, the pack's order, or kCoefficients, the depth-0 coefficient layout, which spares the
// frame the gather through the Hilbert permutation (ViewerSession renders in that order).
class CompressedTransportOperator final : public TransportOperator {
 public:
  explicit CompressedTransportOperator(const CompressedRelighter& relighter,
                                       SampleOrder order = SampleOrder::kSamples);

  std::size_t sample_count() const override;
  std::size_t coefficient_count() const override;
  void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const override;
  void Assign(std::span<const LightingTerm> terms, SampleRadiance& out) const override;
  // A range of SampleOrder::kCoefficients positions (RelightSparseAddRange); in kSamples order
  // the default (every sample computed).
  void AccumulateRange(std::span<const LightingTerm> terms, SampleRadiance& out, std::size_t first,
                       std::size_t count, bool assign) const override;

 private:
  // The terms as the relighter takes them: columns and float weights (3 per term).
  void Weights(std::span<const LightingTerm> terms, std::vector<uint32_t>& columns,
               std::vector<float>& weights) const;
  void Relight(std::span<const LightingTerm> terms, SampleRadiance& out, bool assign) const;
  const CompressedRelighter& relighter_;
  SampleOrder order_;
};

// Final colours: albedo ⊙ radiance, interleaved RGB float per sample (T is albedo-free at the
// receiving sample for any number of channels: a 3-channel T carries the albedos of the surfaces
// the light bounced off, not of the sample it reaches). albedo may be empty (white),
// hold one colour (uniform) or one per sample (else std::invalid_argument). A colour that is not
// a finite float (radiance NaN/Inf, or a finite double beyond 3.4e38: finite T and L whose product
// overflows float) throws NumericalError naming `source` (the pack) and the sample, as
// sample_name[s] when given (ViewerSession: the pack's sample number), else s; nothing is
// replaced by 0 (docs/viewer.md, "NaN and Inf").
std::vector<float> ShadeSamples(const SampleRadiance& radiance, std::span<const Rgb> albedo,
                                const std::string& source = "ShadeSamples",
                                std::span<const uint32_t> sample_name = {});

// Throws NumericalError naming `source`, the coefficient and the channel unless |value| fits in
// float: the compressed relighter takes its lighting in float (Eq. 8's weights).
void CheckFloatLighting(double value, std::size_t coefficient, int channel,
                        const std::string& source);

}  // namespace prt
