#include "worker/adaptive_angular_sampling.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace prt {

AngularStats& AngularStats::operator+=(const AngularStats& o) {
  trace += o.trace;
  texels_above_horizon += o.texels_above_horizon;
  grid_texels += o.grid_texels;
  feature_texels += o.feature_texels;
  borrowed_texels += o.borrowed_texels;
  return *this;
}

void UnoccludedValues(const TransportSampler& sampler, const SpatialSample& sample,
                      uint64_t sample_index, std::span<const uint32_t> texels,
                      const uint8_t* fully_above, float* values) {
  const std::vector<Vec3>& phi = sampler.layout().TexelVectorIrradiance();
  const Vec3 n = Normalize(sample.normal);
  std::vector<uint32_t> straddling;
  std::vector<std::size_t> where;
  for (std::size_t i = 0; i < texels.size(); ++i) {
    const uint32_t j = texels[i];
    // The closed form is the diffuse row's; a glossy pixel's U is the sampler's own estimate.
    if (fully_above[j] && sample.glossy_material == kDiffuseSample && !sample.supersampled) {
      values[i] = static_cast<float>(std::max(0.0, Dot(n, phi[j])) * std::numbers::inv_pi);
    } else {
      straddling.push_back(j);
      where.push_back(i);
    }
  }
  std::vector<float> u(straddling.size());
  sampler.ComputeUnoccludedTexels(sample, sample_index, straddling, u.data());
  for (std::size_t k = 0; k < where.size(); ++k) values[where[k]] = u[k];
}

std::size_t SampleHorizonMask(const TransportSampler& sampler, const SpatialSample& sample,
                              uint64_t sample_index, uint8_t* mask, uint8_t* fully_above) {
  const CubemapLayout& layout = sampler.layout();
  const SampleFootprints* fp = sampler.footprints();
  if (!sample.supersampled || fp == nullptr || sample_index + 1 >= fp->offset.size())
    return layout.AboveHorizonMask(sample.normal, mask, fully_above);
  const std::size_t count = layout.texel_count();
  std::fill(mask, mask + count, uint8_t{0});
  if (fully_above != nullptr) std::fill(fully_above, fully_above + count, uint8_t{1});
  std::vector<uint8_t> above(count), fully(count);
  for (uint32_t s = fp->offset[sample_index]; s < fp->offset[sample_index + 1]; ++s) {
    layout.AboveHorizonMask(fp->subs[s].normal, above.data(), fully.data());
    for (std::size_t j = 0; j < count; ++j) {
      mask[j] = static_cast<uint8_t>(mask[j] | above[j]);
      if (fully_above != nullptr) fully_above[j] = static_cast<uint8_t>(fully_above[j] & fully[j]);
    }
  }
  return static_cast<std::size_t>(std::count(mask, mask + count, uint8_t{1}));
}

void VisibilityOfRow(const TransportSampler& sampler, const SpatialSample& sample,
                     uint64_t sample_index, const float* transport, float* visibility) {
  const CubemapLayout& layout = sampler.layout();
  const std::size_t count = layout.texel_count();
  std::vector<uint8_t> above(count);
  SampleHorizonMask(sampler, sample, sample_index, above.data());
  std::vector<uint32_t> list;
  list.reserve(count);
  for (std::size_t j = 0; j < count; ++j) {
    visibility[j] = 0.0f;
    if (above[j]) list.push_back(static_cast<uint32_t>(j));
  }
  std::vector<float> unocc(list.size());
  sampler.ComputeUnoccludedTexels(sample, sample_index, list, unocc.data());
  for (std::size_t i = 0; i < list.size(); ++i) {
    const float u = unocc[i];
    visibility[list[i]] = u > 0 ? std::clamp(transport[list[i]] / u, 0.0f, 1.0f) : 0.0f;
  }
}

int AngularGridStep(const AngularOptions& options, int n) {
  if (n < 2) return 1;
  return options.grid_step > 0 ? options.grid_step : 2;
}

