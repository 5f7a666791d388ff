#include "worker/transport_sampler.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// Key of one row: depends on (seed, global sample index) only.
constexpr uint64_t RowKey(uint64_t seed, uint64_t sample_index) {
  return SplitMix64(SplitMix64(seed ^ 0x5052544641524D31ull) ^ sample_index);
}

// Largest divisor of k not above √k: the strata grid is (k / b) × b.
int StrataV(int k) {
  int b = 1;
  for (int d = 1; d * d <= k; ++d) {
    if (k % d == 0) b = d;
  }
  return b;
}

// Everything a row needs about its sample, computed once per call.
struct SampleFrame {
  Vec3 normal;  // unit shading normal
  // A glossy pixel's material (GlossySampling::materials) and its frame with the
  // view towards the eye; nullptr for a diffuse sample.
  const Material* material = nullptr;
  ShadingFrame shading;
  // A glossy vertex's term of the factorisation (GlossySampling::factors), else nullptr.
  const BrdfFactors* factors = nullptr;
  int term = 0;
  FactorFrame factor_frame;
  OcclusionRay ray{};  // origin, tnear, tfar filled; direction per ray
  uint64_t key = 0;    // RowKey(seed, sample index)
  // A supersampled pixel (SampleFootprints): its sub-samples' frames and cumulative λ; empty
  // for every other sample.
  std::vector<SampleFrame> subs;
  const double* cdf = nullptr;
  // Per texel: above the horizon of any sub-sample (CubemapLayout::AboveHorizonMask of each
  // distinct sub-sample normal, OR-ed; the same corner test as TexelAboveHorizon).
  std::vector<uint8_t> above;
};

// The texel offset φ_j of a supersampled pixel's stratified sub-sample choice, in [0, 1).
double FootprintOffset(uint64_t key, std::size_t texel) {
  const uint64_t bits =
      SplitMix64(SplitMix64(key ^ 0x464F4F5450524E54ull) ^ static_cast<uint64_t>(texel));
  return static_cast<double>(bits >> 11) * 0x1p-53;
}

// What happens to the generated rays (Impl::Flush): traced by Embree, taken as unoccluded, or
// collected. One compiled EvaluateTexel and one Flush serve every mode (a predictable branch per
// batch), so ComputeRow, ComputeTexels, ComputeUnoccludedTexels and AppendRowRays use
// bit-identical directions and sums whatever the compiler does with floating-point contraction.
struct Tracer {
  enum Mode { kEmbree, kUnoccluded, kCollect } mode;
  const EmbreeScene* scene = nullptr;         // kEmbree
  std::vector<OcclusionRay>* rays = nullptr;  // kCollect
};

}  // namespace

struct TransportSampler::Impl {
  const EmbreeScene& scene;
  CubemapLayout layout;
  TransportSamplerOptions options;
  GlossySampling glossy;
  std::shared_ptr<const SampleFootprints> footprints;
  int strata_u = 1;
  int strata_v = 1;
  // Ω_s for every stratum of every texel of one face (all faces share it): index
  // (y·n + x)·k + s.
  std::vector<double> stratum_omega;
  // Thread CPU nanoseconds spent in ComputeRow / ComputeTexels while measure_trace_cpu is set.
  std::atomic<bool> measure_trace_cpu{false};
  mutable std::atomic<uint64_t> trace_cpu_ns{0};

