// The C API of runtime/prt_runtime.h over RelightSession (runtime/relight_session.h): the same
// calls prt-view makes (ResampleToCubemap, ProjectLighting, RelightExact / NWA / BI / PBI, Shade,
// ToPackOrder), behind opaque handles, status codes and a per-thread message. A glossy pack
// (visibility, no transport) is opened as a GlossyRelightSession instead
// (runtime/glossy_relight_session.h) and relit as prt-view's RunGlossy does: ResampleToCubemap,
// the block lighting (UpdateBlockLighting) and Algorithm 1 towards the eye. No exception leaves
// this file.
#include "runtime/prt_runtime.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "formats/image_file.h"
#include "packager/prtpack_reader.h"
#include "runtime/block_lighting.h"
#include "runtime/glossy_relight_session.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "runtime/relight.h"
#include "runtime/relight_session.h"
#include "vocabulary/cubemap.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/envmap.h"
#include "vocabulary/errors.h"
#include "vocabulary/parallel.h"

namespace {

thread_local std::string g_error;

// A call made out of order (PRT_RUNTIME_ERROR_STATE).
class StateError : public std::logic_error {
 public:
  using std::logic_error::logic_error;
};
// A caller's argument (PRT_RUNTIME_ERROR_ARGUMENT).
class ArgumentError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Runs f, turning every exception into a status and this thread's message.
template <class F>
int Guard(const char* function, F&& f) {
  g_error.clear();
  try {
    f();
    return PRT_RUNTIME_OK;
  } catch (const StateError& e) {
    g_error = std::string(function) + ": " + e.what();
    return PRT_RUNTIME_ERROR_STATE;
  } catch (const ArgumentError& e) {
    g_error = std::string(function) + ": " + e.what();
    return PRT_RUNTIME_ERROR_ARGUMENT;
  } catch (const prt::NumericalError& e) {
    g_error = std::string(function) + ": " + e.what();
    return PRT_RUNTIME_ERROR_NUMERIC;
  } catch (const std::bad_alloc&) {
    g_error = std::string(function) + ": out of memory";
    return PRT_RUNTIME_ERROR_MEMORY;
  } catch (const std::invalid_argument& e) {
    g_error = std::string(function) + ": " + e.what();
    return PRT_RUNTIME_ERROR_ARGUMENT;
  } catch (const std::exception& e) {  // InputError, FileIoError, a corrupt section's error
    g_error = std::string(function) + ": " + e.what();
    return PRT_RUNTIME_ERROR_INPUT;
  } catch (...) {
    g_error = std::string(function) + ": unknown error";
    return PRT_RUNTIME_ERROR_INPUT;
  }
}

void Require(bool ok, const std::string& what) {
  if (!ok) throw ArgumentError(what);
}

// The host's job system as the parallel backend (prt_runtime_set_task_runner).
struct TaskRunner {
  prt_runtime_task_runner run = nullptr;
  void* user = nullptr;
};
TaskRunner g_runner;
// prt_runtime_set_max_section_bytes (0: the reader's default).
std::atomic<uint64_t> g_max_section_bytes{0};

prt::pack::ReaderOptions Options() {
  prt::pack::ReaderOptions o;
  if (const uint64_t m = g_max_section_bytes.load(); m > 0) o.max_section_bytes = m;
  return o;
}

}  // namespace

struct prt_runtime {
  // Exactly one of the two: a pack with a transport, or a glossy pack (visibility only).
  std::unique_ptr<prt::RelightSession> session;
  std::unique_ptr<prt::GlossyRelightSession> glossy;
  std::string name;  // the pack, in messages

  // A glossy pack's view (prt_runtime_set_eye; the pack's camera eye at opening) and its
  // lighting in the block representations (updated in place when the lighting changes).
  prt::Vec3 eye{};
  prt::BlockLighting block_light;

  // Lighting: the environment, its rotation, and the lighting they make.
  prt::EnvironmentImage env;
  bool has_env = false;
  // The rotation: about +Y by `angle_y` (prt-view's, bit for bit), or a general matrix.
  bool general_rotation = false;
  double angle_y = 0;
  std::array<double, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};
  prt::WaveletLighting lighting;
  // The preview's forms of env (made on first use, dropped with a new environment): for
  // rotations about +Y the periodic grid's weights, for general ones the reduced copy.
  bool preview = false;
  std::unique_ptr<prt::PeriodicLatLongResampler> periodic;
  std::unique_ptr<prt::EnvironmentImage> reduced;

  int mode = PRT_RUNTIME_LIGHTING_PBI;
  int order = PRT_RUNTIME_ORDER_PACK;
  // The incremental relighters of BI and PBI, made at the first frame of a budget.
  std::unique_ptr<prt::BasicIncrementalRelighter> bi;
  std::unique_ptr<prt::PerBandIncrementalRelighter> pbi;
  std::size_t incremental_terms = 0;

  // The last whole frame (prt_runtime_relight): shaded radiance in the session's order.
  std::vector<float> frame_rgb;
  // A glossy vertex pack: the last relight's radiance of every term (terms × samples), which
  // prt_runtime_reshade combines again for a new eye without relighting.
  prt::SampleRadiance frame_terms_radiance;  // empty until the first relight
  bool incremental_frame = false;
  // The prepared frame (prt_runtime_prepare), applied range by range: its lighting terms
  // (exact, NWA) into frame_radiance, or an incremental step of BI / PBI.
  enum class Prepared { kNone, kTerms, kBi, kPbi, kGlossy };
  Prepared prepared = Prepared::kNone;
  std::vector<prt::LightingTerm> frame_terms;
  prt::SampleRadiance frame_radiance;
  prt::IncrementalStep step;
  std::atomic<std::size_t> relit{0};  // samples written by relight_range since prepare

  std::size_t samples() const { return glossy ? glossy->sample_count() : session->sample_count(); }
  int cubemap_n() const {
    return glossy ? glossy->cubemap_n() : static_cast<int>(session->cubemap_n());
  }
};

