// Worker kernel: per-vertex visibility cubemaps for triple-product relighting (Inger, Farbman &
// Lischinski 2013, §4 and §4.2), traced with Embree and stored in the block-differential
// representation of formats/visibility_blocks.h.
//
// Binary maps (bits = 1, supersample = 1): one occlusion ray through each texel centre,
// V = 1 when it escapes. Anti-aliased maps (§4.2, Figure 3): a supersample×supersample grid of
// rays through the centres of the sub-texels of each texel (a binary map at supersample·n,
// box-filtered and downsampled), the visible fraction quantised to bits bits:
// level = round(fraction · (2^bits − 1)). Directions at or below the shading normal's horizon
// (n·ω ≤ 0) are 0 without tracing (the cosine folded into the BRDF is zero there), which is what
// makes half the blocks of every map all-zero. Rays leave from EmbreeScene::RobustOrigin.
// Deterministic (no randomness) and independent of the thread count.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "formats/visibility_blocks.h"
#include "vocabulary/cubemap.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

namespace prt {

struct VisibilitySamplerOptions {
  int n = 64;           // cubemap resolution: a multiple of 16 in [16, 256] (64 and 128 in §4)
  int supersample = 1;  // rays per texel side, [1, 16]
  int bits = 1;         // levels 0 … 2^bits − 1, [1, 8]; binary when 1
};

struct VisibilitySamplerStats {
  uint64_t rays_traced = 0;
  uint64_t texels_below_horizon = 0;  // texel centres with n·ω ≤ 0, not traced
};

// Thread-safe after construction; the scene must outlive it.
class VisibilitySampler {
 public:
  // Throws std::invalid_argument on options outside their ranges.
  VisibilitySampler(const EmbreeScene& scene, VisibilitySamplerOptions options);

  const VisibilitySamplerOptions& options() const { return options_; }
  const CubemapLayout& layout() const { return layout_; }

  // One vertex's map: 6·n·n levels in texel order into `levels`. Throws prt::NumericalError on
  // a non-finite position or a zero/non-finite normal.
  VisibilitySamplerStats ComputeMap(const SpatialSample& sample, std::span<uint8_t> levels) const;

  // Maps of all samples in block-differential form, in sample order; parallel over samples
  // (TBB, fixed chunks merged in order, so the result does not depend on the thread count).
  VisibilityBlocks ComputeBlocks(std::span<const SpatialSample> samples,
                                 VisibilitySamplerStats* stats = nullptr) const;

 private:
  const EmbreeScene& scene_;
  VisibilitySamplerOptions options_;
  CubemapLayout layout_;
  std::vector<float> directions_;  // 3 floats per sub-texel ray, texel-major
};

}  // namespace prt
