// Bounce gathering (see bounce_gather.h).
#include "worker/bounce_gather.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// Uniform double in [0, 1) from 53 bits of a hash.
double Unit(uint64_t bits) {
  return static_cast<double>(bits >> 11) * 0x1p-53;
}

bool Finite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// Sorts `raw` by vertex and sums the terms of each vertex into `out` (cleared first).
void MergeTerms(std::vector<GatherTerm>& raw, std::vector<GatherTerm>& out) {
  out.clear();
  std::sort(raw.begin(), raw.end(),
            [](const GatherTerm& l, const GatherTerm& r) { return l.vertex < r.vertex; });
  for (const GatherTerm& g : raw) {
    if (!out.empty() && out.back().vertex == g.vertex) {
      for (int c = 0; c < 3; ++c) out.back().weight[c] += g.weight[c];
    } else {
      out.push_back(g);
    }
  }
}

// The near field's second condition: the hit triangle is this much coarser than the gathering
// vertex's own triangles.
constexpr double kNearCoarser = 2.0;

}  // namespace

BounceGatherer::BounceGatherer(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                               BounceGatherOptions options)
    : scene_(scene), surfaces_(surfaces), options_(options) {
  if (options.paths < 1 || options.paths > 65536)
    throw std::invalid_argument("bounce gathering: paths " + std::to_string(options.paths) +
                                " outside [1, 65536]");
  // The strata grid: sv the largest divisor of P not above √P (as the direct sampler's).
  sv_ = 1;
  for (int d = 1; d * d <= options.paths; ++d)
    if (options.paths % d == 0) sv_ = d;
  su_ = options.paths / sv_;
  if (options.near_field < 0 || options.near_rows < 1)
    throw std::invalid_argument("bounce gathering: near_field < 0 or near_rows < 1");
  if (options.near_field > 0 && options.indirect_n > 0) {
    TransportSamplerOptions to;
    to.rays_per_texel = 1;
    to.seed = SplitMix64(options.seed ^ 0x4E454152u);  // its own stream
    near_sampler_ = std::make_unique<TransportSampler>(scene, options.indirect_n, to);
  }
}

BounceGatherer::~BounceGatherer() = default;

bool BounceGatherer::HasNearField(int bounce, std::size_t cols) const {
  return bounce == 1 && near_sampler_ != nullptr && near_sampler_->layout().texel_count() == cols;
}

GatherStats BounceGatherer::GatherTexels(const SpatialSample& x, uint64_t index, int bounce,
                                         int channels, const float* previous, uint64_t vertex_count,
                                         int prev_channels, std::size_t cols,
                                         std::span<const uint32_t> texels, float* out,
                                         std::vector<GatherTerm>& terms,
                                         std::vector<float>& near) const {
  const bool with_near = HasNearField(bounce, cols);
  const std::size_t count = texels.size();
  if (with_near) near.resize(static_cast<std::size_t>(channels) * count);
  const GatherStats st =
      Terms(x, index, bounce, channels, terms, with_near ? near.data() : nullptr, texels);
  ApplyGatherTexels(terms, previous, vertex_count, prev_channels, channels, cols, texels, out);
  if (with_near && st.near_hits > 0)
    for (std::size_t i = 0; i < static_cast<std::size_t>(channels) * count; ++i) out[i] += near[i];
  return st;
}

GatherStats BounceGatherer::GatherRow(const SpatialSample& x, uint64_t index, int bounce,
                                      int channels, const float* previous, uint64_t vertex_count,
                                      int prev_channels, std::size_t cols, float* out,
                                      std::vector<GatherTerm>& terms,
                                      std::vector<float>& near) const {
  const bool with_near = HasNearField(bounce, cols);
  if (with_near) near.resize(static_cast<std::size_t>(channels) * cols);
  const GatherStats st =
      Terms(x, index, bounce, channels, terms, with_near ? near.data() : nullptr);
  ApplyGather(terms, previous, vertex_count, prev_channels, channels, cols, out);
  if (with_near && st.near_hits > 0)
    for (std::size_t i = 0; i < static_cast<std::size_t>(channels) * cols; ++i) out[i] += near[i];
  return st;
}