namespace {

// What prt-view relights: a pack with visibility and no transport is glossy (view_main.cpp).
prt_runtime* Open(const char* function, const std::function<prt::pack::PackReader()>& read,
                  const std::string& name) {
  std::unique_ptr<prt_runtime> rt;
  const int status = Guard(function, [&] {
    rt = std::make_unique<prt_runtime>();
    rt->name = name;
    const prt::pack::PackReader reader = read();
    if (!reader.has_transport() && !reader.has_cpca() && reader.has_visibility()) {
      rt->glossy = prt::GlossyRelightSession::FromReader(reader, name);
      rt->eye = rt->glossy->camera().eye;
    } else {
      rt->session = prt::RelightSession::FromReader(reader, name);
      rt->eye = rt->session->camera().eye;
    }
  });
  return status == PRT_RUNTIME_OK ? rt.release() : nullptr;
}

void RequireHandle(const prt_runtime* rt) {
  if (rt == nullptr || (!rt->session && !rt->glossy)) throw ArgumentError("the handle is NULL");
}

static_assert(static_cast<int>(prt::BrdfModel::kLambert) == PRT_RUNTIME_BRDF_LAMBERT &&
              static_cast<int>(prt::BrdfModel::kPhong) == PRT_RUNTIME_BRDF_PHONG &&
              static_cast<int>(prt::BrdfModel::kAshikhminShirley) ==
                  PRT_RUNTIME_BRDF_ASHIKHMIN_SHIRLEY);

void RequireMaterialIndex(const prt_runtime& rt, unsigned mesh) {
  if (!rt.glossy)
    throw ArgumentError(rt.name +
                        " is not a glossy pack: its materials are baked into its transport");
  Require(mesh < rt.glossy->materials().size(),
          "mesh " + std::to_string(mesh) + " of " + std::to_string(rt.glossy->materials().size()));
}

// A glossy pack's frames: as prt-view's RunGlossy, whose default is the exact diffuse cosine.
constexpr prt::TripleProductOptions kGlossyOptions{.exact_cosine = true};

void RequireEnvironment(const prt_runtime& rt) {
  if (!rt.has_env)
    throw StateError(rt.name + ": no environment yet (call prt_runtime_set_environment_latlong)");
}

void UpdateLighting(prt_runtime& rt);

// The map reduced to at most 16·n pixels wide (2:1): each reduced pixel the exact mean radiance
// over its own cell (OpenEXR's cells: centres on the poles and at both ends of the longitude
// range, docs/conventions.md), from the source cells' overlaps in longitude and in sin θ (the
// cells are separable), so the map's power is kept exactly.
prt::EnvironmentImage Reduce(const prt::EnvironmentImage& env, int n) {
  const int w = std::max(4, 16 * n), h = w / 2;
  if (env.width <= w) return env;
  // Overlap weights of source columns (rows) with each reduced column (row): a few each.
  struct Piece {
    int source;
    double weight;
  };
  const auto overlaps = [](int src, int dst, bool rows) {
    std::vector<std::vector<Piece>> out(static_cast<std::size_t>(dst));
    for (int d = 0; d < dst; ++d) {
      const prt::PixelInterval c =
          rows ? prt::LatLongRowCell(dst, d) : prt::LatLongColumnCell(dst, d);
      const double lo = std::min(c.lo, c.hi), hi = std::max(c.lo, c.hi);
      for (int s = 0; s < src; ++s) {
        const prt::PixelInterval e =
            rows ? prt::LatLongRowCell(src, s) : prt::LatLongColumnCell(src, s);
        const double elo = std::min(e.lo, e.hi), ehi = std::max(e.lo, e.hi);
        const double a = std::max(lo, elo), b = std::min(hi, ehi);
        if (b > a)  // rows: the solid angle's sin θ factor; columns: the longitude length
          out[d].push_back({s, rows ? std::abs(std::sin(b) - std::sin(a)) : b - a});
      }
    }
    return out;
  };
  const auto cols = overlaps(env.width, w, false), rows = overlaps(env.height, h, true);
  prt::EnvironmentImage out = prt::EnvironmentImage::Zero(prt::EnvmapLayout::kLatLong, w, h);
  std::vector<double> row_sum(3 * static_cast<std::size_t>(env.width));
  for (int y = 0; y < h; ++y) {
    std::fill(row_sum.begin(), row_sum.end(), 0.0);
    double row_weight = 0;
    for (const Piece& r : rows[y]) {
      row_weight += r.weight;
      for (int c = 0; c < 3; ++c) {
        const float* src = env.Channel(c).data() + env.Index(0, r.source);
        for (int x = 0; x < env.width; ++x) row_sum[3 * x + c] += r.weight * src[x];
      }
    }
    for (int x = 0; x < w; ++x) {
      double sum[3] = {0, 0, 0}, weight = 0;
      for (const Piece& p : cols[x]) {
        weight += p.weight;
        for (int c = 0; c < 3; ++c) sum[c] += p.weight * row_sum[3 * p.source + c];
      }
      for (int c = 0; c < 3; ++c)
        out.Channel(c)[out.Index(x, y)] =
            weight * row_weight > 0 ? static_cast<float>(sum[c] / (weight * row_weight)) : 0.0f;
    }
  }
  return out;
}

prt::CubemapRgb Resample(const prt_runtime& rt, const prt::EnvironmentImage& env, int n) {
  return rt.general_rotation ? prt::ResampleToCubemap(env, n, rt.rotation)
                             : prt::ResampleToCubemap(env, n, rt.angle_y);
}

// Sets the rotation and resamples the lighting; on error the old rotation stays.
void SetRotation(prt_runtime& rt, bool general, double angle_y, const std::array<double, 9>& r) {
  const bool old_general = rt.general_rotation;
  const double old_angle = rt.angle_y;
  const std::array<double, 9> old = rt.rotation;
  rt.general_rotation = general;
  rt.angle_y = angle_y;
  rt.rotation = r;
  if (!rt.has_env) return;
  try {
    UpdateLighting(rt);
  } catch (...) {
    rt.general_rotation = old_general;
    rt.angle_y = old_angle;
    rt.rotation = old;
    throw;
  }
}

// Lighting from the environment under the current rotation (prt-view's ResampleToCubemap and
// ProjectLighting).
// With the preview: a rotation about +Y from the periodic 16·n-wide grid's weights (one sparse
// pass, vocabulary/cubemap_resample.h), a general one from the map reduced to 16·n pixels wide;
// either made from `env` into `periodic` / `reduced` when missing.
prt::CubemapRgb Lighting(const prt_runtime& rt, const prt::EnvironmentImage& env,
                         std::unique_ptr<prt::PeriodicLatLongResampler>& periodic,
                         std::unique_ptr<prt::EnvironmentImage>& reduced) {
  const int n = rt.cubemap_n();
  if (!rt.preview) return Resample(rt, env, n);
  if (!rt.general_rotation) {
    if (!periodic)
      periodic = std::make_unique<prt::PeriodicLatLongResampler>(env, n, std::max(4, 16 * n));
    return periodic->Resample(rt.angle_y);
  }
  if (!reduced) reduced = std::make_unique<prt::EnvironmentImage>(Reduce(env, n));
  return Resample(rt, *reduced, n);
}

// A glossy pack's block lighting is updated in place (its storage kept from frame to frame).
void UpdateLighting(prt_runtime& rt) {
  if (rt.glossy) {
    prt::UpdateBlockLighting(Lighting(rt, rt.env, rt.periodic, rt.reduced), rt.glossy->blocks(),
                             rt.block_light);
    return;
  }
  rt.lighting = prt::ProjectLighting(Lighting(rt, rt.env, rt.periodic, rt.reduced));
}

void EnsureIncremental(prt_runtime& rt, unsigned terms);

// This frame's radiance (shaded, the session's order) into rt.frame_rgb.
void ComputeFrame(prt_runtime& rt, unsigned terms) {
  if (!rt.has_env)
    throw StateError(rt.name + ": no environment yet (call prt_runtime_set_environment_latlong)");
  const prt::RelightSession& s = *rt.session;
  prt::SampleRadiance radiance;
  rt.incremental_frame = false;
  if (terms == 0) {
    radiance = s.RelightExact(rt.lighting);
  } else if (rt.mode == PRT_RUNTIME_LIGHTING_NWA) {
    const prt::HaarLightingBasis basis(rt.lighting.n);
    radiance = s.transport().Apply(prt::NonlinearLightingApproximation(rt.lighting, basis, terms));
  } else {
    // BI / PBI: one frame of `terms` terms on the change since the last frame; a new budget
    // restarts from no light (the first frame then equals prt-view's RelightApproximate).
    if (rt.incremental_terms != terms) {
      rt.bi.reset();
      rt.pbi.reset();
      rt.incremental_terms = terms;
    }
    rt.incremental_frame = true;
    if (rt.mode == PRT_RUNTIME_LIGHTING_BI) {
      if (!rt.bi)
        rt.bi =
            std::make_unique<prt::BasicIncrementalRelighter>(s.transport(), rt.lighting.n, terms);
      rt.bi->Update(rt.lighting);
      radiance = rt.bi->Radiance();
    } else {
      if (!rt.pbi)
        rt.pbi =
            std::make_unique<prt::PerBandIncrementalRelighter>(s.transport(), rt.lighting.n, terms);
      rt.pbi->Update(rt.lighting);
      radiance = rt.pbi->Radiance();
    }
  }
  rt.frame_rgb = s.Shade(radiance, rt.eye);  // a glossy vertex pack: its terms for the eye
  if (s.terms() > 1) rt.frame_terms_radiance = std::move(radiance);
}

// Makes (or restarts) the incremental relighter of the mode for a budget of `terms`.
void EnsureIncremental(prt_runtime& rt, unsigned terms) {
  if (rt.incremental_terms != terms) {
    rt.bi.reset();
    rt.pbi.reset();
    rt.incremental_terms = terms;
  }
  const prt::RelightSession& s = *rt.session;
  if (rt.mode == PRT_RUNTIME_LIGHTING_BI && !rt.bi)
    rt.bi = std::make_unique<prt::BasicIncrementalRelighter>(s.transport(), rt.lighting.n, terms);
  if (rt.mode == PRT_RUNTIME_LIGHTING_PBI && !rt.pbi)
    rt.pbi =
        std::make_unique<prt::PerBandIncrementalRelighter>(s.transport(), rt.lighting.n, terms);
}

// prt_runtime_prepare's work: the frame's decisions, none of its per-sample work.
void PrepareFrame(prt_runtime& rt, unsigned terms) {
  RequireEnvironment(rt);
  if (rt.glossy) {  // terms and the lighting mode do not apply: every frame is Algorithm 1
    rt.prepared = prt_runtime::Prepared::kGlossy;
    return;
  }
  const prt::RelightSession& s = *rt.session;
  if (terms == 0 || rt.mode == PRT_RUNTIME_LIGHTING_NWA) {
    if (terms == 0) {
      rt.frame_terms = prt::ExactLightingTerms(rt.lighting);
    } else {
      const prt::HaarLightingBasis basis(rt.lighting.n);
      rt.frame_terms = prt::NonlinearLightingApproximation(rt.lighting, basis, terms);
    }
    for (const prt::LightingTerm& t : rt.frame_terms)  // the relighters take float lighting
      for (int c = 0; c < 3; ++c) prt::CheckFloatLighting(t.value[c], t.index, c, rt.name);
    if (rt.frame_radiance.size() != s.sample_count())
      rt.frame_radiance = prt::SampleRadiance(s.sample_count());
    rt.prepared = prt_runtime::Prepared::kTerms;
    return;
  }
  EnsureIncremental(rt, terms);
  if (rt.mode == PRT_RUNTIME_LIGHTING_BI) {
    rt.step = rt.bi->Plan(rt.lighting);
    rt.prepared = prt_runtime::Prepared::kBi;
  } else {
    rt.step = rt.pbi->Plan(rt.lighting);
    rt.prepared = prt_runtime::Prepared::kPbi;
  }
}

// Radiance of positions [first, first + count) of the session's order for the prepared frame,
// shaded (albedo ⊙ radiance, as ShadeSamples) into `out` in the current order.
void RelightRange(prt_runtime& rt, std::size_t first, std::size_t count, float* out) {
  const prt::SampleRadiance* radiance = nullptr;
  switch (rt.prepared) {
    case prt_runtime::Prepared::kGlossy:  // the pack's order is the runtime's
      rt.glossy->RelightRange(rt.block_light, rt.eye, first, count,
                              std::span<float>(out + 3 * first, 3 * count), kGlossyOptions);
      return;
    case prt_runtime::Prepared::kTerms:
      rt.session->transport().AccumulateRange(rt.frame_terms, rt.frame_radiance, first, count,
                                              true);
      radiance = &rt.frame_radiance;
      break;
    case prt_runtime::Prepared::kBi:
      rt.bi->Apply(rt.step, first, count);
      radiance = &rt.bi->Radiance();
      break;
    case prt_runtime::Prepared::kPbi:
      rt.pbi->Apply(rt.step, first, count);
      radiance = &rt.pbi->Composed();
      break;
    case prt_runtime::Prepared::kNone:
      throw StateError("no prepared frame (call prt_runtime_prepare first)");
  }
  const std::vector<prt::Rgb>& albedo = rt.session->albedo();
  const std::span<const uint32_t> pack_sample = rt.session->pack_sample();
  const bool pack_order = rt.order == PRT_RUNTIME_ORDER_PACK;
  for (std::size_t p = first; p < first + count; ++p) {
    float* o = out + 3 * static_cast<std::size_t>(pack_order ? pack_sample[p] : p);
    for (int c = 0; c < 3; ++c) {
      const double v = static_cast<double>(albedo[p][c]) * radiance->channel[c][p];
      if (!(std::abs(v) <= static_cast<double>(std::numeric_limits<float>::max())))
        throw prt::NumericalError(rt.name + ": relit radiance of sample " +
                                  std::to_string(pack_sample[p]) + " is not a finite float");
      o[c] = static_cast<float>(v);
    }
  }
}

// Writes samples [first, first + count) of the current order from rt.frame_rgb.
void CopyOut(const prt_runtime& rt, std::size_t first, std::size_t count, float* out) {
  const float* src = rt.frame_rgb.data();
  if (rt.order == PRT_RUNTIME_ORDER_RUNTIME) {
    std::memcpy(out + 3 * first, src + 3 * first, sizeof(float) * 3 * count);
    return;
  }
  // Pack order: the session position of pack sample v is its coefficient (inverse of
  // pack_sample()).
  const std::span<const uint32_t> pos = rt.session->session_position();
  for (std::size_t v = first; v < first + count; ++v)
    std::memcpy(out + 3 * v, src + 3 * static_cast<std::size_t>(pos[v]), sizeof(float) * 3);
}

// The checks of a per-pixel output of an image pack: a handle, an output array of `samples`
// entries (`what`), an image pack (`vertex_lacks`: what a vertex pack has not); its image.
template <class T>
const prt::ImageSamplesInfo& PerPixelOutput(const prt_runtime* rt, const T* out, size_t samples,
                                            const char* what, const char* vertex_lacks) {
  RequireHandle(rt);
  Require(out != nullptr, std::string(what) + " is NULL");
  const prt::ImageSamplesInfo* image = rt->glossy ? nullptr : rt->session->image();
  Require(image != nullptr, rt->name + " is a vertex pack: it has no " + vertex_lacks);
  const std::size_t ns = rt->samples();
  Require(samples == ns,
          "room for " + std::to_string(samples) + " samples, the pack has " + std::to_string(ns));
  Require(image->pixel_mesh.size() == ns, rt->name + ": pixel count differs from samples");
  return *image;
}

}  // namespace

