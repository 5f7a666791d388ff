#include "worker/path_trace_reference.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "vocabulary/hash.h"

namespace prt {

namespace {

// Stream constants: the paths' hashes and the path vertices' direct rows never share a key with
// the vertex's own direct row (TransportSampler's RowKey of `seed`).
constexpr uint64_t kPathStream = 0x5052544641524D32ull;
constexpr uint64_t kPathRowStream = 0x5052544641524D33ull;

// Largest divisor of k not above √k (as TransportSampler's strata).
int GridV(int k) {
  int b = 1;
  for (int d = 1; d * d <= k; ++d) {
    if (k % d == 0) b = d;
  }
  return b;
}

// A point of the open unit square from 64 bits (TransportSampler's jitter).
void UnitPoint(uint64_t bits, double& u1, double& u2) {
  u1 = (static_cast<double>(bits >> 32) + 0.5) * 0x1p-32;
  u2 = (static_cast<double>(bits & 0xFFFFFFFFull) + 0.5) * 0x1p-32;
}

// Σ_s Var(x_s) over the first-bounce strata, by collapsed strata (see RelitEstimate).
double CollapsedStrataVariance(const double* x, int a, int b) {
  const int p = a * b;
  if (p < 2) return 0;
  double sum = 0;
  if (a % 2 == 0 && b % 2 == 0) {
    for (int v = 0; v < b; v += 2) {
      for (int u = 0; u < a; u += 2) {
        const double* r0 = x + static_cast<std::ptrdiff_t>(v) * a + u;
        const double* r1 = r0 + a;
        const double d = r0[0] - r0[1] - r1[0] + r1[1];
        sum += d * d;
      }
    }
    return sum;
  }
  for (int g0 = 0; g0 < p;) {
    const int g = (p - g0 == 3) ? 3 : 2;
    double m = 0;
    for (int i = 0; i < g; ++i) m += x[g0 + i];
    m /= g;
    double ss = 0;
    for (int i = 0; i < g; ++i) ss += (x[g0 + i] - m) * (x[g0 + i] - m);
    sum += ss * g / (g - 1);
    g0 += g;
  }
  return sum;
}

// The side a segment in direction w leaves from: the geometric normal turned towards w.
Vec3 LeavingSide(const Vec3& geometric_normal, const Vec3& w) {
  return Dot(geometric_normal, w) >= 0 ? geometric_normal : -geometric_normal;
}

}  // namespace

double RelitEstimate::standard_error() const {
  return std::sqrt(direct_standard_error * direct_standard_error +
                   indirect_standard_error * indirect_standard_error);
}

struct PathTraceReference::Impl {
  const EmbreeScene& scene;
  const SceneSurfaces& surfaces;
  PathTraceOptions options;
  TransportSampler direct;  // T⁰ at the vertex: (rays_per_texel, seed), the farm's direct rows
  TransportSampler at_hit;  // T̂⁰ at path vertices: (path_rays_per_texel, its own seed)
  int grid_u = 1, grid_v = 1;
  bool grey = true;

  static TransportSamplerOptions PathRowOptions(const PathTraceOptions& o) {
    return {o.path_rays_per_texel, SplitMix64(o.seed ^ kPathRowStream)};
  }

  Impl(const EmbreeScene& s, const SceneSurfaces& surf, int n, const PathTraceOptions& o)
      : scene(s),
        surfaces(surf),
        options(o),
        direct(s, n, {o.rays_per_texel, o.seed}),
        at_hit(s, n, PathRowOptions(o)) {
    if (o.bounces < 0 || o.bounces > 8) {
      throw std::invalid_argument("PathTraceReference: bounces must be in [0, 8], got " +
                                  std::to_string(o.bounces));
    }
    if (o.paths < 1 || o.paths > 65536) {
      throw std::invalid_argument("PathTraceReference: paths must be in [1, 65536], got " +
                                  std::to_string(o.paths));
    }
    if (s.geometry_count() != surf.geometry().meshes.size()) {
      throw std::invalid_argument("PathTraceReference: the scene has " +
                                  std::to_string(s.geometry_count()) + " meshes, the surfaces " +
                                  std::to_string(surf.geometry().meshes.size()));
    }
    grid_v = GridV(o.paths);
    grid_u = o.paths / grid_v;
    grey = !HasColouredAlbedo(surf.geometry());
  }

