// Worker kernel: the path-traced REFERENCE for transport with interreflection (no MPI here).
// Huang & Ramamoorthi 2010 §7 precompute "both direct and indirect lighting, using a raytracer
// for the former and a path tracer for the latter"; this is that path tracer, per element: slow
// by nature, unbiased, and what every faster interreflection estimator is measured against.
//
// For a spatial sample x with shading normal n_x and cubemap texel j (docs/conventions.md), with
// K bounces and per colour channel c:
//   T_c[x][j]     = T⁰[x][j] + T¹_c[x][j] + … + Tᴷ_c[x][j]
//   T⁰[x][j]      = (1/π) ∫_texel_j V(x, ω) max(0, n_x·ω) dω          (TransportSampler)
//   Tᵏ⁺¹_c[x][j] = (1/π) ∫_H(x) ρ_c(y) · Tᵏ_c[y][j] · max(0, n_x·ω) dω,
// y the first surface hit from x along ω; the integrand is 0 when the ray escapes and when y is
// a back face (worker/surface_hit.h: every surface occludes from both sides, only the side its
// normals face reflects). ρ is the hit mesh's RGB albedo; the vertex's own albedo is applied at
// relighting, B = albedo ⊙ (T·L). T⁰ is the same for every channel.
//
// Estimator. T⁰[x] is TransportSampler::ComputeRow with (rays_per_texel, seed): bit for bit the
// direct row the farm computes. Then P paths leave x: path p's first direction is cosine-weighted
// about n_x from stratum p of an a×b grid of the unit square (CosineDirection; the pdf cos/π
// cancels the (1/π)·cos of the integral), later directions cosine-weighted about the hit's
// shading normal from independent uniform points. At the d-th front-face hit y_d the throughput
// is β_c = Π_{i≤d} ρ_c(y_i) and the path adds β_c · T̂⁰[y_d] / P to bounce d, T̂⁰[y_d] being a
// full direct row at the hit point (interpolated shading normal) from a TransportSampler with
// path_rays_per_texel rays per texel and its own seed stream. A path stops at K hits, when it
// escapes, at a back face, or when every β_c is 0 (no Russian roulette). Each step is an unbiased
// estimate of the next term given the previous point, so the sum is unbiased for T (up to the
// direct rows' O(h²) jitter bias, docs/transport-sampling.md).
//
// Rays. A segment leaves the point along the unit geometric normal of the side its direction
// goes to (EmbreeScene::RobustOrigin, tnear 0, tfar ∞): a cosine direction about the shading
// normal that lies below the geometric surface (they differ inside a triangle and at a vertex)
// is traced from just below it, as pbrt's SpawnRay does, so it reaches the surface's own back
// or whatever lies beyond, never the front of its own triangle an offset away (which would
// reflect the point onto itself).
//
// Determinism. Every random number is a pure function of (seed, global sample index, path,
// depth) by SplitMix64 (vocabulary/hash.h): a row is bit-identical whichever thread or batch
// computes it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "vocabulary/cubemap.h"
#include "vocabulary/envmap.h"
#include "worker/embree_scene.h"
#include "worker/surface_hit.h"
#include "worker/transport_sampler.h"