extern "C" {

prt_runtime* prt_runtime_open_file(const char* path) {
  if (path == nullptr) {
    g_error = "prt_runtime_open_file: the path is NULL";
    return nullptr;
  }
  const std::string p(path);
  return Open(
      "prt_runtime_open_file", [&] { return prt::pack::PackReader::OpenFile(p); }, p);
}

prt_runtime* prt_runtime_open_memory(const void* data, size_t size) {
  if (data == nullptr && size != 0) {
    g_error = "prt_runtime_open_memory: data is NULL";
    return nullptr;
  }
  return Open(
      "prt_runtime_open_memory",
      [&] { return prt::pack::PackReader::OpenMemory(data, size, "<memory>", Options()); },
      "<memory>");
}

void prt_runtime_close(prt_runtime* rt) {
  delete rt;
}

const char* prt_runtime_last_error(void) {
  return g_error.c_str();
}

size_t prt_runtime_sample_count(const prt_runtime* rt) {
  return rt != nullptr && (rt->session || rt->glossy) ? rt->samples() : 0;
}

int prt_runtime_is_image(const prt_runtime* rt) {
  return rt != nullptr && rt->session && rt->session->image() != nullptr ? 1 : 0;
}

int prt_runtime_is_glossy(const prt_runtime* rt) {
  return rt != nullptr && rt->glossy ? 1 : 0;
}

unsigned prt_runtime_brdf_terms(const prt_runtime* rt) {
  return rt != nullptr && rt->session ? static_cast<unsigned>(rt->session->terms()) : 0;
}

unsigned prt_runtime_transport_channels(const prt_runtime* rt) {
  return rt != nullptr && rt->session ? rt->session->transport_header().channels : 0;
}

unsigned prt_runtime_cubemap_size(const prt_runtime* rt) {
  return rt != nullptr && (rt->session || rt->glossy) ? static_cast<unsigned>(rt->cubemap_n()) : 0;
}

unsigned prt_runtime_coefficient_count(const prt_runtime* rt) {
  const unsigned n = prt_runtime_cubemap_size(rt);
  return 6 * n * n;
}

size_t prt_runtime_triangle_count(const prt_runtime* rt) {
  if (rt != nullptr && rt->glossy) return rt->glossy->triangles().size();
  return rt != nullptr && rt->session ? rt->session->triangles().size() : 0;
}

int prt_runtime_get_positions(const prt_runtime* rt, float* xyz, size_t samples) {
  return Guard("prt_runtime_get_positions", [&] {
    RequireHandle(rt);
    Require(xyz != nullptr, "xyz is NULL");
    const std::size_t ns = rt->samples();
    Require(rt->glossy || rt->session->image() == nullptr,
            rt->name + " is an image pack: it has no positions");
    Require(samples == ns,
            "room for " + std::to_string(samples) + " samples, the pack has " + std::to_string(ns));
    if (rt->glossy) {  // the pack's order
      const std::span<const prt::Vec3> p = rt->glossy->positions();
      for (std::size_t i = 0; i < ns; ++i) {
        xyz[3 * i] = static_cast<float>(p[i].x);
        xyz[3 * i + 1] = static_cast<float>(p[i].y);
        xyz[3 * i + 2] = static_cast<float>(p[i].z);
      }
      return;
    }
    const std::span<const prt::Vec3> p = rt->session->positions();
    const std::span<const uint32_t> pack_sample = rt->session->pack_sample();
    for (std::size_t i = 0; i < ns; ++i) {
      float* o = xyz + 3 * static_cast<std::size_t>(pack_sample[i]);
      o[0] = static_cast<float>(p[i].x);
      o[1] = static_cast<float>(p[i].y);
      o[2] = static_cast<float>(p[i].z);
    }
  });
}

int prt_runtime_get_triangles(const prt_runtime* rt, uint32_t* indices, size_t triangles) {
  return Guard("prt_runtime_get_triangles", [&] {
    RequireHandle(rt);
    Require(indices != nullptr, "indices is NULL");
    const std::span<const std::array<uint32_t, 3>> t =
        rt->glossy ? rt->glossy->triangles() : rt->session->triangles();
    Require(triangles == t.size(), "room for " + std::to_string(triangles) +
                                       " triangles, the pack has " + std::to_string(t.size()));
    if (rt->glossy) {  // the pack's order
      for (std::size_t i = 0; i < t.size(); ++i)
        for (int k = 0; k < 3; ++k) indices[3 * i + k] = t[i][k];
      return;
    }
    const std::span<const uint32_t> pack_sample = rt->session->pack_sample();
    for (std::size_t i = 0; i < t.size(); ++i)
      for (int k = 0; k < 3; ++k) indices[3 * i + k] = pack_sample[t[i][k]];
  });
}

int prt_runtime_get_image_background(const prt_runtime* rt, uint8_t* background, size_t samples) {
  return Guard("prt_runtime_get_image_background", [&] {
    const prt::ImageSamplesInfo& image =
        PerPixelOutput(rt, background, samples, "background", "background pixels");
    const std::size_t ns = samples;
    for (std::size_t p = 0; p < ns; ++p)
      background[p] = image.pixel_mesh[p] == prt::kImageBackground ? 1 : 0;
  });
}

int prt_runtime_get_image_coverage(const prt_runtime* rt, float* coverage, size_t samples) {
  return Guard("prt_runtime_get_image_coverage", [&] {
    const prt::ImageSamplesInfo& image =
        PerPixelOutput(rt, coverage, samples, "coverage", "pixel coverage");
    const std::size_t ns = samples;
    const std::vector<float> share = prt::PixelEnvironmentShare(image);
    for (std::size_t p = 0; p < ns; ++p) coverage[p] = 1.0f - share[p];
  });
}

int prt_runtime_get_camera(const prt_runtime* rt, float eye[3], float target[3], float up[3],
                           float* fov_deg, int* width, int* height) {
  return Guard("prt_runtime_get_camera", [&] {
    RequireHandle(rt);
    const prt::Camera& c = rt->glossy ? rt->glossy->camera() : rt->session->camera();
    const auto put = [](float* o, const prt::Vec3& v) {
      if (o == nullptr) return;
      o[0] = static_cast<float>(v.x);
      o[1] = static_cast<float>(v.y);
      o[2] = static_cast<float>(v.z);
    };
    put(eye, c.eye);
    put(target, c.target);
    put(up, c.up);
    if (fov_deg != nullptr) *fov_deg = static_cast<float>(c.fov_deg);
    if (width != nullptr) *width = c.width;
    if (height != nullptr) *height = c.height;
  });
}

int prt_runtime_set_environment_latlong(prt_runtime* rt, const float* rgb, int width, int height) {
  return Guard("prt_runtime_set_environment_latlong", [&] {
    RequireHandle(rt);
    Require(rgb != nullptr, "rgb is NULL");
    Require(height >= 2 && width == 2 * height,
            "a lat-long map must be width = 2 x height with height >= 2, not " +
                std::to_string(width) + " x " + std::to_string(height));
    prt::EnvironmentImage env =
        prt::EnvironmentImage::Zero(prt::EnvmapLayout::kLatLong, width, height);
    const std::size_t pixels = env.PixelCount();
    for (std::size_t i = 0; i < pixels; ++i)
      for (int c = 0; c < 3; ++c) {
        const float v = rgb[3 * i + c];
        if (!std::isfinite(v))
          throw prt::InputError("environment", "pixel (x=" + std::to_string(i % width) + ", y=" +
                                                   std::to_string(i / width) + ") channel " +
                                                   std::to_string(c) + " is not finite");
        env.Channel(c)[i] = v < 0 ? 0.0f : v;  // as prt-view's readers clamp negatives
      }
    // Resample before replacing anything: on error the previous environment stays.
    std::unique_ptr<prt::PeriodicLatLongResampler> periodic;
    std::unique_ptr<prt::EnvironmentImage> reduced;
    const prt::CubemapRgb cube = Lighting(*rt, env, periodic, reduced);
    if (rt->glossy) {
      prt::BlockLighting light;
      prt::UpdateBlockLighting(cube, rt->glossy->blocks(), light);
      rt->block_light = std::move(light);
    } else {
      rt->lighting = prt::ProjectLighting(cube);
    }
    rt->env = std::move(env);
    rt->periodic = std::move(periodic);
    rt->reduced = std::move(reduced);
    rt->has_env = true;
  });
}

int prt_runtime_set_rotation(prt_runtime* rt, const float rotation[9]) {
  return Guard("prt_runtime_set_rotation", [&] {
    RequireHandle(rt);
    Require(rotation != nullptr, "rotation is NULL");
    std::array<double, 9> r{};
    for (int i = 0; i < 9; ++i) {
      Require(std::isfinite(rotation[i]), "rotation[" + std::to_string(i) + "] is not finite");
      r[i] = rotation[i];
    }
    // Orthonormal with determinant +1: R·Rᵀ = I to 1e-4.
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double d = 0;
        for (int k = 0; k < 3; ++k) d += r[3 * i + k] * r[3 * j + k];
        Require(std::abs(d - (i == j ? 1.0 : 0.0)) <= 1e-4, "the matrix is not orthonormal");
      }
    const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                       r[2] * (r[3] * r[7] - r[4] * r[6]);
    Require(det > 0, "the matrix is a reflection (determinant -1), not a rotation");
    // A rotation about +Y (the identity included) takes prt-view's path: its angle.
    const bool about_y = r[1] == 0 && r[3] == 0 && r[5] == 0 && r[7] == 0 && r[4] == 1;
    SetRotation(*rt, !about_y, about_y ? std::atan2(r[2], r[0]) : 0.0, r);
  });
}