int AngularWindowHalf(const AngularOptions& options, int n) {
  return (options.window / 2) * std::max(1, AngularGridStep(options, n) / 2);
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
  out.variance.assign(count, 0.0f);
  AngularStats stats;

  std::vector<uint8_t> above(count), fully(count);
  stats.texels_above_horizon =
      SampleHorizonMask(sampler, sample, sample_index, above.data(), fully.data());

  // Pass 1: the regular grid (half resolution per face axis by default). The same rays give the
  // unoccluded estimate U_j, so v_j = T_j / U_j is exactly 1 where nothing blocks the texel.
  std::vector<uint8_t> sampled(count, 0);
  std::vector<uint32_t> grid;
  grid.reserve(count / 4 + 8);
  const int step = AngularGridStep(options, n);
  for (int face = 0; face < 6; ++face)
    for (int y = 0; y < n; y += step)
      for (int x = 0; x < n; x += step) {
        const std::size_t j = layout.Index(face, x, y);
        if (above[j]) grid.push_back(static_cast<uint32_t>(j));
      }
  std::vector<float> values(grid.size()), unocc(grid.size()), var(grid.size());
  stats.trace +=
      sampler.ComputeTexels(sample, sample_index, grid, values.data(), unocc.data(), var.data());
  stats.grid_texels = grid.size();
  for (std::size_t i = 0; i < grid.size(); ++i) out.variance[grid[i]] = var[i];
  auto record = [&](uint32_t j, float t, float u) {
    out.transport[j] = t;
    out.visibility[j] = u > 0 ? std::clamp(t / u, 0.0f, 1.0f) : 0.0f;
    sampled[j] = 1;
  };
  for (std::size_t i = 0; i < grid.size(); ++i) record(grid[i], values[i], unocc[i]);

  // Pass 2: the window test on every other texel above the horizon: the smallest and largest
  // visibility of the sampled texels in the window, as a separable filter (along the rows, then
  // the columns of the row results: the same min and max as the 2D window, at 2·window instead
  // of window² reads per texel). lo > hi where the window holds no sampled texel.
  const int half = AngularWindowHalf(options, n);
  std::vector<float> row_lo(static_cast<std::size_t>(n) * n), row_hi(row_lo.size());
  std::vector<uint32_t> features, borrowed;
  std::vector<float> borrowed_v;
  for (int face = 0; face < 6; ++face) {
    const std::size_t base = layout.Index(face, 0, 0);
    for (int y = 0; y < n; ++y) {
      const std::size_t r = base + static_cast<std::size_t>(y) * n;
      for (int cx = 0; cx < n; ++cx) {
        float lo = 2.0f, hi = -1.0f;
        for (int x = std::max(0, cx - half); x <= std::min(n - 1, cx + half); ++x) {
          if (!sampled[r + x]) continue;
          lo = std::min(lo, out.visibility[r + x]);
          hi = std::max(hi, out.visibility[r + x]);
        }
        row_lo[static_cast<std::size_t>(y) * n + cx] = lo;
        row_hi[static_cast<std::size_t>(y) * n + cx] = hi;
      }
    }
    for (int cy = 0; cy < n; ++cy) {
      for (int cx = 0; cx < n; ++cx) {
        const std::size_t j = layout.Index(face, cx, cy);
        if (!above[j] || sampled[j]) continue;
        float lo = 2.0f, hi = -1.0f;
        for (int y = std::max(0, cy - half); y <= std::min(n - 1, cy + half); ++y) {
          lo = std::min(lo, row_lo[static_cast<std::size_t>(y) * n + cx]);
          hi = std::max(hi, row_hi[static_cast<std::size_t>(y) * n + cx]);
        }
        if (hi < lo || hi - lo > options.tolerance) {
          features.push_back(static_cast<uint32_t>(j));
        } else {
          borrowed.push_back(static_cast<uint32_t>(j));
          borrowed_v.push_back(0.5f * (lo + hi));
        }
      }
    }
  }
  values.resize(features.size());
  unocc.resize(features.size());
  var.resize(features.size());
  stats.trace += sampler.ComputeTexels(sample, sample_index, features, values.data(), unocc.data(),
                                       var.data());
  for (std::size_t i = 0; i < features.size(); ++i) {
    record(features[i], values[i], unocc[i]);
    out.feature[features[i]] = 1;
    out.variance[features[i]] = var[i];
  }
  // Borrowed texels: the window's visibility under this texel's own cosine.
  std::vector<float> ub(borrowed.size());
  UnoccludedValues(sampler, sample, sample_index, borrowed, fully.data(), ub.data());
  for (std::size_t i = 0; i < borrowed.size(); ++i) {
    out.visibility[borrowed[i]] = borrowed_v[i];
    out.transport[borrowed[i]] = borrowed_v[i] * ub[i];
  }
  stats.feature_texels = features.size();
  stats.borrowed_texels = borrowed.size();
  return stats;
}

}  // namespace prt