  Impl(const EmbreeScene& s, int n, const TransportSamplerOptions& o, GlossySampling g,
       std::shared_ptr<const SampleFootprints> fp)
      : scene(s), layout(n), options(o), glossy(std::move(g)), footprints(std::move(fp)) {
    const int k = o.rays_per_texel;
    if (k < 1 || k > 1024) {
      throw std::invalid_argument("TransportSampler: rays_per_texel must be in [1, 1024], got " +
                                  std::to_string(k));
    }
    strata_v = StrataV(k);
    strata_u = k / strata_v;
    stratum_omega.resize(layout.face_size() * static_cast<std::size_t>(k));
    const double h = 2.0 / n;
    const double du = h / strata_u, dv = h / strata_v;
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const double u0 = -1 + h * x, v0 = -1 + h * y;
        for (int sv = 0; sv < strata_v; ++sv) {
          for (int su = 0; su < strata_u; ++su) {
            // The stratum edges are computed as the jittered rays compute them (u0 + i·du), so
            // neighbouring strata share their edge and the strata tile the texel exactly.
            stratum_omega[(static_cast<std::size_t>(y) * n + x) * k + sv * strata_u + su] =
                FaceRectSolidAngle(u0 + su * du, su + 1 == strata_u ? u0 + h : u0 + (su + 1) * du,
                                   v0 + sv * dv, sv + 1 == strata_v ? v0 + h : v0 + (sv + 1) * dv);
          }
        }
      }
    }
  }

  SampleFrame Frame(const SpatialSample& sample, uint64_t sample_index) const {
    SampleFrame f = PointFrame(sample, sample_index);
    if (!sample.supersampled) return f;
    const SampleFootprints* fp = footprints.get();
    if (fp == nullptr || sample_index + 1 >= fp->offset.size() ||
        fp->offset[sample_index] >= fp->offset[sample_index + 1] ||
        fp->offset[sample_index + 1] > fp->subs.size() || fp->cdf.size() != fp->subs.size()) {
      throw std::logic_error("TransportSampler: supersampled sample " +
                             std::to_string(sample_index) + " has no footprint");
    }
    const uint32_t begin = fp->offset[sample_index], end = fp->offset[sample_index + 1];
    f.subs.reserve(end - begin);
    for (uint32_t i = begin; i < end; ++i) f.subs.push_back(PointFrame(fp->subs[i], sample_index));
    f.cdf = fp->cdf.data() + begin;
    const std::size_t count = layout.texel_count();
    f.above.assign(count, 0);
    std::vector<uint8_t> mask(count);
    std::vector<Vec3> seen;
    for (const SampleFrame& sub : f.subs) {
      if (std::find(seen.begin(), seen.end(), sub.normal) != seen.end()) continue;
      seen.push_back(sub.normal);
      layout.AboveHorizonMask(sub.normal, mask.data());
      for (std::size_t j = 0; j < count; ++j) f.above[j] |= mask[j];
    }
    return f;
  }

  SampleFrame PointFrame(const SpatialSample& sample, uint64_t sample_index) const {
    SampleFrame f;
    const double len = Length(sample.normal);
    if (!IsFinite(sample.position) || !std::isfinite(len) || len == 0) {
      throw NumericalError("TransportSampler: sample " + std::to_string(sample_index) +
                           " has a non-finite position or a zero/non-finite normal");
    }
    f.normal = std::abs(len - 1) > 1e-12 ? sample.normal / len : sample.normal;
    Vec3 ng = sample.geometric_normal;
    const double lg = Length(ng);
    ng = (std::isfinite(lg) && lg > 0) ? ng / lg : f.normal;
    if (Dot(ng, f.normal) < 0) ng = -ng;
    scene.RobustOrigin(sample.position, ng, f.ray.origin);
    f.ray.tnear = 0.0f;
    f.ray.tfar = std::numeric_limits<float>::infinity();
    f.key = RowKey(options.seed, sample_index);
    if (sample.glossy_material != kDiffuseSample) {
      if (!glossy.factors && sample.glossy_material >= glossy.materials.size()) {
        throw std::out_of_range("TransportSampler: sample " + std::to_string(sample_index) +
                                " names glossy material " + std::to_string(sample.glossy_material) +
                                " of " + std::to_string(glossy.materials.size()));
      }
      if (glossy.factors) {
        if (sample.glossy_material >= glossy.factors->factors.size() ||
            sample.term >= glossy.factors->terms)
          throw std::out_of_range("TransportSampler: sample " + std::to_string(sample_index) +
                                  " names factors " + std::to_string(sample.glossy_material) +
                                  " term " + std::to_string(sample.term));
        f.factors = &glossy.factors->factors[sample.glossy_material];
        f.term = sample.term;
        f.factor_frame = MakeFactorFrame(f.normal);
      } else {
        f.material = &glossy.materials[sample.glossy_material];
        f.shading = MakeShadingFrame(f.normal, glossy.eye - sample.position);
      }
    }
    return f;
  }

  // Rays of one sample's texels, traced EmbreeScene::kPacket at a time as one packet and summed
  // per texel afterwards, in stratum order, so that a texel's value does not depend on which
  // rays shared its packet (rays from one point in neighbouring directions: 2.3× the throughput
  // of one rtcOccluded1 call per ray, bench/transport_bench.cpp).
  static constexpr int kMaxBlocksPerBand = 32;
  struct Batch {
    static constexpr int kRays = static_cast<int>(EmbreeScene::kPacket);
    struct Open {  // a texel whose value is not written yet
      double sum = 0, unocc = 0;
      float* value = nullptr;
      float* unoccluded = nullptr;
      float* variance = nullptr;  // the collapsed-strata variance estimate (see AddToVariance)
      // The group being summed and the finished groups' total. Pairs: Σx and Σx² of the pair's
      // strata. 2×2 blocks: the signed sums of the current band of two stratum rows are in
      // Batch::block, row = the texel's slot (only touched when the variance is asked for, so
      // that opening a texel stays a few words).
      int group = -1;
      double gx = 0, gxx = 0, var = 0;
      bool complete = false;
    };
    OcclusionRay rays[kRays];
    double weight[kRays];  // Ω_s·cos of each ray
    int slot[kRays];       // the open texel it belongs to
    int stratum[kRays];    // its stratum (with variance only)
    int count = 0;
    Open open[kRays + 1];
    double block[kRays + 1][kMaxBlocksPerBand];  // per slot, see Open
    int opened = 0;
  };

  // The Monte-Carlo variance of a texel's estimate, from its own rays (docs/transport-sampling.md,
  // "Monte-Carlo error"). One ray per stratum gives no variance per stratum, so neighbouring
  // strata are compared (collapsed strata, Cochran, Sampling Techniques §5A.12). The strata
  // values are x_s = Ω_s·V(ω_s)·cos(ω_s) (0 for a stratum below the horizon); their means differ
  // across a texel (the cosine, a visibility edge), and a plain difference of neighbours counts
  // that trend as noise. So where the stratum grid allows (a and b even, a/2 ≤ 32), strata go in
  // 2×2 blocks and each block's second difference d = x₀₀ − x₁₀ − x₀₁ + x₁₁ is used:
  // E[d²] = Σ Var(x) + (the trend's second difference)², unbiased for any trend linear across
  // the block (a straight visibility edge, the cosine's gradient). Otherwise strata go in pairs
  // along u (the last pair takes a third when k is odd), with g/(g−1)·Σ(x − x̄)². The texel's
  // variance is the sum over its blocks or pairs, divided by π². k = 1 has nothing to compare:
  // the variance is reported as 0 (VarianceEstimable() is false).
  bool UseBlocks() const {
    return strata_u % 2 == 0 && strata_v % 2 == 0 && strata_u / 2 <= kMaxBlocksPerBand;
  }
  int PairOf(int stratum) const {
    const int k = options.rays_per_texel;
    return std::min(stratum / 2, std::max(0, k / 2 - 1));
  }
  int PairSize(int pair) const {
    const int k = options.rays_per_texel;
    if (k < 2) return 1;
    return pair == k / 2 - 1 ? 2 + k % 2 : 2;
  }
  void FoldVarianceGroup(Batch::Open& t, double* block) const {
    if (t.group >= 0) {
      if (UseBlocks()) {
        for (int i = 0; i < strata_u / 2; ++i) {
          t.var += block[i] * block[i];
          block[i] = 0;
        }
      } else {
        const int g = PairSize(t.group);
        if (g >= 2) t.var += std::max(0.0, t.gxx - t.gx * t.gx / g) * g / (g - 1);
      }
    }
    t.group = -1;
    t.gx = t.gxx = 0;
  }
  // Adds the value x of stratum s of texel t, whose block sums are `block` (strata arrive in
  // increasing order).
  void AddToVariance(Batch::Open& t, double* block, int s, double x) const {
    if (UseBlocks()) {
      const int su = s % strata_u, sv = s / strata_u;
      if (sv / 2 != t.group) {
        FoldVarianceGroup(t, block);
        t.group = sv / 2;
      }
      block[su / 2] += ((su ^ sv) & 1) ? -x : x;
      return;
    }
    if (PairOf(s) != t.group) {
      FoldVarianceGroup(t, block);
      t.group = PairOf(s);
    }
    t.gx += x;
    t.gxx += x * x;
  }

  // Traces the batch's rays, adds each one's weight to its texel in order (the unoccluded sum
  // always, the sum when nothing blocks it), writes the texels whose rays are all in, and keeps
  // the one still receiving rays (a texel of more than kRays strata) as the first open texel.
  [[gnu::noinline]] void Flush(Batch& b, const Tracer& trace) const {
    bool blocked[Batch::kRays];
    switch (trace.mode) {
      case Tracer::kEmbree:
        trace.scene->OccludedPacket(std::span<const OcclusionRay>(b.rays, b.count), blocked);
        break;
      case Tracer::kCollect:
        for (int i = 0; i < b.count; ++i) {
          trace.rays->push_back(b.rays[i]);
          blocked[i] = true;
        }
        break;
      default:
        std::fill_n(blocked, b.count, false);
    }
    for (int i = 0; i < b.count; ++i) {
      Batch::Open& t = b.open[b.slot[i]];
      t.unocc += b.weight[i];
      if (!blocked[i]) t.sum += b.weight[i];
      if (t.variance != nullptr) {
        AddToVariance(t, b.block[b.slot[i]], b.stratum[i], blocked[i] ? 0.0 : b.weight[i]);
      }
    }
    int kept = 0;
    for (int o = 0; o < b.opened; ++o) {
      Batch::Open& t = b.open[o];
      if (!t.complete) {
        if (t.variance != nullptr && kept != o)
          std::copy_n(b.block[o], kMaxBlocksPerBand, b.block[kept]);
        b.open[kept++] = t;
        continue;
      }
      if (t.value != nullptr) *t.value = static_cast<float>(t.sum * std::numbers::inv_pi);
      if (t.unoccluded != nullptr) {
        *t.unoccluded = static_cast<float>(t.unocc * std::numbers::inv_pi);
      }
      if (t.variance != nullptr) {
        FoldVarianceGroup(t, b.block[o]);
        *t.variance = static_cast<float>(t.var * (std::numbers::inv_pi * std::numbers::inv_pi));
      }
    }
    b.opened = kept;
    b.count = 0;
  }

  // (1/π)·Σ_s Ω_s·V(ω_s)·max(0, n·ω_s) over the strata of texel (face, x, y) — DESIGN.md's
  // transport integral, estimated by stratified jittered sampling in the face coordinates with
  // exact stratum solid angles as weights (docs/transport-sampling.md, "Estimator"). The rays
  // join the batch; the value (and, with `unoccluded`, the same sum with V ≡ 1 from the same
  // rays) is written when the batch is flushed. Not inlined: one compiled copy of the
  // directions' arithmetic serves every caller (see Tracer).
  [[gnu::noinline]] void EvaluateTexel(const SampleFrame& f, int face, int x, int y,
                                       std::size_t texel, SampleStats& stats, const Tracer& trace,
                                       Batch& b, float* value, float* unoccluded,
                                       float* variance) const {
    const int n = layout.n();
    const int k = options.rays_per_texel;
    const double h = 2.0 / n;
    const double du = h / strata_u, dv = h / strata_v;
    const double u0 = -1 + h * x, v0 = -1 + h * y;
    const double* omega = &stratum_omega[(static_cast<std::size_t>(y) * n + x) * k];
    const uint64_t base = static_cast<uint64_t>(texel) * static_cast<uint64_t>(k);
    if (b.opened == Batch::kRays + 1) Flush(b, trace);
    int slot = b.opened++;
    b.open[slot] = Batch::Open{};
    b.open[slot].value = value;
    b.open[slot].unoccluded = unoccluded;
    b.open[slot].variance = variance;
    if (variance != nullptr) std::fill_n(b.block[slot], kMaxBlocksPerBand, 0.0);
    // Directions are computed a chunk of strata at a time before any joins the batch: the
    // chunk's computations (a square root and a division each) are independent, so they overlap
    // instead of each waiting on the bookkeeping of the one before. Each ray's arithmetic and the
    // order of the sums do not depend on the chunking.
    constexpr int kChunk = 16;
    float dir[kChunk][3];
    double cosine[kChunk];
    Vec3 unit[kChunk];                // the directions in double (glossy pixels' BRDF)
    const SampleFrame* from[kChunk];  // the point each ray leaves (a sub-sample, or the sample)
    const std::size_t subs = f.subs.size();
    const double phi = subs == 0 ? 0.0 : FootprintOffset(f.key, texel);
    int su = 0, sv = 0;
    for (int s0 = 0; s0 < k; s0 += kChunk) {
      const int count = std::min(kChunk, k - s0);
      for (int i = 0; i < count; ++i) {
        // Jitter = pure function of (seed, sample index, texel, stratum); open interval (0, 1).
        const uint64_t bits = SplitMix64(f.key ^ (base + static_cast<uint64_t>(s0 + i)));
        const double ju = (static_cast<double>(bits >> 32) + 0.5) * 0x1p-32;
        const double jv = (static_cast<double>(bits & 0xFFFFFFFFull) + 0.5) * 0x1p-32;
        const double u = u0 + (su + ju) * du;
        const double v = v0 + (sv + jv) * dv;
        const double inv = 1.0 / std::sqrt(1.0 + u * u + v * v);
        const Vec3 d = CubemapLayout::FacePoint(face, u, v) * inv;
        from[i] = &f;
        if (subs != 0) {  // stratified inverse CDF of λ
          double w = (s0 + i + 0.5) / k + phi;
          w -= std::floor(w);
          const std::size_t pick =
              static_cast<std::size_t>(std::upper_bound(f.cdf, f.cdf + subs, w) - f.cdf);
          from[i] = &f.subs[std::min(pick, subs - 1)];
        }
        cosine[i] = Dot(from[i]->normal, d);
        unit[i] = d;
        dir[i][0] = static_cast<float>(d.x);
        dir[i][1] = static_cast<float>(d.y);
        dir[i][2] = static_cast<float>(d.z);
        if (++su == strata_u) {  // stratum s = sv·strata_u + su
          su = 0;
          ++sv;
        }
      }
      for (int i = 0; i < count; ++i) {
        const double c = cosine[i];
        if (!(c > 0)) {  // below the horizon inside a partly visible texel: 0, not traced
          ++stats.rays_below_horizon;
          continue;
        }
        ++stats.rays_traced;
        const SampleFrame& p = *from[i];
        OcclusionRay& ray = b.rays[b.count];
        ray = p.ray;
        ray.direction[0] = dir[i][0];
        ray.direction[1] = dir[i][1];
        ray.direction[2] = dir[i][2];
        // Diffuse: Ω_s·cos (the 1/π comes at Flush). Glossy pixel: Ω_s·(k_d·cos + π·k_s·f_s·cos).
        // Glossy vertex term: Ω_s·π·f_term(ω).
        b.weight[b.count] =
            p.factors != nullptr ? omega[s0 + i] * std::numbers::pi *
                                       p.factors->F(p.term, p.factor_frame.ToLocal(unit[i]))
            : p.material == nullptr
                ? omega[s0 + i] * c
                : omega[s0 + i] * (p.material->diffuse[0] * c +
                                   std::numbers::pi * p.material->specular[0] *
                                       SpecularLobe(*p.material, p.shading, unit[i]));
        b.slot[b.count] = slot;
        b.stratum[b.count] = s0 + i;
        if (++b.count == Batch::kRays) {
          Flush(b, trace);
          slot = b.opened - 1;  // this texel, the one left open, moved to the front
        }
      }
    }
    b.open[slot].complete = true;
    ++stats.texels_traced;
  }

  // A face whose four corners are all below (above) the horizon plane by more than the
  // rounding error of a corner's dot product has every texel below (above): n·p is linear on
  // the face and texel corners are exact in double, so TexelAboveHorizon would say the same for
  // each texel. Used to skip per-texel horizon tests; the counts stay exact.
  enum class FaceSide { kBelow, kAbove, kMixed };
  static FaceSide ClassifyFace(int face, const Vec3& nrm) {
    constexpr double kMargin = 1e-12;  // ≫ 3·2⁻⁵³·(|x|+|y|+|z|) for |p|∞ = 1, |n| = 1
    int below = 0, above = 0;
    for (int c = 0; c < 4; ++c) {
      const double d =
          Dot(CubemapLayout::FacePoint(face, c & 1 ? 1.0 : -1.0, c & 2 ? 1.0 : -1.0), nrm);
      below += d < -kMargin ? 1 : 0;
      above += d > kMargin ? 1 : 0;
    }
    return below == 4 ? FaceSide::kBelow : (above == 4 ? FaceSide::kAbove : FaceSide::kMixed);
  }

  // Whether texel j (its face `face`) is above the horizon of the sample, or of any sub-sample of
  // a supersampled pixel.
  FaceSide Side(int face, const SampleFrame& f) const {
    if (f.subs.empty()) return ClassifyFace(face, f.normal);
    bool below = true, above = true;
    for (const SampleFrame& sub : f.subs) {
      const FaceSide side = ClassifyFace(face, sub.normal);
      below = below && side == FaceSide::kBelow;
      above = above && side == FaceSide::kAbove;
    }
    return below ? FaceSide::kBelow : (above ? FaceSide::kAbove : FaceSide::kMixed);
  }
  bool Above(std::size_t j, const SampleFrame& f) const {
    if (f.subs.empty()) return layout.TexelAboveHorizon(j, f.normal);
    return f.above[j] != 0;
  }

  SampleStats Row(const SpatialSample& sample, uint64_t sample_index, float* row,
                  const Tracer& trace, float* variance = nullptr) const {
    if (sample.background) {  // no surface: T = 0, nothing traced
      if (row != nullptr) std::fill(row, row + layout.texel_count(), 0.0f);
      if (variance != nullptr) std::fill(variance, variance + layout.texel_count(), 0.0f);
      return {};
    }
    const ScopedFlushDenormals ftz;
    const SampleFrame f = Frame(sample, sample_index);
    SampleStats stats;
    Batch batch;
    const int n = layout.n();
    std::size_t j = 0;
    for (int face = 0; face < 6; ++face) {
      const FaceSide side = Side(face, f);
      if (side == FaceSide::kBelow) {
        stats.texels_below_horizon += layout.face_size();
        if (row != nullptr) std::fill(row + j, row + j + layout.face_size(), 0.0f);
        if (variance != nullptr) {
          std::fill(variance + j, variance + j + layout.face_size(), 0.0f);
        }
        j += layout.face_size();
        continue;
      }
      for (int y = 0; y < n; ++y) {
        for (int x = 0; x < n; ++x, ++j) {
          if (side == FaceSide::kMixed && !Above(j, f)) {
            ++stats.texels_below_horizon;
            if (row != nullptr) row[j] = 0.0f;
            if (variance != nullptr) variance[j] = 0.0f;
            continue;
          }
          EvaluateTexel(f, face, x, y, j, stats, trace, batch, row != nullptr ? row + j : nullptr,
                        nullptr, variance != nullptr ? variance + j : nullptr);
        }
      }
    }
    Flush(batch, trace);
    return stats;
  }

  SampleStats Texels(const SpatialSample& sample, uint64_t sample_index,
                     std::span<const uint32_t> texels, float* values, const Tracer& trace,
                     float* unoccluded = nullptr, float* variance = nullptr) const {
    const std::size_t count = layout.texel_count();
    for (uint32_t j : texels) {
      if (j >= count) {
        throw std::out_of_range("TransportSampler: texel " + std::to_string(j) +
                                " >= " + std::to_string(count));
      }
    }
    if (sample.background) {  // no surface: T = 0, nothing traced
      std::fill(values, values + texels.size(), 0.0f);
      if (unoccluded != nullptr) std::fill(unoccluded, unoccluded + texels.size(), 0.0f);
      if (variance != nullptr) std::fill(variance, variance + texels.size(), 0.0f);
      return {};
    }
    const ScopedFlushDenormals ftz;
    const SampleFrame f = Frame(sample, sample_index);
    SampleStats stats;
    Batch batch;
    for (std::size_t i = 0; i < texels.size(); ++i) {
      const std::size_t j = texels[i];
      if (!Above(j, f)) {
        ++stats.texels_below_horizon;
        values[i] = 0.0f;
        if (unoccluded != nullptr) unoccluded[i] = 0.0f;
        if (variance != nullptr) variance[i] = 0.0f;
        continue;
      }
      const TexelCoord c = layout.Coord(j);
      EvaluateTexel(f, c.face, c.x, c.y, j, stats, trace, batch, values + i,
                    unoccluded != nullptr ? unoccluded + i : nullptr,
                    variance != nullptr ? variance + i : nullptr);
    }
    Flush(batch, trace);
    return stats;
  }
};