int prt_runtime_set_rotation_y(prt_runtime* rt, double radians) {
  if (!std::isfinite(radians)) {
    g_error = "prt_runtime_set_rotation_y: the angle is not finite";
    return PRT_RUNTIME_ERROR_ARGUMENT;
  }
  return Guard("prt_runtime_set_rotation_y", [&] {
    RequireHandle(rt);
    // RotateAboutY (vocabulary/envmap.h) as a matrix: x' = x cos + z sin, z' = −x sin + z cos.
    const double c = std::cos(radians), s = std::sin(radians);
    SetRotation(*rt, false, radians, {c, 0, s, 0, 1, 0, -s, 0, c});
  });
}

int prt_runtime_set_eye(prt_runtime* rt, const float eye[3]) {
  return Guard("prt_runtime_set_eye", [&] {
    RequireHandle(rt);
    Require(eye != nullptr, "eye is NULL");
    for (int i = 0; i < 3; ++i)
      Require(std::isfinite(eye[i]), "eye[" + std::to_string(i) + "] is not finite");
    // A diffuse vertex pack's radiance does not depend on it; a glossy one's (triple products,
    // or BRDF terms) from the next relight on.
    rt->eye = {eye[0], eye[1], eye[2]};
  });
}

int prt_runtime_get_eye(const prt_runtime* rt, float eye[3]) {
  return Guard("prt_runtime_get_eye", [&] {
    RequireHandle(rt);
    Require(eye != nullptr, "eye is NULL");
    eye[0] = static_cast<float>(rt->eye.x);
    eye[1] = static_cast<float>(rt->eye.y);
    eye[2] = static_cast<float>(rt->eye.z);
  });
}

