#include "worker/visibility_sampler.h"

#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"

namespace prt {

VisibilitySampler::VisibilitySampler(const EmbreeScene& scene, VisibilitySamplerOptions options)
    : scene_(scene), options_(options), layout_([&] {
        if (options.n < 16 || options.n > 256 || options.n % 16 != 0)
          throw std::invalid_argument("VisibilitySampler: n must be a multiple of 16 in [16, 256]");
        if (options.supersample < 1 || options.supersample > 16)
          throw std::invalid_argument("VisibilitySampler: supersample outside [1, 16]");
        if (options.bits < 1 || options.bits > 8)
          throw std::invalid_argument("VisibilitySampler: bits outside [1, 8]");
        return options.n;
      }()) {
  const int s = options_.supersample;
  const std::size_t texels = layout_.texel_count();
  directions_.resize(texels * s * s * 3);
  for (std::size_t j = 0; j < texels; ++j) {
    for (int sy = 0; sy < s; ++sy) {
      for (int sx = 0; sx < s; ++sx) {
        const Vec3 d = layout_.TexelDirection(j, (sx + 0.5) / s, (sy + 0.5) / s);
        float* out = &directions_[((j * s + sy) * s + sx) * 3];
        out[0] = static_cast<float>(d.x);
        out[1] = static_cast<float>(d.y);
        out[2] = static_cast<float>(d.z);
      }
    }
  }
}

VisibilitySamplerStats VisibilitySampler::ComputeMap(const SpatialSample& sample,
                                                     std::span<uint8_t> levels) const {
  if (levels.size() != layout_.texel_count())
    throw std::invalid_argument("VisibilitySampler::ComputeMap: wrong map size");
  const double nl = Length(sample.normal);
  if (!IsFinite(sample.position) || !IsFinite(sample.normal) || !(nl > 0))
    throw NumericalError("VisibilitySampler: non-finite position or zero normal");
  const Vec3 nrm = sample.normal / nl;
  Vec3 gn = Normalize(sample.geometric_normal);
  if (!IsFinite(gn) || Length(gn) == 0) gn = nrm;
  OcclusionRay ray{};
  scene_.RobustOrigin(sample.position, gn, ray.origin);
  ray.tnear = 0.f;
  ray.tfar = std::numeric_limits<float>::infinity();
  const int s = options_.supersample;
  const int ss = s * s;
  const int max_level = (1 << options_.bits) - 1;
  VisibilitySamplerStats st;
  const ScopedFlushDenormals ftz;
  for (std::size_t j = 0; j < levels.size(); ++j) {
    int visible = 0, above = 0;
    for (int i = 0; i < ss; ++i) {
      const float* d = &directions_[(j * ss + i) * 3];
      if (nrm.x * d[0] + nrm.y * d[1] + nrm.z * d[2] <= 0) continue;
      ++above;
      ray.direction[0] = d[0];
      ray.direction[1] = d[1];
      ray.direction[2] = d[2];
      ++st.rays_traced;
      if (!scene_.Occluded(ray)) ++visible;
    }
    if (above == 0) ++st.texels_below_horizon;
    levels[j] = static_cast<uint8_t>(
        std::lround(static_cast<double>(visible) * max_level / static_cast<double>(ss)));
  }
  return st;
}

VisibilityBlocks VisibilitySampler::ComputeBlocks(std::span<const SpatialSample> samples,
                                                  VisibilitySamplerStats* stats) const {
  constexpr std::size_t kChunk = 32;
  const std::size_t chunks = (samples.size() + kChunk - 1) / kChunk;
  std::vector<VisibilityBlocks> parts(chunks);
  std::vector<VisibilitySamplerStats> part_stats(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    VisibilityBlocks part = MakeVisibilityBlocks(options_.n, options_.bits);
    std::vector<uint8_t> map(layout_.texel_count());
    const std::size_t last = std::min(samples.size(), (c + 1) * kChunk);
    for (std::size_t i = c * kChunk; i < last; ++i) {
      const VisibilitySamplerStats st = ComputeMap(samples[i], map);
      part_stats[c].rays_traced += st.rays_traced;
      part_stats[c].texels_below_horizon += st.texels_below_horizon;
      AppendVisibilityMap(part, map);
    }
    parts[c] = std::move(part);
  });
  VisibilityBlocks all = MakeVisibilityBlocks(options_.n, options_.bits);
  VisibilitySamplerStats total;
  for (std::size_t c = 0; c < chunks; ++c) {
    AppendVisibilityBlocks(all, parts[c]);
    parts[c] = {};
    total.rays_traced += part_stats[c].rays_traced;
    total.texels_below_horizon += part_stats[c].texels_below_horizon;
  }
  if (stats != nullptr) *stats = total;
  return all;
}

}  // namespace prt
