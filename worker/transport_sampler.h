// Worker kernel: rows of the light transport matrix T by Embree ray tracing (no MPI here).
// For a spatial sample x with normal n and cubemap texel j (docs/conventions.md):
//   T[x][j] = (1/π) · ∫_texel_j V(x, ω) · max(0, n·ω) dω
// (albedo is applied at relighting, B = albedo ⊙ (T·L)), estimated with k stratified jittered
// occlusion rays per texel, one per stratum s of an a×b grid of the texel's face rectangle,
// each weighted by the exact solid angle Ω_s of its stratum (Σ_s Ω_s = Ω_j exactly):
//   T[x][j] ≈ (1/π) · Σ_s Ω_s · V(x, ω_s) · max(0, n·ω_s).
// Texels entirely below the horizon of n are skipped without tracing and counted; rays below
// the horizon inside a partly visible texel count 0 without tracing.
// Full description: docs/transport-sampling.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "formats/glossy_factors.h"
#include "runtime/brdf.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/scene.h"
#include "vocabulary/vec3.h"
#include "worker/embree_scene.h"

namespace prt {

// One spatial sample: a point on a surface with its shading normal and the geometric normal of
// (one of) its triangles, which the robust ray-origin offset uses.
struct SpatialSample {
  Vec3 position;
  Vec3 normal;            // unit shading normal (the cosine term and the horizon use it)
  Vec3 geometric_normal;  // unit, same hemisphere as normal
  // A camera pixel that sees the environment directly (worker/camera_samples.h): no surface, so
  // its row of T is 0 (every kernel returns zeros without tracing); the viewer draws the
  // environment there.
  bool background = false;
  // A supersampled camera pixel (docs/image-relighting.md, "Supersampling"): its row is the
  // λ-weighted mix of its footprint's sub-samples' rows (SampleFootprints), and this sample is
  // only the representative point (the sparse method's neighbour position).
  bool supersampled = false;
  // A glossy camera pixel (docs/image-relighting.md, "Glossy pixels"): the index of its material
  // in GlossySampling::materials; kDiffuseSample for every other sample.
  uint32_t glossy_material = 0xFFFFFFFFu;
  // Glossy vertex transport (docs/glossy-transport.md): with GlossySampling::factors, a sample
  // with glossy_material = i is one term of the BRDF in-out factorisation, its row
  // T_term(x, ω) = ∫ V·f_term(ω) dω with factors->factors[i]; the run's rows are the vertices
  // once per term (term-major). The sparse method keeps each term's neighbours in its own term.
  uint8_t term = 0;
};
inline constexpr uint32_t kDiffuseSample = 0xFFFFFFFFu;

// Samples of a scene in prtfarm's global order (scene.h): meshes in file order, ground last;
// each mesh's vertices in order. The geometric normal is the normalised sum of the incident
// triangles' cross products (area-weighted face normals), flipped into the shading normal's
// hemisphere. A vertex without a usable shading normal takes the geometric one; one with
// neither (no non-degenerate triangle) gets +Y.
std::vector<SpatialSample> SpatialSamplesOf(const SceneGeometry& geometry);

struct TransportSamplerOptions {
  // Stratified jittered rays per texel, in [1, 1024]: an a×b grid of strata in the texel's face
  // coordinates (u, v) with b the largest divisor of k not above √k and a = k/b (2×2 for 4).
  int rays_per_texel = 4;
  uint64_t seed = 1;  // rows are a pure function of (seed, global sample index)
};

// Glossy camera pixels (docs/image-relighting.md, "Glossy pixels"): a sample with
// glossy_material = i has the row
//   T[x][j] = ∫_texel_j V(x, ω) · [k_d/π + k_s·f_s(ω, ω_o)] · max(0, n·ω) dω
// with k_d = materials[i].diffuse[0], k_s = .specular[0], f_s its lobe (runtime/brdf.h) and
// ω_o = normalize(eye − x), estimated by the same strata and rays as the diffuse row: each ray's
// weight Ω_s·cos/π becomes Ω_s·cos·(k_d/π + k_s·f_s), so the lobe is sampled at the texel's
// rays_per_texel jittered directions and a lobe narrower than a texel is under-resolved
// (docs/image-relighting.md measures it). The unoccluded estimate (ComputeUnoccludedTexels)
// and the variance carry the same weights.
// Glossy vertex transport (docs/glossy-transport.md): with `factors` set, glossy_material
// indexes factors->factors instead and the ray weight Ω_s·cos/π becomes Ω_s·f_term(ω), f looked
// up in the vertex's factor frame (formats/glossy_factors.h); f_term carries the cosine and
// may be negative (terms after the first). The horizon rules are unchanged (f = 0 below it).
struct GlossySampling {
  std::vector<Material> materials;
  Vec3 eye{0, 0, 0};
  std::shared_ptr<const GlossyFactorTable> factors{};
};

// Supersampled camera pixels (docs/image-relighting.md, "Supersampling"): the surface
// sub-samples of each pixel footprint and their mixing weights λ (Σ λ = 1). A sample with
// `supersampled` set and global index i has the row
//   R[i][j] = Σ_s λ_s T(x_s)[j]
// estimated at the cost of one row: the same strata and jittered directions as an ordinary row,
// each ray r of texel j taking sub-sample s by the stratified inverse CDF of λ at
// u = frac((r + ½)/rays + φ_j), φ_j uniform per texel (from the sample's stream), and its weight
// Ω_r·V·cos/π (or the glossy weight) evaluated at that sub-sample's point, normal and material:
// unbiased for Σ_s λ_s T_s. A texel is skipped only below the horizon of every sub-sample. The
// unoccluded estimate is the same mix with V ≡ 1.
struct SampleFootprints {
  // Sample i's sub-samples are subs[offset[i] … offset[i+1]) with cumulative λ in cdf (the last
  // of each range is 1); offset has one entry per sample plus one.
  std::vector<uint32_t> offset;
  std::vector<SpatialSample> subs;
  std::vector<double> cdf;
  // Parallel to subs: the longest edge of each sub-sample's triangle (the bounce gather's near
  // field compares hits with it, as with CameraSamples::pixel_edge).
  std::vector<float> edge;
};

// Counters a job reports (added up by the coordinator into run/report.json).
struct SampleStats {
  uint64_t rays_traced = 0;           // occlusion rays given to Embree
  uint64_t texels_traced = 0;         // texels meeting the upper hemisphere (evaluated)
  uint64_t texels_below_horizon = 0;  // texels entirely below the horizon: skipped, T = 0
  uint64_t rays_below_horizon = 0;    // strata of evaluated texels below the horizon: not traced
  SampleStats& operator+=(const SampleStats& o) {
    rays_traced += o.rays_traced;
    texels_traced += o.texels_traced;
    texels_below_horizon += o.texels_below_horizon;
    rays_below_horizon += o.rays_below_horizon;
    return *this;
  }
  bool operator==(const SampleStats&) const = default;
};

// Thread-safe after construction: one sampler serves every thread of a rank. The scene must
// outlive it.
class TransportSampler {
 public:
  // cubemap_n: a power of two in [1, 256] (CubemapLayout). Throws std::invalid_argument on a bad
  // n or rays_per_texel outside [1, 1024].
  // footprints: the sub-samples of supersampled camera pixels (indexed by the global sample
  // index), or null; a sample with `supersampled` set needs its (non-empty) entry.
  TransportSampler(const EmbreeScene& scene, int cubemap_n, TransportSamplerOptions options,
                   GlossySampling glossy = {},
                   std::shared_ptr<const SampleFootprints> footprints = nullptr);
  ~TransportSampler();
  TransportSampler(const TransportSampler&) = delete;
  TransportSampler& operator=(const TransportSampler&) = delete;