unsigned prt_runtime_material_count(const prt_runtime* rt) {
  return rt != nullptr && rt->glossy ? static_cast<unsigned>(rt->glossy->materials().size()) : 0;
}

int prt_runtime_get_material(const prt_runtime* rt, unsigned mesh, prt_runtime_material* out) {
  return Guard("prt_runtime_get_material", [&] {
    RequireHandle(rt);
    Require(out != nullptr, "out is NULL");
    RequireMaterialIndex(*rt, mesh);
    const prt::Material& m = rt->glossy->materials()[mesh];
    out->brdf = static_cast<int>(m.model);
    for (int c = 0; c < 3; ++c) {
      out->diffuse[c] = m.diffuse[c];
      out->specular[c] = m.specular[c];
    }
    out->exponent = m.exponent;
    out->exponent_v = m.exponent_v;
  });
}

int prt_runtime_set_material(prt_runtime* rt, unsigned mesh, const prt_runtime_material* material) {
  return Guard("prt_runtime_set_material", [&] {
    RequireHandle(rt);
    Require(material != nullptr, "material is NULL");
    RequireMaterialIndex(*rt, mesh);
    const prt_runtime_material& in = *material;
    Require(in.brdf == PRT_RUNTIME_BRDF_LAMBERT || in.brdf == PRT_RUNTIME_BRDF_PHONG ||
                in.brdf == PRT_RUNTIME_BRDF_ASHIKHMIN_SHIRLEY,
            "unknown brdf " + std::to_string(in.brdf));
    prt::Material m;
    m.model = static_cast<prt::BrdfModel>(in.brdf);
    for (int c = 0; c < 3; ++c) {
      Require(in.diffuse[c] >= 0 && in.diffuse[c] <= 1,
              "diffuse[" + std::to_string(c) + "] is outside [0, 1]");
      Require(in.specular[c] >= 0 && in.specular[c] <= 1,
              "specular[" + std::to_string(c) + "] is outside [0, 1]");
      m.diffuse[c] = in.diffuse[c];
      m.specular[c] = in.specular[c];
    }
    Require(in.exponent > 0 && in.exponent <= 1e6, "exponent is outside (0, 1e6]");
    Require(in.exponent_v > 0 && in.exponent_v <= 1e6, "exponent_v is outside (0, 1e6]");
    m.exponent = in.exponent;
    m.exponent_v = in.exponent_v;
    rt->glossy->materials()[mesh] = m;
  });
}

