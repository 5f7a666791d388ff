// Dense vertices, angular domain (Huang & Ramamoorthi 2010, §4.2, Figure 3): trace a regular grid
// at half resolution per face axis (1/4 of the texels; AngularOptions::grid_step), then for every
// other texel above the horizon inspect the sampled texels in a 7×7 window: where they disagree
// (non-zero variance) the texel is a feature and is traced; where they agree it borrows their
// value.
//
// The test is made on visibility, not on T: a texel's fractional visibility is
// v_j = T_j / U_j, with U_j the same estimator with visibility ≡ 1 (TransportSampler::
// ComputeTexels' unoccluded output: identical rays), so v_j ∈ [0, 1] is exactly 1 for an
// unoccluded texel. The cosine varies smoothly across a window and would make every variance
// non-zero; the paper's argument ("visibility is a binary function, so we can determine the value
// of a pixel by borrowing if all its neighbours are the same") is about V. A borrowed texel gets
// T_j = v · U_j with its own cosine.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "worker/transport_sampler.h"

namespace prt {

struct DenseRow {
  std::vector<float> transport;   // T, texel_count floats (0 below the horizon)
  std::vector<float> visibility;  // v = T/U in [0, 1] above the horizon, 0 below
  std::vector<uint8_t> feature;   // 1 where the texel was traced in the second (feature) pass
  // Each traced texel's Monte-Carlo variance (TransportSampler::ComputeTexels); 0 where the texel
  // was borrowed or is below the horizon, and everywhere when !sampler.VarianceEstimable().
  std::vector<float> variance;
};

struct AngularStats {
  SampleStats trace;  // rays and texels actually traced
  uint64_t texels_above_horizon = 0;
  uint64_t grid_texels = 0;      // first pass
  uint64_t feature_texels = 0;   // second pass
  uint64_t borrowed_texels = 0;  // filled from neighbours without tracing
  AngularStats& operator+=(const AngularStats& o);
};

struct AngularOptions {
  int window = 7;           // the paper's 7×7 (at a grid step of 2)
  double tolerance = 1e-6;  // |v_a − v_b| above this counts as non-zero variance
  // The first pass's grid step per face axis (0 = 2, the paper's half resolution, 1/4 of the
  // texels), the window scaled by step/2 so that it spans the same solid angle and holds as
  // many grid samples (step 4: 13×13). Measured at n = 64 (docs/sparse-precomputation.md,
  // "n = 64"): step 4 traced 19.6–21.8 % of the dense rows against 32.3–33.4 % for step 2, in
  // the same time (feature texels graze geometry and cost more than grid ones) and with
  // 1.2–1.6× the direct error on the models, so the default stays 2.
  int grid_step = 0;
};
// The grid step and the window's half-width used at cubemap resolution n.
int AngularGridStep(const AngularOptions& options, int n);
int AngularWindowHalf(const AngularOptions& options, int n);

// One dense vertex row by two-pass adaptive angular sampling. Deterministic: traced values are
// bit-identical to TransportSampler::ComputeRow's entries for the same texels.
AngularStats SampleDenseRowAdaptive(const TransportSampler& sampler, const SpatialSample& sample,
                                    uint64_t sample_index, const AngularOptions& options,
                                    DenseRow& out);

// The texels above the sample's horizon (CubemapLayout::AboveHorizonMask of its normal), or, for a
// supersampled camera pixel (SpatialSample::supersampled), above the horizon of any of its
// footprint's sub-samples (fully_above: of every one). Returns the count of `mask`.
std::size_t SampleHorizonMask(const TransportSampler& sampler, const SpatialSample& sample,
                              uint64_t sample_index, uint8_t* mask, uint8_t* fully_above = nullptr);

// Unoccluded values U_j for texels not traced: exact (n·Φ_j/π, CubemapLayout::
// TexelVectorIrradiance) where the texel is entirely above the horizon (fully_above[j] = 1),
// else (and for every texel of a glossy pixel, SpatialSample::glossy_material) the sampler's
// estimate with visibility ≡ 1.
void UnoccludedValues(const TransportSampler& sampler, const SpatialSample& sample,
                      uint64_t sample_index, std::span<const uint32_t> texels,
                      const uint8_t* fully_above, float* values);

// Visibility fractions of a full row: v_j = T_j / U_j above the horizon (U_j > 0), else 0.
void VisibilityOfRow(const TransportSampler& sampler, const SpatialSample& sample,
                     uint64_t sample_index, const float* transport, float* visibility);

}  // namespace prt