  const CubemapLayout& layout() const;
  const TransportSamplerOptions& options() const;
  const GlossySampling& glossy() const;
  const SampleFootprints* footprints() const;
  // The stratum grid: strata_u() × strata_v() = rays_per_texel; stratum s = sv·strata_u() + su.
  int strata_u() const;
  int strata_v() const;
  // Exact solid angle Ω_s of stratum s of texel `texel` (FaceRectSolidAngle of its rectangle).
  double StratumSolidAngle(std::size_t texel, int stratum) const;

  // Every function below throws prt::NumericalError when the sample's position is not finite
  // or its normal is zero or not finite (SpatialSamplesOf never produces such a sample).

  // Full row of T for one sample (layout().texel_count() floats). `sample_index` is the
  // sample's global index: it seeds the jitter, so a row is identical whichever rank, thread
  // or batch computes it. Thread-safe; no allocation inside (but a supersampled pixel's sub-sample
  // frames). variance (optional, texel_count floats): each texel's Monte-Carlo variance Var(T_j),
  // estimated from the same rays by collapsing neighbouring strata in pairs (docs/
  // transport-sampling.md, "Monte-Carlo error"); 0 below the horizon, and 0 everywhere when
  // !VarianceEstimable(). The row's bytes do not depend on whether it is asked for.
  SampleStats ComputeRow(const SpatialSample& sample, uint64_t sample_index, float* row,
                         float* variance = nullptr) const;
  // Whether the variance outputs mean anything: at least two rays (strata) per texel.
  bool VarianceEstimable() const;