TransportSampler::TransportSampler(const EmbreeScene& scene, int cubemap_n,
                                   TransportSamplerOptions options, GlossySampling glossy,
                                   std::shared_ptr<const SampleFootprints> footprints)
    : impl_(std::make_unique<Impl>(scene, cubemap_n, options, std::move(glossy),
                                   std::move(footprints))) {}

TransportSampler::~TransportSampler() = default;

const CubemapLayout& TransportSampler::layout() const {
  return impl_->layout;
}
const TransportSamplerOptions& TransportSampler::options() const {
  return impl_->options;
}
const GlossySampling& TransportSampler::glossy() const {
  return impl_->glossy;
}
const SampleFootprints* TransportSampler::footprints() const {
  return impl_->footprints.get();
}
int TransportSampler::strata_u() const {
  return impl_->strata_u;
}
int TransportSampler::strata_v() const {
  return impl_->strata_v;
}

double TransportSampler::StratumSolidAngle(std::size_t texel, int stratum) const {
  const std::size_t fs = impl_->layout.face_size();
  const int k = impl_->options.rays_per_texel;
  if (texel >= impl_->layout.texel_count() || stratum < 0 || stratum >= k) {
    throw std::out_of_range("TransportSampler::StratumSolidAngle: texel or stratum out of range");
  }
  return impl_->stratum_omega[(texel % fs) * k + stratum];
}