namespace prt {

struct PathTraceOptions {
  int bounces = 1;  // K in [0, 8]: T⁰ + … + Tᴷ
  // Paths per vertex P in [1, 65536], stratified on the first bounce: an a×b grid of the unit
  // square, b the largest divisor of P not above √P and a = P/b (16: 4×4, 32: 8×4).
  int paths = 64;
  int rays_per_texel = 4;  // the vertex's direct row T⁰ (as TransportSamplerOptions), [1, 1024]
  int path_rays_per_texel = 1;  // the direct row at each path vertex, [1, 1024]
  uint64_t seed = 1;            // T⁰ uses it as the direct rows do; the paths hash it apart
};

struct PathTraceStats {
  uint64_t intersect_rays = 0;  // path segments (closest-hit rays)
  uint64_t shadow_rays = 0;     // occlusion rays of the direct rows: the vertex's and the paths'
  uint64_t path_vertices = 0;   // front-face hits, each one direct row added (a black one ends
                                // the path uncounted)
  uint64_t escaped = 0;         // segments that hit nothing
  uint64_t back_faces = 0;      // segments absorbed by a back face
  uint64_t rays_traced() const { return intersect_rays + shadow_rays; }
  PathTraceStats& operator+=(const PathTraceStats& o) {
    intersect_rays += o.intersect_rays;
    shadow_rays += o.shadow_rays;
    path_vertices += o.path_vertices;
    escaped += o.escaped;
    back_faces += o.back_faces;
    return *this;
  }
  bool operator==(const PathTraceStats&) const = default;
};

// The relit value Σ_j T_c[x][j]·L_c[j] of one vertex under one lighting, colour c, split into its
// direct part (exact from the row T⁰) and the paths' part, each with its Monte-Carlo standard
// error: "the reference's noise" against which another estimator's answer is judged.
struct RelitEstimate {
  double direct = 0;  // Σ_j T⁰[j]·L_c[j] over the float row
  // √(Σ_j L_c[j]²·Var(T⁰_j)) from TransportSampler's per-texel variance; 0 when
  // rays_per_texel = 1 (not estimable, TransportSampler::VarianceEstimable()).
  double direct_standard_error = 0;
  // Mean over the P paths of each path's sample Σ_d β_c(d)·Σ_j T̂⁰[y_d][j]·L_c[j] (= the
  // indirect part of the row relit, up to its float rounding).
  double indirect = 0;
  // Standard error of that mean by collapsed strata (Cochran, Sampling Techniques §5A.12, as
  // TransportSampler's variance): with a and b even, the first-bounce strata go in 2×2 blocks and
  // each block's second difference d gives Σ_blocks d² / P²; otherwise neighbouring strata go in
  // pairs (the last takes a third when P is odd), g/(g−1)·Σ(x − x̄)² per group, / P². Unbiased
  // for stratum means that vary linearly across a block, conservative otherwise; 0 when P = 1.
  double indirect_standard_error = 0;
  // Each bounce's share: bounce[0] = direct, bounce[k] (k = 1..K) the mean over the paths of
  // their k-th term (Σ_k bounce[k] = total), with the same standard errors
  // (bounce_standard_error[0] = direct_standard_error); 0 beyond K.
  std::array<double, 9> bounce{};
  std::array<double, 9> bounce_standard_error{};
  double total() const { return direct + indirect; }
  double standard_error() const;  // √(direct_standard_error² + indirect_standard_error²)
};

// Optional outputs of ComputeRow / ComputeRows (all null/empty: the row only). What is asked
// for never changes the row's bytes.
struct PathTraceExtras {
  // (K+1)·channels·texel_count floats: bounce k's term Tᵏ_c, at [(k·channels + c)·texels + j]
  // (k = 0 is T⁰, copied for every channel). Batches: one such block per sample.
  float* bounce_rows = nullptr;
  // Relight under each of these (n == the cubemap's n, three channels each) into `relit`:
  // lights.size()·3 estimates per sample at [light·3 + colour]; with channels = 1 every colour
  // uses T's one channel. Batches: one such block per sample.
  std::span<const CubemapRgb> lights;
  RelitEstimate* relit = nullptr;
};

// Thread-safe after construction; the scene and surfaces (the same SceneGeometry) must outlive
// it.
class PathTraceReference {
 public:
  // Throws std::invalid_argument on bounces outside [0, 8], paths outside [1, 65536], rays per
  // texel outside [1, 1024], a bad cubemap_n (TransportSampler) or a scene whose geometry count
  // differs from the surfaces' meshes.
  PathTraceReference(const EmbreeScene& scene, const SceneSurfaces& surfaces, int cubemap_n,
                     PathTraceOptions options);
  ~PathTraceReference();
  PathTraceReference(const PathTraceReference&) = delete;
  PathTraceReference& operator=(const PathTraceReference&) = delete;

  const CubemapLayout& layout() const;
  const PathTraceOptions& options() const;
  int paths_u() const;  // a: the first-bounce grid is paths_u() × paths_v(), path p = pv·a + pu
  int paths_v() const;
  // Whether a channel count is allowed: 3 always; 1 only when every mesh's albedo is grey
  // (r = g = b; channel 0 is used).
  bool ChannelsAllowed(int channels) const;

  // The full row for one sample: channels·texel_count floats, row[c·texels + j] = T_c[x][j].
  // `sample_index` is its global index (seeds T⁰ exactly as TransportSampler::ComputeRow and
  // the paths). Throws std::invalid_argument when !ChannelsAllowed(channels) or a light's n
  // differs, prt::NumericalError on a non-finite sample (as TransportSampler).
  PathTraceStats ComputeRow(const SpatialSample& sample, uint64_t sample_index, int channels,
                            float* row, const PathTraceExtras& extras = {}) const;

  // The indirect part alone, Σ_k Tᵏ_c[x][j] for k = 1..K, at the listed texels (sorted or not;
  // every texel when empty) into out[c·count + i]: the same paths as ComputeRow, the direct rows
  // at the path vertices evaluated at those texels only (TransportSampler::ComputeTexels, the
  // same values as the full rows'), so a texel's value does not depend on which others are
  // asked for. What sparse precomputation traces at a vertex's feature texels
  // (worker/sparse_indirect.h); its cost is proportional to the texels asked for.
  // Throws as ComputeRow, and std::out_of_range on a texel ≥ texel_count.
  PathTraceStats ComputeIndirect(const SpatialSample& sample, uint64_t sample_index, int channels,
                                 std::span<const uint32_t> texels, float* out) const;

  // Rows for samples[0..count) with global indices first_index.., row-major into out (count ×
  // channels × texels), in parallel over samples with TBB; extras hold one block per sample.
  PathTraceStats ComputeRows(std::span<const SpatialSample> samples, uint64_t first_index,
                             int channels, float* out, const PathTraceExtras& extras = {}) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace prt
