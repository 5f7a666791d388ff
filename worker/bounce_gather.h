// Interreflection by bounce gathering (docs/interreflection.md), the production estimator of
// the indirect transport (no MPI here). With T⁰ the direct rows (worker/transport_sampler.h),
//   Tᵏ⁺¹(x)[J] = (1/π) ∫_H(x) ρ(y) · Tᵏ(y)[J] · max(0, n_x·ω) dω,   y = first hit from x along ω,
// estimated with P cosine-distributed directions ω_p (pdf cos θ/π cancels (1/π)·cos θ),
// stratified on a √P-ish grid of the unit square and jittered per (seed, vertex, bounce):
//   Tᵏ⁺¹(x) ≈ (1/P) Σ_p ρ(y_p) · Tᵏ(y_p),   Tᵏ(y_p) = Σ_i b_i Tᵏ(v_i)   (barycentric interpolation
// of the hit triangle's vertex rows). A ray that escapes, or reaches a back face, brings 0
// (worker/surface_hit.h). So each vertex's gather is a short list of (vertex, weight per colour
// channel) terms, traced once per bounce and applied to the previous bounce's rows of the whole
// scene. The indirect part is smooth (Huang & Ramamoorthi 2010 §7: indirect light "is generally
// much smoother and low-frequency"; §4.2 samples it on the low-resolution grid), so the bounce
// rows live on a coarse cubemap of m < n texels per face edge: CoarsenRow sums each coarse
// texel's fine texels (exact for light that is constant over the coarse texel), and
// AddRefinedRow spreads a coarse value over its fine texels in proportion to their solid angles,
// so that relighting the refined row with the fine light equals relighting the coarse row with
// the light averaged over each coarse texel.
//
// Near field (final gathering, as in photon mapping's final gather): interpolating the hit
// triangle's vertex rows is accurate when the triangle looks small from x, and wrong where a
// vertex sits next to a coarsely tessellated surface — the bunny's belly a few millimetres above
// a ground grid of 6 cm, whose contact shadow no ground vertex resolves. So in bounce 1 a hit
// closer than near_field × its triangle's longest edge, on a triangle more than twice as coarse
// as the gathering vertex's own (SceneSurfaces::VertexEdge), takes T⁰ traced at the hit point
// itself on the indirect grid (one jittered ray per coarse texel, TransportSampler), kept with
// probability q = min(1, near_rows / the vertex's near hits) and weighted 1/q (unbiased). Later
// bounces interpolate (there is no traced Tᵏ at a point).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "runtime/brdf.h"
#include "vocabulary/cubemap.h"
#include "worker/embree_scene.h"
#include "worker/surface_hit.h"
#include "worker/transport_sampler.h"