int prt_runtime_set_preview(prt_runtime* rt, int preview) {
  return Guard("prt_runtime_set_preview", [&] {
    RequireHandle(rt);
    Require(preview == 0 || preview == 1, "preview is 0 or 1, not " + std::to_string(preview));
    if ((preview == 1) == rt->preview) return;
    rt->preview = preview == 1;
    if (!rt->has_env) return;
    try {
      UpdateLighting(*rt);
    } catch (...) {
      rt->preview = !rt->preview;
      throw;
    }
  });
}

int prt_runtime_set_lighting_mode(prt_runtime* rt, int mode) {
  return Guard("prt_runtime_set_lighting_mode", [&] {
    RequireHandle(rt);
    Require(mode == PRT_RUNTIME_LIGHTING_NWA || mode == PRT_RUNTIME_LIGHTING_BI ||
                mode == PRT_RUNTIME_LIGHTING_PBI,
            "unknown lighting mode " + std::to_string(mode));
    if (mode != rt->mode) {
      rt->bi.reset();
      rt->pbi.reset();
      rt->incremental_terms = 0;
    }
    rt->mode = mode;
  });
}

int prt_runtime_set_sample_order(prt_runtime* rt, int order) {
  return Guard("prt_runtime_set_sample_order", [&] {
    RequireHandle(rt);
    Require(order == PRT_RUNTIME_ORDER_PACK || order == PRT_RUNTIME_ORDER_RUNTIME,
            "unknown sample order " + std::to_string(order));
    rt->order = order;
  });
}

