#include "worker/adaptive_angular_sampling.h"

#include <algorithm>
#include <cmath>

namespace prt {

AngularStats& AngularStats::operator+=(const AngularStats& o) {
  trace += o.trace;
  texels_above_horizon += o.texels_above_horizon;
  grid_texels += o.grid_texels;
  feature_texels += o.feature_texels;
  borrowed_texels += o.borrowed_texels;
  return *this;
}

void VisibilityOfRow(const TransportSampler& sampler, const SpatialSample& sample,
                     uint64_t sample_index, const float* transport, float* visibility) {
  const CubemapLayout& layout = sampler.layout();
  const std::size_t count = layout.texel_count();
  std::vector<uint32_t> above;
  above.reserve(count);
  for (std::size_t j = 0; j < count; ++j) {
    visibility[j] = 0.0f;
    if (layout.TexelAboveHorizon(j, sample.normal)) above.push_back(static_cast<uint32_t>(j));
  }
  std::vector<float> unocc(above.size());
  sampler.ComputeUnoccludedTexels(sample, sample_index, above, unocc.data());
  for (std::size_t i = 0; i < above.size(); ++i) {
    const float u = unocc[i];
    visibility[above[i]] = u > 0 ? std::clamp(transport[above[i]] / u, 0.0f, 1.0f) : 0.0f;
  }
}

AngularStats SampleDenseRowAdaptive(const TransportSampler& sampler, const SpatialSample& sample,
                                    uint64_t sample_index, const AngularOptions& options,
                                    DenseRow& out) {
  const CubemapLayout& layout = sampler.layout();
  const int n = layout.n();
  const std::size_t count = layout.texel_count();
  out.transport.assign(count, 0.0f);
  out.visibility.assign(count, 0.0f);
  out.feature.assign(count, 0);
  AngularStats stats;

  // Unoccluded values of every texel above the horizon (no rays: visibility ≡ 1).
  std::vector<uint8_t> above(count, 0);
  std::vector<uint32_t> above_list;
  above_list.reserve(count);
  for (std::size_t j = 0; j < count; ++j) {
    if (layout.TexelAboveHorizon(j, sample.normal)) {
      above[j] = 1;
      above_list.push_back(static_cast<uint32_t>(j));
    }
  }
  stats.texels_above_horizon = above_list.size();
  std::vector<float> unocc_list(above_list.size());
  sampler.ComputeUnoccludedTexels(sample, sample_index, above_list, unocc_list.data());
  std::vector<float> unocc(count, 0.0f);
  for (std::size_t i = 0; i < above_list.size(); ++i) unocc[above_list[i]] = unocc_list[i];

  // Pass 1: the regular grid at half resolution per face axis.
  std::vector<uint8_t> sampled(count, 0);
  std::vector<uint32_t> grid;
  grid.reserve(above_list.size() / 4 + 8);
  const int step = n >= 2 ? 2 : 1;
  for (uint32_t j : above_list) {
    const TexelCoord c = layout.Coord(j);
    if (c.x % step == 0 && c.y % step == 0) grid.push_back(j);
  }
  std::vector<float> values(grid.size());
  stats.trace += sampler.ComputeTexels(sample, sample_index, grid, values.data());
  stats.grid_texels = grid.size();
  auto record = [&](uint32_t j, float t) {
    out.transport[j] = t;
    const float u = unocc[j];
    out.visibility[j] = u > 0 ? std::clamp(t / u, 0.0f, 1.0f) : 0.0f;
    sampled[j] = 1;
  };
  for (std::size_t i = 0; i < grid.size(); ++i) record(grid[i], values[i]);

  // Pass 2: the window test on every other texel above the horizon.
  const int half = options.window / 2;
  std::vector<uint32_t> features;
  std::vector<std::pair<uint32_t, float>> borrowed;
  for (uint32_t j : above_list) {
    if (sampled[j]) continue;
    const TexelCoord c = layout.Coord(j);
    float lo = 2.0f, hi = -1.0f;
    int seen = 0;
    for (int y = std::max(0, c.y - half); y <= std::min(n - 1, c.y + half); ++y) {
      for (int x = std::max(0, c.x - half); x <= std::min(n - 1, c.x + half); ++x) {
        const std::size_t k = layout.Index(c.face, x, y);
        if (!sampled[k]) continue;
        lo = std::min(lo, out.visibility[k]);
        hi = std::max(hi, out.visibility[k]);
        ++seen;
      }
    }
    if (seen == 0 || hi - lo > options.tolerance) {
      features.push_back(j);
    } else {
      borrowed.emplace_back(j, 0.5f * (lo + hi));
    }
  }
  values.resize(features.size());
  stats.trace += sampler.ComputeTexels(sample, sample_index, features, values.data());
  for (std::size_t i = 0; i < features.size(); ++i) {
    record(features[i], values[i]);
    out.feature[features[i]] = 1;
  }
  for (const auto& [j, v] : borrowed) {
    out.visibility[j] = v;
    out.transport[j] = v * unocc[j];
  }
  stats.feature_texels = features.size();
  stats.borrowed_texels = borrowed.size();
  return stats;
}

}  // namespace prt