namespace prt {

struct BounceGatherOptions {
  int paths = 1024;  // cosine-distributed directions per vertex and bounce, in [1, 65536]
  uint64_t seed = 1;
  // Near field (above): 0 turns it off; indirect_n is the grid the traced rows are on.
  double near_field = 1.0;
  int near_rows = 32;  // traced near-field rows per vertex, about (docs/interreflection.md)
  int indirect_n = 0;  // 0: no near field
};

// One term of a vertex's gather: Tᵏ⁺¹(x)[c] += weight[c] · Tᵏ(vertex)[c].
struct GatherTerm {
  uint64_t vertex = 0;
  float weight[3] = {0, 0, 0};
};

struct GatherStats {
  uint64_t rays_traced = 0;     // closest-hit rays and the near field's occlusion rays
  uint64_t rays_escaped = 0;    // reached the environment
  uint64_t back_face_hits = 0;  // absorbed at a back face
  uint64_t near_hits = 0;       // bounce 1: hits in the near field (traced or skipped)
  GatherStats& operator+=(const GatherStats& o) {
    rays_traced += o.rays_traced;
    rays_escaped += o.rays_escaped;
    back_face_hits += o.back_face_hits;
    near_hits += o.near_hits;
    return *this;
  }
};

// Glossy camera pixels in a gather (docs/image-relighting.md, "Glossy pixels"): a sample with
// glossy_material = i has the material materials[i] (k_d in diffuse[0], k_s in specular[0], as
// GlossySampling's) and the view towards `eye`. The gather's directions are cosine-distributed,
// so its row T(x) = ∫ [k_d/π + k_s·f_s(ω, ω_o)]·cos·L_in(ω) dω is estimated by weighing
// direction ω_q's terms by k_d + π·k_s·f_s(ω_q, ω_o) (a diffuse sample's arithmetic is
// untouched).
struct GatherLobe {
  std::span<const Material> materials;
  Vec3 eye{0, 0, 0};
};

// Where a gather is taken when it is not at a mesh vertex (an image run's pixel,
// docs/image-relighting.md "Interreflection").
struct GatherSite {
  // The near field's "own tessellation" of the gathering point: the longest edge of the
  // triangle it lies on (< 0: SceneSurfaces::VertexEdge(index), the gathering vertex's).
  double own_edge = -1;
  // Receives the interpolation terms of the bounce-1 near hits (merged per vertex, sorted, the
  // same weights ρ_c·b_i/P as `out`'s), which Terms otherwise drops: what a gather of
  // Σ_k Tᵏ applies to the bounces k ≥ 1 at those hits, whose T⁰ the near field traces.
  std::vector<GatherTerm>* near_terms = nullptr;
  // Glossy pixels (nullptr: every sample diffuse): each point the directions leave from (x or a
  // footprint's sub-sample) weighs them by its own lobe when it is glossy (GatherLobe).
  const GatherLobe* lobe = nullptr;
  // A supersampled pixel (docs/image-relighting.md, "Supersampling"): its footprint's surface
  // sub-samples (footprint->subs[first … first + count), their cdf and edge). Direction p then
  // leaves the sub-sample picked by the stratified inverse CDF of λ at frac((p + ½)/P + φ), φ
  // uniform per pixel, from its point and normals, with its edge as own_edge: an unbiased
  // estimate of Σ_s λ_s Σ_k Tᵏ(x_s). count 0: x alone (x then only names the pixel).
  const SampleFootprints* footprint = nullptr;
  std::size_t first = 0, count = 0;
};

// Thread-safe after construction; the scene and surfaces must outlive it.
class BounceGatherer {
 public:
  // Throws std::invalid_argument on paths outside [1, 65536].
  BounceGatherer(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                 BounceGatherOptions options);
  ~BounceGatherer();
  const BounceGatherOptions& options() const { return options_; }
  int strata_u() const { return su_; }
  int strata_v() const { return sv_; }

  // The gather terms of sample `x` (global index `index`) for bounce `bounce` (1 …): merged per
  // vertex, sorted by vertex, weights ρ_c · b_i / P (channel 0 only when `channels` is 1).
  // A pure function of (seed, index, bounce). Throws NumericalError on a non-finite sample.
  // near (optional; bounce 1 with a near field): channels × 6·indirect_n² floats receiving the
  // near field's traced part, to be added to the applied terms; zeroed first. near_texels (a
  // sparse vertex's feature texels, worker/sparse_indirect.h): only these coarse texels are
  // traced at the near hits, near then holds channels × near_texels.size() floats (channel c at
  // c·size), each value bit-identical to the full near row's at that texel.
  // site: a gather away from the vertices (GatherSite).
  GatherStats Terms(const SpatialSample& x, uint64_t index, int bounce, int channels,
                    std::vector<GatherTerm>& out, float* near = nullptr,
                    std::span<const uint32_t> near_texels = {}, const GatherSite& site = {}) const;