namespace {

uint64_t ThreadCpuNanoseconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<uint64_t>(ts.tv_sec) * 1000000000u + static_cast<uint64_t>(ts.tv_nsec);
}

// Adds the calling thread's CPU time over its lifetime to `total` when `on`.
class ScopedThreadCpu {
 public:
  ScopedThreadCpu(bool on, std::atomic<uint64_t>& total)
      : total_(on ? &total : nullptr), start_(on ? ThreadCpuNanoseconds() : 0) {}
  ~ScopedThreadCpu() {
    if (total_ != nullptr) total_->fetch_add(ThreadCpuNanoseconds() - start_);
  }
  ScopedThreadCpu(const ScopedThreadCpu&) = delete;
  ScopedThreadCpu& operator=(const ScopedThreadCpu&) = delete;

 private:
  std::atomic<uint64_t>* total_;
  uint64_t start_;
};

}  // namespace

SampleStats TransportSampler::ComputeRow(const SpatialSample& sample, uint64_t sample_index,
                                         float* row, float* variance) const {
  const ScopedThreadCpu cpu(impl_->measure_trace_cpu.load(std::memory_order_relaxed),
                            impl_->trace_cpu_ns);
  return impl_->Row(sample, sample_index, row, Tracer{Tracer::kEmbree, &impl_->scene, nullptr},
                    variance);
}