  // Only the listed texels (for adaptive angular sampling and sparse vertices); values[i] is
  // T for texels[i], using the same jitter as ComputeRow (so values agree bit for bit). Throws
  // std::out_of_range on a texel index ≥ layout().texel_count().
  // unoccluded (optional): receives, for each texel, the same estimate with visibility ≡ 1
  // from the same rays (bit-identical to ComputeUnoccludedTexels), at no extra tracing cost.
  // variance (optional): each listed texel's variance, as ComputeRow's.
  SampleStats ComputeTexels(const SpatialSample& sample, uint64_t sample_index,
                            std::span<const uint32_t> texels, float* values,
                            float* unoccluded = nullptr, float* variance = nullptr) const;

  // U_j for the listed texels: the estimator of ComputeTexels with visibility ≡ 1 (the same
  // jittered directions and weights, no rays traced), so T_j / U_j ∈ [0, 1] is the visible
  // fraction of texel j and equals 1 exactly where no ray was blocked. Texels below the horizon
  // give 0. Throws std::out_of_range like ComputeTexels. Used by adaptive angular sampling and
  // sparse reconstruction (Huang & Ramamoorthi 2010).
  void ComputeUnoccludedTexels(const SpatialSample& sample, uint64_t sample_index,
                               std::span<const uint32_t> texels, float* values) const;

  // Rows for samples[0..count) with global indices first_index.., into out (count rows,
  // row-major), in parallel over samples with TBB.
  // variance (optional): count rows of per-texel variances, as ComputeRow's.
  SampleStats ComputeRows(std::span<const SpatialSample> samples, uint64_t first_index, float* out,
                          float* variance = nullptr) const;

  // The occlusion rays ComputeRow traces for this sample, in the order it traces them, appended
  // to `rays` (for the raw-Embree reference in bench/transport_bench.cpp and for tests).
  void AppendRowRays(const SpatialSample& sample, uint64_t sample_index,
                     std::vector<OcclusionRay>& rays) const;

  // For benchmarks: with `on`, the thread CPU time spent inside ComputeRow and ComputeTexels
  // (the tracing and the estimator around it; clock_gettime per call) is summed over all
  // threads; resets the sum either way. Not thread-safe against concurrent Compute* calls.
  void MeasureTraceCpu(bool on);
  // The sum since the last MeasureTraceCpu call, in seconds.
  double trace_cpu_seconds() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace prt