  // Tᵏ(x) for bounce k into out (channels rows of `cols` floats): Terms, ApplyGather to the
  // previous bounce's rows (prev_channels × vertex_count rows) and, in bounce 1, the near field.
  // `terms` and `near` are the caller's scratch (per thread).
  GatherStats GatherRow(const SpatialSample& x, uint64_t index, int bounce, int channels,
                        const float* previous, uint64_t vertex_count, int prev_channels,
                        std::size_t cols, float* out, std::vector<GatherTerm>& terms,
                        std::vector<float>& near) const;
  // The same at the listed coarse texels only (sorted, distinct): out receives channels ×
  // texels.size() floats (channel c at c·size), each bit-identical to GatherRow's at that texel
  // (the same rays, the same order of sums). What a sparse vertex gathers (its features).
  GatherStats GatherTexels(const SpatialSample& x, uint64_t index, int bounce, int channels,
                           const float* previous, uint64_t vertex_count, int prev_channels,
                           std::size_t cols, std::span<const uint32_t> texels, float* out,
                           std::vector<GatherTerm>& terms, std::vector<float>& near) const;
  // Σ_{k=1..K} Tᵏ(x) in one gather at a point that is not a mesh vertex (an image run's pixel,
  // docs/image-relighting.md "Interreflection"), from the vertices' rows on the indirect grid:
  // `direct` T⁰ (vertex_count rows of `cols`), `higher` Σ_{k=1..K−1} Tᵏ (channels ×
  // vertex_count rows, channel-major; nullptr for K = 1):
  //   Σ_k Tᵏ(x) = (1/P) Σ_q ρ(y_q) · (T⁰(y_q) + Σ_{k≥1} Tᵏ(y_q)),
  // bounce 1's directions for every bounce, T⁰ traced at near-field hits (GatherSite, own_edge:
  // the longest edge of x's triangle). out: channels rows of `cols`. A pure function of
  // (seed, index). `terms`, `near_terms`, `near`, `part` are the caller's scratch.
  struct SumScratch {
    std::vector<GatherTerm> terms, near_terms;
    std::vector<float> near, part;
  };
  // where: a supersampled pixel's footprint (its footprint, first and count fields; see
  // GatherSite), whose sub-samples' edges replace own_edge, and glossy pixels' lobes (lobe).
  GatherStats GatherSumRow(const SpatialSample& x, uint64_t index, double own_edge, int channels,
                           const float* direct, const float* higher, uint64_t vertex_count,
                           std::size_t cols, float* out, SumScratch& scratch,
                           const GatherSite& where = {}) const;
  // Whether bounce `bounce` on rows of `cols` texels traces a near field.
  bool HasNearField(int bounce, std::size_t cols) const;

 private:
  const EmbreeScene& scene_;
  const SceneSurfaces& surfaces_;
  BounceGatherOptions options_;
  int su_ = 1, sv_ = 1;
  std::unique_ptr<TransportSampler> near_sampler_;  // T⁰ at near hits, on the indirect grid
};

// Applies terms to the previous bounce's rows: `previous` holds prev_channels × vertex_count rows
// of `cols` floats, channel-major (row c·vertex_count + v); out receives `channels` rows of
// `cols` floats (channel c from the previous bounce's channel c, or its only channel).
void ApplyGather(std::span<const GatherTerm> terms, const float* previous, uint64_t vertex_count,
                 int prev_channels, int channels, std::size_t cols, float* out);
// The same at the listed texels only: out receives channels × texels.size() floats (channel c at
// c·size), each summed in the same order as ApplyGather's (bit-identical values).
void ApplyGatherTexels(std::span<const GatherTerm> terms, const float* previous,
                       uint64_t vertex_count, int prev_channels, int channels, std::size_t cols,
                       std::span<const uint32_t> texels, float* out);

// coarse[J] = Σ_{j ∈ J} fine[j] (fine.n() a multiple of coarse.n()).
void CoarsenRow(const CubemapLayout& fine, const CubemapLayout& coarse, const float* in,
                float* out);
// fine[j] += coarse[J] · Ω_j / Ω_J for every fine texel j of coarse texel J.
void AddRefinedRow(const CubemapLayout& coarse, const CubemapLayout& fine, const float* in,
                   float* out);

// The light averaged over each coarse texel (weighted by the fine texels' solid angles), so that
// Σ_J coarse_row[J]·L̄_J equals relighting the refined row (AddRefinedRow) with the fine light.
std::vector<float> CoarsenLight(const CubemapLayout& fine, const CubemapLayout& coarse,
                                std::span<const float> light);

}  // namespace prt

namespace prt {

// Every bounce in one process, in parallel over vertices with TBB (tests, benchmarks; the farm
// runs the same kernels as jobs, farm/bounce/gathering.cpp). `direct` holds the samples' T⁰ rows at
// `fine` (samples.size() rows); returns bounces 1 … K, each channels × samples.size() rows of
// coarse.texel_count() floats, channel-major. stats and seconds (optional) receive one entry per
// bounce (its counters, its wall time).
std::vector<std::vector<float>> GatherBounces(
    const BounceGatherer& gatherer, std::span<const SpatialSample> samples,
    const CubemapLayout& fine, const CubemapLayout& coarse, std::span<const float> direct,
    int bounces, int channels, std::vector<GatherStats>* stats = nullptr,
    std::vector<double>* seconds = nullptr);

}  // namespace prt