GatherStats BounceGatherer::Terms(const SpatialSample& x, uint64_t index, int bounce, int channels,
                                  std::vector<GatherTerm>& out, float* near,
                                  std::span<const uint32_t> near_texels,
                                  const GatherSite& site) const {
  out.clear();
  const double own_edge = site.own_edge >= 0 ? site.own_edge : surfaces_.VertexEdge(index);
  GatherStats st;
  const bool near_field = near != nullptr && bounce == 1 && near_sampler_ != nullptr;
  const bool subset = !near_texels.empty();
  const std::size_t near_cols = !near_field ? 0
                                : subset    ? near_texels.size()
                                            : near_sampler_->layout().texel_count();
  if (near_field) std::fill(near, near + channels * near_cols, 0.0f);
  thread_local std::vector<float> near_row;
  struct NearHit {
    SpatialSample at;
    Rgb rho;
    uint64_t pick;
  };
  thread_local std::vector<NearHit> near_hits;
  near_hits.clear();
  // The points the directions leave from: x, or a supersampled pixel's sub-samples.
  struct Origin {
    Vec3 n, t, b, ng;
    float above[3], below[3];
    double edge;
    const Material* material;  // a glossy point's lobe (GatherLobe), or nullptr
    ShadingFrame frame;
  };
  thread_local std::vector<Origin> origins;
  origins.clear();
  auto add_origin = [&](const SpatialSample& at, double edge) {
    const double ln = Length(at.normal);
    if (!Finite(at.position) || !Finite(at.normal) || !(ln > 0))
      throw NumericalError("bounce gathering: sample " + std::to_string(index) +
                           " has a non-finite position or a zero normal");
    Origin o;
    o.n = at.normal / ln;
    OrthonormalFrame(o.n, o.t, o.b);
    o.ng = at.geometric_normal;
    o.edge = edge;
    o.material = nullptr;
    if (site.lobe != nullptr && at.glossy_material != kDiffuseSample) {
      if (at.glossy_material >= site.lobe->materials.size())
        throw std::logic_error("bounce gathering: sample " + std::to_string(index) +
                               " names a glossy material beyond the table");
      o.material = &site.lobe->materials[at.glossy_material];
      o.frame = MakeShadingFrame(at.normal, site.lobe->eye - at.position);
    }
    // Origins on both sides of the surface: a cosine direction about the shading normal may dip
    // below the geometric surface; it leaves from the side it goes to (as pbrt's SpawnRay), so
    // it reaches the surface's own back or escapes instead of hitting its own front.
    scene_.RobustOrigin(at.position, at.geometric_normal, o.above);
    scene_.RobustOrigin(at.position, -at.geometric_normal, o.below);
    origins.push_back(o);
  };
  const SampleFootprints* fp = site.count > 0 ? site.footprint : nullptr;
  if (fp != nullptr) {
    if (site.first + site.count > fp->subs.size() || fp->cdf.size() != fp->subs.size() ||
        fp->edge.size() != fp->subs.size())
      throw std::logic_error("bounce gathering: sample " + std::to_string(index) +
                             " names a footprint outside its table");
    for (std::size_t i = site.first; i < site.first + site.count; ++i)
      add_origin(fp->subs[i], fp->edge[i]);
  } else {
    add_origin(x, own_edge);
  }
  OcclusionRay ray{};
  ray.tnear = 0;
  ray.tfar = std::numeric_limits<float>::infinity();
  const uint64_t key = SplitMix64(SplitMix64(options_.seed ^ 0x5052544245434E31ull) ^ index) ^
                       SplitMix64(static_cast<uint64_t>(bounce));
  const double inv_p = 1.0 / options_.paths;
  const double* cdf = fp != nullptr ? fp->cdf.data() + site.first : nullptr;
  const double phi = fp != nullptr ? Unit(SplitMix64(key ^ 0x464F4F5450524E54ull)) : 0.0;
  // The sub-samples go to the directions in a random order (Fisher–Yates from the pixel's key):
  // in path order they would take whole bands of the cosine strata each.
  thread_local std::vector<uint32_t> order;
  if (fp != nullptr) {
    order.resize(static_cast<std::size_t>(options_.paths));
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<uint32_t>(i);
    for (std::size_t i = order.size(); i > 1; --i) {
      const uint64_t r = SplitMix64(key ^ (0x5045524D00000000ull + i));
      std::swap(order[i - 1], order[static_cast<std::size_t>(r % i)]);
    }
  }
  std::vector<GatherTerm> raw, raw_near;
  raw.reserve(3 * static_cast<std::size_t>(options_.paths));
  for (int p = 0; p < options_.paths; ++p) {
    const uint64_t bits = SplitMix64(key + 2 * static_cast<uint64_t>(p));
    const uint64_t bits2 = SplitMix64(key + 2 * static_cast<uint64_t>(p) + 1);
    const double u1 = (p % su_ + Unit(bits)) / su_;
    const double u2 = (p / su_ + Unit(bits2)) / sv_;
    std::size_t pick = 0;
    if (cdf != nullptr) {  // stratified inverse CDF of λ
      double u = (order[static_cast<std::size_t>(p)] + 0.5) * inv_p + phi;
      u -= std::floor(u);
      pick = std::min(static_cast<std::size_t>(std::upper_bound(cdf, cdf + site.count, u) - cdf),
                      site.count - 1);
    }
    const Origin& o = origins[pick];
    const Vec3 d = CosineDirection(o.n, o.t, o.b, u1, u2);
    ray.direction[0] = static_cast<float>(d.x);
    ray.direction[1] = static_cast<float>(d.y);
    ray.direction[2] = static_cast<float>(d.z);
    const float* origin = Dot(d, o.ng) >= 0 ? o.above : o.below;
    std::copy_n(origin, 3, ray.origin);
    ++st.rays_traced;
    RayHit hit;
    SurfaceHit h;
    const SceneSurfaces::Outcome outcome = surfaces_.Trace(scene_, ray, hit, h);
    if (outcome != SceneSurfaces::Outcome::kFront) {
      ++(outcome == SceneSurfaces::Outcome::kEscaped ? st.rays_escaped : st.back_face_hits);
      continue;
    }
    Rgb rho = surfaces_.albedo(h.mesh);
    if (o.material != nullptr) {
      // A glossy point: the direction's weight k_d + π·k_s·f_s (GatherLobe); SpecularLobe has
      // the cosine folded in, which the cosine-distributed direction's pdf takes out.
      const Material& m = *o.material;
      const double c = Dot(o.n, d);
      const double f =
          m.diffuse[0] +
          (c > 1e-12 ? std::numbers::pi * m.specular[0] * SpecularLobe(m, o.frame, d) / c : 0.0);
      for (int k = 0; k < 3; ++k) rho[k] = static_cast<float>(rho[k] * f);
    }
    // Near: closer than the hit triangle's size, and a triangle coarser than x's own
    // tessellation (kNearCoarser ×), whose vertices cannot resolve what x sees of it.
    const bool is_near = near_field && hit.t < options_.near_field * h.max_edge &&
                         h.max_edge > kNearCoarser * o.edge;
    if (is_near) {
      // Near field: traced below, once the vertex's near hits are known.
      ++st.near_hits;
      near_hits.push_back({h.sample, rho, SplitMix64(key ^ (0x6E656172ull + 2 * uint64_t(p)))});
      if (!site.near_terms) continue;
    }
    std::vector<GatherTerm>& into = is_near ? raw_near : raw;
    for (int i = 0; i < 3; ++i) {
      GatherTerm g;
      g.vertex = h.vertices[i];
      for (int c = 0; c < channels; ++c)
        g.weight[c] = static_cast<float>(rho[c] * h.weights[i] * inv_p);
      into.push_back(g);
    }
  }
  // The near hits: each traced with probability q = min(1, near_rows / their count) and weighted
  // 1/q (q is fixed by this vertex's directions, so the estimate stays unbiased), which bounds
  // the traced rows per vertex by about near_rows.
  if (!near_hits.empty()) {
    const double q = std::min(1.0, double(options_.near_rows) / double(near_hits.size()));
    near_row.resize(near_cols);
    for (const NearHit& nh : near_hits) {
      if (Unit(nh.pick) >= q) continue;
      const SampleStats ss =
          subset ? near_sampler_->ComputeTexels(nh.at, SplitMix64(nh.pick), near_texels,
                                                near_row.data())
                 : near_sampler_->ComputeRow(nh.at, SplitMix64(nh.pick), near_row.data());
      st.rays_traced += ss.rays_traced;
      const double w = inv_p / q;
      for (int c = 0; c < channels; ++c) {
        const auto wc = static_cast<float>(nh.rho[c] * w);
        float* dst = near + c * near_cols;
        for (std::size_t J = 0; J < near_cols; ++J) dst[J] += wc * near_row[J];
      }
    }
  }
  MergeTerms(raw, out);
  if (site.near_terms) MergeTerms(raw_near, *site.near_terms);
  return st;
}