  void Check(int channels, const PathTraceExtras& extras) const {
    if (channels != 3 && !(channels == 1 && grey)) {
      throw std::invalid_argument(
          "PathTraceReference: channels must be 3, or 1 when every albedo is grey; got " +
          std::to_string(channels));
    }
    for (const CubemapRgb& l : extras.lights) {
      const std::size_t t = direct.layout().texel_count();
      if (l.n != direct.layout().n() || l.r.size() != t || l.g.size() != t || l.b.size() != t) {
        throw std::invalid_argument(
            "PathTraceReference: a lighting cubemap of n = " + std::to_string(l.n) +
            " for rows of n = " + std::to_string(direct.layout().n()));
      }
    }
    if (!extras.lights.empty() && extras.relit == nullptr) {
      throw std::invalid_argument("PathTraceReference: lights given without a relit output");
    }
  }

  // Walks the P paths leaving x (the estimator above): at the d-th front-face hit y of path p,
  // with throughput beta[c] = Π ρ_c, calls visit(p, d, beta, y, row_key), row_key seeding the
  // direct row at y. Counts the segments, escapes, back faces and path vertices.
  template <class Visit>
  void Walk(const SpatialSample& sample, uint64_t sample_index, PathTraceStats& stats,
            Visit&& visit) const {
    if (sample.background) return;  // a camera pixel on the environment: no paths leave it
    const int k_max = options.bounces;
    const int paths = options.paths;
    // The frame at x as TransportSampler's (unit shading normal; geometric normal unit and in
    // its hemisphere).
    const Vec3 nx = Normalize(sample.normal);
    Vec3 gx = sample.geometric_normal;
    const double lg = Length(gx);
    gx = (std::isfinite(lg) && lg > 0) ? gx / lg : nx;
    if (Dot(gx, nx) < 0) gx = -gx;
    Vec3 tx, bx;
    OrthonormalFrame(nx, tx, bx);
    const uint64_t vertex_key = SplitMix64(SplitMix64(options.seed ^ kPathStream) ^ sample_index);
    const ScopedFlushDenormals ftz;
    for (int p = 0; p < paths; ++p) {
      const uint64_t path_key = SplitMix64(vertex_key ^ static_cast<uint64_t>(p));
      Vec3 pos = sample.position, ns = nx, ng = gx, t = tx, b = bx;
      double beta[3] = {1, 1, 1};
      for (int d = 0; d < k_max; ++d) {
        double u1, u2;
        UnitPoint(SplitMix64(path_key ^ (2 * static_cast<uint64_t>(d))), u1, u2);
        if (d == 0) {  // stratum p = pv·a + pu of the a×b grid
          u1 = ((p % grid_u) + u1) / grid_u;
          u2 = ((p / grid_u) + u2) / grid_v;
        }
        const Vec3 w = Normalize(CosineDirection(ns, t, b, u1, u2));
        OcclusionRay ray{};
        scene.RobustOrigin(pos, LeavingSide(ng, w), ray.origin);
        ray.tnear = 0.0f;
        ray.tfar = std::numeric_limits<float>::infinity();
        ray.direction[0] = static_cast<float>(w.x);
        ray.direction[1] = static_cast<float>(w.y);
        ray.direction[2] = static_cast<float>(w.z);
        ++stats.intersect_rays;
        RayHit hit;
        SurfaceHit y;
        const SceneSurfaces::Outcome outcome = surfaces.Trace(scene, ray, hit, y);
        if (outcome != SceneSurfaces::Outcome::kFront) {
          ++(outcome == SceneSurfaces::Outcome::kEscaped ? stats.escaped : stats.back_faces);
          break;
        }
        const Rgb& rho = surfaces.albedo(y.mesh);
        for (int c = 0; c < 3; ++c) beta[c] *= rho[c];
        if (beta[0] == 0 && beta[1] == 0 && beta[2] == 0) break;  // nothing more to carry
        ++stats.path_vertices;
        visit(p, d, static_cast<const double*>(beta), y.sample,
              SplitMix64(path_key ^ (2 * static_cast<uint64_t>(d) + 1)));
        pos = y.sample.position;
        ns = y.sample.normal;
        ng = y.sample.geometric_normal;
        OrthonormalFrame(ns, t, b);
      }
    }
  }