int prt_runtime_get_sample_order(const prt_runtime* rt, uint32_t* pack_index, size_t samples) {
  return Guard("prt_runtime_get_sample_order", [&] {
    RequireHandle(rt);
    Require(pack_index != nullptr, "pack_index is NULL");
    Require(samples == rt->samples(), "room for " + std::to_string(samples) +
                                          " samples, the pack has " +
                                          std::to_string(rt->samples()));
    if (rt->glossy) {  // a glossy pack's runtime order is the pack's
      for (std::size_t i = 0; i < rt->samples(); ++i) pack_index[i] = static_cast<uint32_t>(i);
      return;
    }
    const std::span<const uint32_t> p = rt->session->pack_sample();
    std::copy(p.begin(), p.end(), pack_index);
  });
}

int prt_runtime_prepare(prt_runtime* rt, unsigned terms) {
  return Guard("prt_runtime_prepare", [&] {
    RequireHandle(rt);
    const bool incremental =
        rt->prepared == prt_runtime::Prepared::kBi || rt->prepared == prt_runtime::Prepared::kPbi;
    if (incremental && rt->relit.load() < rt->samples())
      throw StateError("the previous frame relit " + std::to_string(rt->relit.load()) + " of " +
                       std::to_string(rt->samples()) +
                       " samples; its incremental state would be torn");
    if (rt->session && rt->session->terms() > 1)
      throw StateError(rt->name + ": a glossy vertex pack (" +
                       std::to_string(rt->session->terms()) +
                       " BRDF terms) relights with prt_runtime_relight; ranges over its terms "
                       "are not built (docs/glossy-transport.md)");
    rt->prepared = prt_runtime::Prepared::kNone;
    PrepareFrame(*rt, terms);
    rt->relit.store(0);
  });
}