bool TransportSampler::VarianceEstimable() const {
  return impl_->options.rays_per_texel >= 2;
}

SampleStats TransportSampler::ComputeTexels(const SpatialSample& sample, uint64_t sample_index,
                                            std::span<const uint32_t> texels, float* values,
                                            float* unoccluded, float* variance) const {
  const ScopedThreadCpu cpu(impl_->measure_trace_cpu.load(std::memory_order_relaxed),
                            impl_->trace_cpu_ns);
  return impl_->Texels(sample, sample_index, texels, values,
                       Tracer{Tracer::kEmbree, &impl_->scene, nullptr}, unoccluded, variance);
}

void TransportSampler::MeasureTraceCpu(bool on) {
  impl_->trace_cpu_ns = 0;
  impl_->measure_trace_cpu = on;
}

double TransportSampler::trace_cpu_seconds() const {
  return static_cast<double>(impl_->trace_cpu_ns.load()) * 1e-9;
}

void TransportSampler::ComputeUnoccludedTexels(const SpatialSample& sample, uint64_t sample_index,
                                               std::span<const uint32_t> texels,
                                               float* values) const {
  impl_->Texels(sample, sample_index, texels, values,
                Tracer{Tracer::kUnoccluded, nullptr, nullptr});
}

SampleStats TransportSampler::ComputeRows(std::span<const SpatialSample> samples,
                                          uint64_t first_index, float* out, float* variance) const {
  const std::size_t row_size = impl_->layout.texel_count();
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, samples.size()), SampleStats{},
      [&](const tbb::blocked_range<std::size_t>& r, SampleStats acc) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          acc += ComputeRow(samples[i], first_index + i, out + i * row_size,
                            variance != nullptr ? variance + i * row_size : nullptr);
        }
        return acc;
      },
      [](SampleStats a, const SampleStats& b) { return a += b; });
}