  // Σ_k Tᵏ_c[x][J] (k = 1..K) at the listed texels (all when empty): out[c·count + i].
  PathTraceStats Indirect(const SpatialSample& sample, uint64_t sample_index, int channels,
                          std::span<const uint32_t> texels, float* out) const {
    const bool all = texels.empty();
    const std::size_t count = all ? direct.layout().texel_count() : texels.size();
    PathTraceStats stats;
    std::vector<double> acc(static_cast<std::size_t>(channels) * count, 0.0);
    std::vector<float> hit_row(count);
    if (options.bounces > 0) {
      Walk(sample, sample_index, stats,
           [&](int, int, const double* beta, const SpatialSample& y, uint64_t row_key) {
             stats.shadow_rays += (all ? at_hit.ComputeRow(y, row_key, hit_row.data())
                                       : at_hit.ComputeTexels(y, row_key, texels, hit_row.data()))
                                      .rays_traced;
             for (int c = 0; c < channels; ++c) {
               double* a = acc.data() + static_cast<std::size_t>(c) * count;
               for (std::size_t i = 0; i < count; ++i) a[i] += beta[c] * hit_row[i];
             }
           });
    }
    const double inv_p = 1.0 / options.paths;
    for (std::size_t i = 0; i < acc.size(); ++i) out[i] = static_cast<float>(acc[i] * inv_p);
    return stats;
  }

