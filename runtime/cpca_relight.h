// Relighting from a clustered-PCA transport (formats/cpca_transport.h), Overbeck et al. 2006
// §6.3: per frame, project the lighting on every cluster's mean and basis (Eq. 7,
// P_{c,i} = u_{c,i}·L̂, using only the lighting's kept terms when it is a non-linear
// approximation), then per row S multiply-adds (Eq. 8, B_r = m_{c}·L̂ + Σ_i w_{r,i} P_{c,i}).
//
//   CpcaRelighter             the two steps; a TransportOperator, so NWA, BI, PBI and every
//                             consumer of a transport can use it "blindly" (§6.3, first paragraph)
//   CpcaIncrementalRelighter  both steps incremental (§6.3): PBI (runtime/per_band_incremental.h)
//                             on the lighting for step 1, through the projection operator, and
//                             the basic incremental update of Eq. 10 for step 2: per cluster only
//                             the `basis_terms` (default S/4) coefficients P_{c,i} that changed
//                             most are brought up to date, U += W·ΔP.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "formats/cpca_transport.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "runtime/relight.h"

namespace prt {

// Step 1 (Eq. 7) as a transport operator: one "sample" per cluster vector, sample c·(S+1) the
// mean of cluster c and c·(S+1) + 1 + i its basis vector i; Accumulate adds u·L̂ per channel.
// A lighting of few terms (NWA) walks only their columns (the vectors stored column by column);
// one of many terms (exact lighting) is scattered into a dense vector once and every cluster
// vector's sparse dot product with it runs in parallel (the vectors stored row by row).
class CpcaProjection final : public TransportOperator {
 public:
  explicit CpcaProjection(const CpcaTransport& t);
  std::size_t sample_count() const override { return vectors_; }
  std::size_t coefficient_count() const override { return columns_; }
  void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const override;
  std::size_t memory_bytes() const {
    return sizeof(uint32_t) * (column_begin_.size() + entry_vector_.size() + vector_begin_.size() +
                               row_column_.size()) +
           sizeof(float) * (entry_value_.size() + row_value_.size());
  }

 private:
  std::size_t vectors_ = 0, columns_ = 0;
  // Column-major (CSC) over the lighting coefficients: column j's entries are (vector, value).
  std::vector<uint32_t> column_begin_;  // columns_ + 1
  std::vector<uint32_t> entry_vector_;
  std::vector<float> entry_value_;
  // Row-major (CSR): vector k's terms are (column, value) in [vector_begin_[k], …[k + 1]).
  std::vector<uint32_t> vector_begin_;  // vectors_ + 1
  std::vector<uint32_t> row_column_;
  std::vector<float> row_value_;
};

class CpcaRelighter final : public TransportOperator {
 public:
  // `name` names the transport in errors. Dequantises everything once.
  explicit CpcaRelighter(const CpcaTransport& t, std::string name = "CpcaRelighter");

  // V spatial samples; 6n² lighting coefficients.
  std::size_t sample_count() const override { return spatial_; }
  std::size_t coefficient_count() const override { return projection_.coefficient_count(); }
  uint32_t channels() const { return channels_; }
  uint32_t clusters() const { return clusters_; }
  uint32_t bases() const { return bases_; }
  const std::string& name() const { return name_; }

  // out += CPCA(T)·L̂ for a list of lighting terms: step 1 then step 2.
  void Accumulate(std::span<const LightingTerm> terms, SampleRadiance& out) const override;
  void Assign(std::span<const LightingTerm> terms, SampleRadiance& out) const override;
  void AccumulateRange(std::span<const LightingTerm> terms, SampleRadiance& out, std::size_t first,
                       std::size_t count, bool assign) const override;

  const CpcaProjection& projection() const { return projection_; }
  // Step 2 (Eq. 8): out (V samples) = Σ over each row's mean and S basis terms of the
  // projection P (K·(S+1) samples, CpcaProjection's layout), overwriting out.
  void Blend(const SampleRadiance& P, SampleRadiance& out) const;
  // The same for samples [first, first + count) of `out` (already sized), written (`assign`) or
  // added; NumericalError naming the sample on a non-finite value.
  void BlendRange(const SampleRadiance& P, SampleRadiance& out, std::size_t first,
                  std::size_t count, bool assign) const;
  // Step 2 for a few changed projection entries (Eq. 10): out += W[:, k]·ΔP_k for every
  // (vector k, ΔP_k) listed; vectors of one cluster touch only that cluster's rows.
  void BlendDelta(std::span<const uint32_t> vectors, std::span<const std::array<double, 3>> delta,
                  SampleRadiance& out) const;
  // Bytes held: the projection's two layouts, the rows' clusters and weights.
  std::size_t memory_bytes() const;
  // The cluster of spatial sample s (in channel 0's rows).
  uint32_t ClusterOf(std::size_t sample) const { return cluster_of_[sample]; }

 private:
  std::string name_;
  uint32_t channels_ = 1, clusters_ = 0, bases_ = 0;
  std::size_t spatial_ = 0;
  CpcaProjection projection_;
  std::vector<uint32_t> cluster_of_;  // per row
  std::vector<float> weights_;        // per row: 1 (the mean) then its S coefficients
  // Rows grouped by cluster: rows_of_cluster_[begin_[c] … begin_[c+1]).
  std::vector<uint32_t> cluster_begin_;
  std::vector<uint32_t> rows_of_cluster_;
};

// Both steps incremental (§6.3). Not thread-safe.
class CpcaIncrementalRelighter {
 public:
  // n: the lighting's cubemap size; lighting_terms: PBI's N per frame; basis_terms: Eq. 10's
  // coefficients per cluster per frame (0: S/4, at least 1). The relighter must outlive this.
  CpcaIncrementalRelighter(const CpcaRelighter& relighter, int n, std::size_t lighting_terms,
                           std::size_t basis_terms = 0);

  // Frame 0: P̃ = P = M·L exactly (a full projection), B = W·P̃.
  void Initialize(const WaveletLighting& lighting);
  // One frame: PBI on the lighting (step 1), then per cluster the basis_terms entries of
  // P − P̃ largest in L1 over the channels (the mean's entry always) applied to B (step 2).
  IncrementalFrame Update(const WaveletLighting& lighting);
  const SampleRadiance& Radiance() const { return image_; }
  std::size_t basis_terms() const { return basis_terms_; }
  // L̃: the lighting step 1 currently represents.
  const WaveletLighting& Represented() const { return step1_.Represented(); }

 private:
  const CpcaRelighter& relighter_;
  PerBandIncrementalRelighter step1_;
  std::size_t basis_terms_;
  SampleRadiance represented_;  // P̃: what B currently holds, per projection entry
  SampleRadiance image_;
};

// Per spatial sample (channel 0's row), an RGB colour for its cluster (Overbeck 2006 Figure 12):
// well-spread hues by a hash of the cluster id, 3 floats per sample in the relighter's order.
std::vector<float> ClusterColours(const CpcaRelighter& relighter);

}  // namespace prt