int prt_runtime_relight_range(prt_runtime* rt, size_t first, size_t count, float* out_rgb,
                              size_t out_samples) {
  return Guard("prt_runtime_relight_range", [&] {
    RequireHandle(rt);
    Require(out_rgb != nullptr, "out_rgb is NULL");
    const std::size_t ns = rt->samples();
    Require(out_samples == ns, "room for " + std::to_string(out_samples) +
                                   " samples, the pack has " + std::to_string(ns));
    Require(first <= ns && count <= ns - first,
            "range [" + std::to_string(first) + ", " + std::to_string(first) + " + " +
                std::to_string(count) + ") is outside the " + std::to_string(ns) + " samples");
    RelightRange(*rt, first, count, out_rgb);
    rt->relit.fetch_add(count);
  });
}

int prt_runtime_relight(prt_runtime* rt, unsigned terms, float* out_rgb, size_t out_samples) {
  return Guard("prt_runtime_relight", [&] {
    RequireHandle(rt);
    Require(out_rgb != nullptr, "out_rgb is NULL");
    Require(out_samples == rt->samples(), "room for " + std::to_string(out_samples) +
                                              " samples, the pack has " +
                                              std::to_string(rt->samples()));
    const bool incremental =
        rt->prepared == prt_runtime::Prepared::kBi || rt->prepared == prt_runtime::Prepared::kPbi;
    if (incremental && rt->relit.load() < rt->samples())
      throw StateError("the prepared frame relit " + std::to_string(rt->relit.load()) + " of " +
                       std::to_string(rt->samples()) +
                       " samples; its incremental state would be torn");
    rt->prepared = prt_runtime::Prepared::kNone;
    if (rt->glossy) {  // terms and the lighting mode do not apply; the pack's order
      RequireEnvironment(*rt);
      rt->glossy->Relight(rt->block_light, rt->eye, std::span<float>(out_rgb, 3 * rt->samples()),
                          kGlossyOptions);
      return;
    }
    ComputeFrame(*rt, terms);
    CopyOut(*rt, 0, rt->samples(), out_rgb);
  });
}

int prt_runtime_reshade(prt_runtime* rt, float* out_rgb, size_t out_samples) {
  return Guard("prt_runtime_reshade", [&] {
    RequireHandle(rt);
    Require(out_rgb != nullptr, "out_rgb is NULL");
    Require(out_samples == rt->samples(), "room for " + std::to_string(out_samples) +
                                              " samples, the pack has " +
                                              std::to_string(rt->samples()));
    if (!rt->session || rt->session->terms() <= 1)
      throw StateError(rt->name + ": prt_runtime_reshade needs a glossy vertex pack (BRDF terms)");
    if (rt->frame_terms_radiance.size() == 0)
      throw StateError(rt->name + ": no frame to reshade yet (call prt_runtime_relight first)");
    rt->frame_rgb = rt->session->Shade(rt->frame_terms_radiance, rt->eye);
    CopyOut(*rt, 0, rt->samples(), out_rgb);
  });
}

void prt_runtime_set_task_runner(prt_runtime_task_runner run, void* user, unsigned concurrency) {
  g_runner = {run, user};
  prt::ParallelBackend b;
  if (run != nullptr && concurrency > 1) {
    b.run = [](void*, std::size_t count, void (*task)(void*, std::size_t), void* data) {
      g_runner.run(g_runner.user, count, task, data);
    };
    b.concurrency = concurrency;
  }
  prt::SetParallelBackend(b);
}

void prt_runtime_set_max_section_bytes(uint64_t bytes) {
  g_max_section_bytes.store(bytes);
}

// A glossy pack: its visibility, vertices (position, normal, material), triangles, the blocks'
// geometry (texel, directions, solid angles), the block lighting, and the map.
std::size_t GlossyMemoryBytes(const prt_runtime& rt) {
  const prt::GlossyRelightSession& g = *rt.glossy;
  std::size_t bytes = g.visibility().MemoryBytes();
  bytes += g.sample_count() * (2 * sizeof(prt::Vec3) + sizeof(uint16_t));
  bytes += g.triangles().size() * sizeof(std::array<uint32_t, 3>);
  bytes += static_cast<std::size_t>(g.blocks().block_count()) *
           (256 * sizeof(uint32_t) + sizeof(prt::Vec3) + (768 + 63 + 256) * sizeof(float));
  const prt::BlockLighting& l = rt.block_light;
  bytes +=
      sizeof(float) * (l.dct.size() + l.suffix.size() + l.pixels.size() + l.suffix_vec.size()) +
      sizeof(prt::BlockLighting::SuffixLine) * l.suffix_rgbxyz.size();
  bytes += sizeof(float) * rt.env.r.size() * 3;
  if (rt.periodic) bytes += rt.periodic->memory_bytes();
  if (rt.reduced) bytes += sizeof(float) * 3 * rt.reduced->PixelCount();
  return bytes;
}

size_t prt_runtime_memory_bytes(const prt_runtime* rt) {
  if (rt != nullptr && rt->glossy) return GlossyMemoryBytes(*rt);
  if (rt == nullptr || !rt->session) return 0;
  std::size_t bytes = rt->session->memory_bytes();
  bytes += sizeof(float) * (rt->env.r.size() * 3 + rt->frame_rgb.size()) +
           sizeof(double) * 3 * rt->frame_terms_radiance.size();
  bytes += sizeof(double) * 3 * rt->lighting.size();
  if (rt->periodic) bytes += rt->periodic->memory_bytes();
  if (rt->reduced) bytes += sizeof(float) * 3 * rt->reduced->PixelCount();
  const std::size_t ns = rt->samples();
  if (rt->pbi) {  // band images, composed radiance, the represented lighting
    bytes += sizeof(double) * 3 * ns * (rt->pbi->basis().band_count() + 1);
    bytes += sizeof(double) * 3 * rt->lighting.size();
  }
  if (rt->bi) bytes += sizeof(double) * 3 * (ns + rt->lighting.size());
  return bytes;
}

}  // extern "C"