  PathTraceStats Row(const SpatialSample& sample, uint64_t sample_index, int channels, float* row,
                     const PathTraceExtras& extras) const {
    const std::size_t texels = direct.layout().texel_count();
    const int k_max = options.bounces;
    const int paths = options.paths;
    const std::size_t lights = extras.lights.size();
    const bool relight = lights > 0;
    PathTraceStats stats;

    // T⁰ (throws NumericalError on a bad sample before anything is traced).
    std::vector<float> t0(texels);
    std::vector<float> t0_variance(relight ? texels : 0);
    stats.shadow_rays +=
        direct.ComputeRow(sample, sample_index, t0.data(), relight ? t0_variance.data() : nullptr)
            .rays_traced;

    // The indirect sums: Σ_paths Σ_d β_c·T̂⁰[y_d] (total), and per bounce when asked.
    std::vector<double> acc(k_max > 0 ? static_cast<std::size_t>(channels) * texels : 0, 0.0);
    std::vector<double> per_bounce(
        extras.bounce_rows != nullptr ? static_cast<std::size_t>(k_max) * channels * texels : 0,
        0.0);
    // Each path's relit sample per bounce, [((light·3 + colour)·K + bounce − 1)·P + path].
    const std::size_t per_estimate = static_cast<std::size_t>(k_max) * paths;
    std::vector<double> path_sample(relight ? lights * 3 * per_estimate : 0, 0.0);
    std::vector<double> path_total(relight ? static_cast<std::size_t>(paths) : 0);
    std::vector<float> hit_row(k_max > 0 ? texels : 0);

    if (k_max > 0) {
      Walk(sample, sample_index, stats,
           [&](int p, int d, const double* beta, const SpatialSample& y, uint64_t row_key) {
             stats.shadow_rays += at_hit.ComputeRow(y, row_key, hit_row.data()).rays_traced;
             for (int c = 0; c < channels; ++c) {
               double* a = acc.data() + static_cast<std::size_t>(c) * texels;
               for (std::size_t j = 0; j < texels; ++j) a[j] += beta[c] * hit_row[j];
               if (!per_bounce.empty()) {
                 double* q =
                     per_bounce.data() + (static_cast<std::size_t>(d) * channels + c) * texels;
                 for (std::size_t j = 0; j < texels; ++j) q[j] += beta[c] * hit_row[j];
               }
             }
             for (std::size_t l = 0; l < lights; ++l) {
               for (int c = 0; c < 3; ++c) {
                 const float* lc = extras.lights[l].Channel(c).data();
                 double dot = 0;
                 for (std::size_t j = 0; j < texels; ++j)
                   dot += static_cast<double>(hit_row[j]) * lc[j];
                 path_sample[(l * 3 + c) * per_estimate + static_cast<std::size_t>(d) * paths + p] =
                     beta[channels == 1 ? 0 : c] * dot;
               }
             }
           });
    }

    // The row: T⁰ + (1/P)·Σ, rounded once per element (K = 0: T⁰ exactly).
    const double inv_p = 1.0 / paths;
    for (int c = 0; c < channels; ++c) {
      float* out = row + static_cast<std::size_t>(c) * texels;
      if (k_max == 0) {
        std::copy(t0.begin(), t0.end(), out);
        continue;
      }
      const double* a = acc.data() + static_cast<std::size_t>(c) * texels;
      for (std::size_t j = 0; j < texels; ++j) {
        out[j] = static_cast<float>(static_cast<double>(t0[j]) + a[j] * inv_p);
      }
    }
    if (extras.bounce_rows != nullptr) {
      for (int c = 0; c < channels; ++c) {
        std::copy(t0.begin(), t0.end(), extras.bounce_rows + static_cast<std::size_t>(c) * texels);
      }
      for (int d = 0; d < k_max; ++d) {
        for (int c = 0; c < channels; ++c) {
          const std::size_t at = (static_cast<std::size_t>(d) * channels + c) * texels;
          float* out = extras.bounce_rows + at + static_cast<std::size_t>(channels) * texels;
          for (std::size_t j = 0; j < texels; ++j) {
            out[j] = static_cast<float>(per_bounce[at + j] * inv_p);
          }
        }
      }
    }
    for (std::size_t l = 0; l < lights; ++l) {
      for (int c = 0; c < 3; ++c) {
        const float* lc = extras.lights[l].Channel(c).data();
        RelitEstimate& e = extras.relit[l * 3 + c];
        e = RelitEstimate{};
        double var = 0;
        for (std::size_t j = 0; j < texels; ++j) {
          e.direct += static_cast<double>(t0[j]) * lc[j];
          var += static_cast<double>(lc[j]) * lc[j] * t0_variance[j];
        }
        e.direct_standard_error = std::sqrt(var);
        e.bounce[0] = e.direct;
        e.bounce_standard_error[0] = e.direct_standard_error;
        if (k_max == 0) continue;
        const double* x = path_sample.data() + (l * 3 + c) * per_estimate;
        std::fill(path_total.begin(), path_total.end(), 0.0);
        for (int d = 0; d < k_max; ++d) {
          const double* xd = x + static_cast<std::size_t>(d) * paths;
          double sum = 0;
          for (int p = 0; p < paths; ++p) {
            sum += xd[p];
            path_total[p] += xd[p];
          }
          e.bounce[d + 1] = sum * inv_p;
          e.bounce_standard_error[d + 1] =
              std::sqrt(CollapsedStrataVariance(xd, grid_u, grid_v)) * inv_p;
        }
        double sum = 0;
        for (int p = 0; p < paths; ++p) sum += path_total[p];
        e.indirect = sum * inv_p;
        e.indirect_standard_error =
            std::sqrt(CollapsedStrataVariance(path_total.data(), grid_u, grid_v)) * inv_p;
      }
    }
    return stats;
  }
};

PathTraceReference::PathTraceReference(const EmbreeScene& scene, const SceneSurfaces& surfaces,
                                       int cubemap_n, PathTraceOptions options)
    : impl_(std::make_unique<Impl>(scene, surfaces, cubemap_n, options)) {}

PathTraceReference::~PathTraceReference() = default;

const CubemapLayout& PathTraceReference::layout() const {
  return impl_->direct.layout();
}
const PathTraceOptions& PathTraceReference::options() const {
  return impl_->options;
}
int PathTraceReference::paths_u() const {
  return impl_->grid_u;
}
int PathTraceReference::paths_v() const {
  return impl_->grid_v;
}
bool PathTraceReference::ChannelsAllowed(int channels) const {
  return channels == 3 || (channels == 1 && impl_->grey);
}

PathTraceStats PathTraceReference::ComputeRow(const SpatialSample& sample, uint64_t sample_index,
                                              int channels, float* row,
                                              const PathTraceExtras& extras) const {
  impl_->Check(channels, extras);
  return impl_->Row(sample, sample_index, channels, row, extras);
}

PathTraceStats PathTraceReference::ComputeIndirect(const SpatialSample& sample,
                                                   uint64_t sample_index, int channels,
                                                   std::span<const uint32_t> texels,
                                                   float* out) const {
  impl_->Check(channels, {});
  const std::size_t t = layout().texel_count();
  for (uint32_t j : texels)
    if (j >= t) throw std::out_of_range("PathTraceReference: texel " + std::to_string(j));
  return impl_->Indirect(sample, sample_index, channels, texels, out);
}

PathTraceStats PathTraceReference::ComputeRows(std::span<const SpatialSample> samples,
                                               uint64_t first_index, int channels, float* out,
                                               const PathTraceExtras& extras) const {
  impl_->Check(channels, extras);
  const std::size_t row_size = static_cast<std::size_t>(channels) * layout().texel_count();
  const std::size_t bounce_size = row_size * static_cast<std::size_t>(impl_->options.bounces + 1);
  const std::size_t relit_size = extras.lights.size() * 3;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, samples.size()), PathTraceStats{},
      [&](const tbb::blocked_range<std::size_t>& r, PathTraceStats acc) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          PathTraceExtras e;
          e.bounce_rows =
              extras.bounce_rows != nullptr ? extras.bounce_rows + i * bounce_size : nullptr;
          e.lights = extras.lights;
          e.relit = extras.relit != nullptr ? extras.relit + i * relit_size : nullptr;
          acc += impl_->Row(samples[i], first_index + i, channels, out + i * row_size, e);
        }
        return acc;
      },
      [](PathTraceStats a, const PathTraceStats& b) { return a += b; });
}

}  // namespace prt