GatherStats BounceGatherer::GatherSumRow(const SpatialSample& x, uint64_t index, double own_edge,
                                         int channels, const float* direct, const float* higher,
                                         uint64_t vertex_count, std::size_t cols, float* out,
                                         SumScratch& s, const GatherSite& where) const {
  const std::size_t per_row = static_cast<std::size_t>(channels) * cols;
  const bool with_near = HasNearField(1, cols);
  s.near.resize(per_row);
  GatherSite site;
  site.own_edge = own_edge;
  site.near_terms = higher ? &s.near_terms : nullptr;
  site.lobe = where.lobe;
  site.footprint = where.footprint;
  site.first = where.first;
  site.count = where.count;
  s.near_terms.clear();
  const GatherStats st =
      Terms(x, index, 1, channels, s.terms, with_near ? s.near.data() : nullptr, {}, site);
  // T⁰ interpolated at the far hits; the bounces k ≥ 1 interpolated at every hit.
  ApplyGather(s.terms, direct, vertex_count, 1, channels, cols, out);
  if (higher) {
    s.part.resize(per_row);
    ApplyGather(s.terms, higher, vertex_count, channels, channels, cols, s.part.data());
    for (std::size_t j = 0; j < per_row; ++j) out[j] += s.part[j];
    if (!s.near_terms.empty()) {
      ApplyGather(s.near_terms, higher, vertex_count, channels, channels, cols, s.part.data());
      for (std::size_t j = 0; j < per_row; ++j) out[j] += s.part[j];
    }
  }
  if (with_near && st.near_hits > 0)
    for (std::size_t j = 0; j < per_row; ++j) out[j] += s.near[j];
  return st;
}