void TransportSampler::AppendRowRays(const SpatialSample& sample, uint64_t sample_index,
                                     std::vector<OcclusionRay>& rays) const {
  impl_->Row(sample, sample_index, nullptr, Tracer{Tracer::kCollect, nullptr, &rays});
}

std::vector<SpatialSample> SpatialSamplesOf(const SceneGeometry& geometry) {
  std::size_t total = 0;
  for (const SceneMesh& m : geometry.meshes) total += m.mesh.positions.size();
  std::vector<SpatialSample> samples;
  samples.reserve(total);
  std::vector<Vec3> face_sum;
  for (const SceneMesh& m : geometry.meshes) {
    const TriangleMesh& mesh = m.mesh;
    face_sum.assign(mesh.positions.size(), Vec3{});
    for (const auto& t : mesh.triangles) {
      if (t[0] >= mesh.positions.size() || t[1] >= mesh.positions.size() ||
          t[2] >= mesh.positions.size()) {
        continue;  // EmbreeScene reports the bad index as an InputError
      }
      const Vec3 a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
      const Vec3 area2 = Cross(b - a, c - a);  // |area2| = 2·area: area-weighted face normal
      for (uint32_t v : t) face_sum[v] += area2;
    }
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
      SpatialSample s;
      s.position = mesh.positions[i];
      Vec3 ng = face_sum[i];
      const double lg = Length(ng);
      const bool has_ng = std::isfinite(lg) && lg > 0;
      Vec3 ns = i < mesh.normals.size() ? mesh.normals[i] : Vec3{};
      const double ls = Length(ns);
      const bool has_ns = std::isfinite(ls) && ls > 0;
      if (has_ng) ng = ng / lg;
      if (has_ns) ns = ns / ls;
      if (!has_ns) ns = has_ng ? ng : Vec3{0, 1, 0};
      if (!has_ng) ng = ns;
      if (Dot(ng, ns) < 0) ng = -ng;
      s.normal = ns;
      s.geometric_normal = ng;
      samples.push_back(s);
    }
  }
  return samples;
}

}  // namespace prt