namespace {

// out[c·count + i] = Σ_terms w_c · previous[row(c, vertex)][texel(i)], terms in order.
template <class Texel>
void Apply(std::span<const GatherTerm> terms, const float* previous, uint64_t vertex_count,
           int prev_channels, int channels, std::size_t cols, std::size_t count, Texel&& texel,
           float* out) {
  std::fill(out, out + static_cast<std::size_t>(channels) * count, 0.0f);
  for (const GatherTerm& g : terms) {
    for (int c = 0; c < channels; ++c) {
      const float w = g.weight[c];
      if (w == 0) continue;
      const uint64_t row =
          static_cast<uint64_t>(prev_channels == 1 ? 0 : c) * vertex_count + g.vertex;
      const float* src = previous + row * cols;
      float* dst = out + static_cast<std::size_t>(c) * count;
      for (std::size_t i = 0; i < count; ++i) dst[i] += w * src[texel(i)];
    }
  }
}

}  // namespace

void ApplyGather(std::span<const GatherTerm> terms, const float* previous, uint64_t vertex_count,
                 int prev_channels, int channels, std::size_t cols, float* out) {
  Apply(
      terms, previous, vertex_count, prev_channels, channels, cols, cols,
      [](std::size_t i) { return i; }, out);
}

void ApplyGatherTexels(std::span<const GatherTerm> terms, const float* previous,
                       uint64_t vertex_count, int prev_channels, int channels, std::size_t cols,
                       std::span<const uint32_t> texels, float* out) {
  Apply(
      terms, previous, vertex_count, prev_channels, channels, cols, texels.size(),
      [&](std::size_t i) { return texels[i]; }, out);
}

void CoarsenRow(const CubemapLayout& fine, const CubemapLayout& coarse, const float* in,
                float* out) {
  const int n = fine.n(), m = coarse.n(), f = n / m;
  std::fill(out, out + coarse.texel_count(), 0.0f);
  for (int face = 0; face < 6; ++face)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        out[coarse.Index(face, x / f, y / f)] += in[fine.Index(face, x, y)];
}

void AddRefinedRow(const CubemapLayout& coarse, const CubemapLayout& fine, const float* in,
                   float* out) {
  const int n = fine.n(), m = coarse.n(), f = n / m;
  for (int face = 0; face < 6; ++face)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const std::size_t J = coarse.Index(face, x / f, y / f), j = fine.Index(face, x, y);
        out[j] += static_cast<float>(in[J] * (fine.TexelSolidAngle(j) / coarse.TexelSolidAngle(J)));
      }
}

std::vector<float> CoarsenLight(const CubemapLayout& fine, const CubemapLayout& coarse,
                                std::span<const float> light) {
  std::vector<float> weighted(fine.texel_count()), out(coarse.texel_count());
  for (std::size_t j = 0; j < weighted.size(); ++j)
    weighted[j] = static_cast<float>(light[j] * fine.TexelSolidAngle(j));
  CoarsenRow(fine, coarse, weighted.data(), out.data());
  for (std::size_t J = 0; J < out.size(); ++J)
    out[J] = static_cast<float>(out[J] / coarse.TexelSolidAngle(J));
  return out;
}

}  // namespace prt

namespace prt {

std::vector<std::vector<float>> GatherBounces(
    const BounceGatherer& gatherer, std::span<const SpatialSample> samples,
    const CubemapLayout& fine, const CubemapLayout& coarse, std::span<const float> direct,
    int bounces, int channels, std::vector<GatherStats>* stats, std::vector<double>* seconds) {
  const std::size_t V = samples.size(), cols = coarse.texel_count();
  std::vector<float> coarse_direct(V * cols);
  tbb::parallel_for(std::size_t{0}, V, [&](std::size_t v) {
    CoarsenRow(fine, coarse, direct.data() + v * fine.texel_count(),
               coarse_direct.data() + v * cols);
  });
  std::vector<std::vector<float>> out;
  if (stats) stats->clear();
  if (seconds) seconds->clear();
  for (int k = 1; k <= bounces; ++k) {
    const std::vector<float>& previous = k == 1 ? coarse_direct : out.back();
    const int prev_channels = k == 1 ? 1 : channels;
    std::vector<float> next(static_cast<std::size_t>(channels) * V * cols);
    tbb::enumerable_thread_specific<GatherStats> local;
    const auto t0 = std::chrono::steady_clock::now();
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, V, 16), [&](const tbb::blocked_range<std::size_t>& r) {
          std::vector<GatherTerm> terms;
          std::vector<float> near;
          std::vector<float> row(static_cast<std::size_t>(channels) * cols);
          for (std::size_t v = r.begin(); v != r.end(); ++v) {
            local.local() += gatherer.GatherRow(samples[v], v, k, channels, previous.data(), V,
                                                prev_channels, cols, row.data(), terms, near);
            for (int c = 0; c < channels; ++c)
              std::copy_n(row.data() + c * cols, cols, next.data() + (c * V + v) * cols);
          }
        });
    if (seconds)
      seconds->push_back(
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (stats) {
      GatherStats s;
      for (const GatherStats& l : local) s += l;
      stats->push_back(s);
    }
    out.push_back(std::move(next));
  }
  return out;
}

}  // namespace prt
