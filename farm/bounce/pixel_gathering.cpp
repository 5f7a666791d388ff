// An image run's interreflection by bounce gathering (docs/image-relighting.md,
// "Interreflection"; worker/bounce_gather.h). A pixel's gather interpolates the previous bounce
// at the vertices of the triangle its direction hits, so the run computes support rows at the
// mesh vertices first, on the indirect grid (m = indirect_n), never shipped:
//   "vertex-direct"       T⁰(v): rays_per_texel jittered shadow rays per coarse texel
//                         (indirect/vertex-direct.prtt, one channel);
//   "vertex-bounce-<k>"   Tᵏ(v), k = 1 … K−1, gathered from Tᵏ⁻¹ exactly as a vertex run's
//                         bounce k (near field in bounce 1; indirect/vertex-bounce-<k>.prtt);
//   "pixel-gather"        the pixels' whole indirect part in one gather:
//     Σ_{k=1..K} Tᵏ(p) = (1/P) Σ_q ρ(y_q) · Σ_{k=0..K−1} Tᵏ(y_q),
// the same P directions for every bounce (each bounce's estimate stays unbiased; they are
// correlated, which does not bias the sum). At a bounce-1 near-field hit y_q (a hit closer than
// its triangle's size on a triangle more than twice as coarse as the one the pixel sees) T⁰(y_q)
// is traced at y_q (BounceGatherer's near field, thinned to near_rows per pixel and weighted 1/q)
// and only Σ_{k≥1} Tᵏ(y_q) is interpolated (GatherSite::near_terms). The result,
// indirect/pixel-gather.prtt (channels × pixels rows), is the indirect file the compression adds
// to the pixels' direct rows. Every row is a pure function of (seed, index): any rank count gives
// the same bytes; each phase journals and resumes like the vertex run's bounces (the driver).
// Method "sparse" with [sparse] indirect = "combination": only the dense pixels gather, the
// others combine them (the driver, as for vertices).
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

namespace {

// Every rank: the image run's mesh vertices as samples (created by the first vertex phase).
struct ImageVertexSamples {
  std::vector<SpatialSample> samples;
};
const std::vector<SpatialSample>& VertexSamples(FarmContext& ctx) {
  if (const ImageVertexSamples* v = ctx.results.Find<ImageVertexSamples>()) return v->samples;
  return ctx.results.Put(ImageVertexSamples{SpatialSamplesOf(ctx.geometry)}).samples;
}

// The gathers of pixels draw from their own stream: pixel p gathers as index kPixelStream + p.
constexpr uint64_t kPixelStream = uint64_t{1} << 48;

// Reads all `channels` × `rows` rows of a support file of the indirect grid into `out`
// (added to what is there when `add`).
void ReadSupport(const std::string& path, uint64_t rows, int channels, std::size_t cols, int n,
                 std::vector<float>& out, bool add) {
  const TransportFileReader reader(path);
  if (reader.info().rows != uint64_t(channels) * rows || reader.info().cubemap_n != uint32_t(n))
    throw InputError(path, "does not hold " + std::to_string(channels) + " × " +
                               std::to_string(rows) + " rows at n = " + std::to_string(n));
  const std::size_t floats = static_cast<std::size_t>(channels * rows) * cols;
  if (!add) {
    out.resize(floats);
    reader.ReadRows(0, reader.info().rows, out.data());
    return;
  }
  std::vector<float> more(floats);
  reader.ReadRows(0, reader.info().rows, more.data());
  for (std::size_t i = 0; i < floats; ++i) out[i] += more[i];
}

// The figures of a support or pixel phase: report.json "interreflection.image_passes".
void AddPassFigures(BounceDriver& driver, const BounceTotals& totals, int k) {
  nlohmann::ordered_json f = TracedFigures(totals, k);
  f["phase"] = driver.name();
  driver.figures()["image_passes"].push_back(std::move(f));
}

// Fills the header at `at` of `out` for `floats` rows floats (checked finite).
void FinishHeader(const BounceDriver& driver, std::string& out, std::size_t at, const float* rows,
                  std::size_t floats, std::size_t per_row, const RowRange& range,
                  const GatherStats& s) {
  BounceResultHeader h;
  h.rows_checksum = ChecksumFiniteRows(rows, floats, per_row, range, driver.name());
  h.rays_traced = s.rays_traced;
  h.rays_escaped = s.rays_escaped;
  h.back_face_hits = s.back_face_hits;
  std::memcpy(out.data() + at, &h, sizeof h);
}

class VertexDirectPhase final : public BouncePhase {
 public:
  explicit VertexDirectPhase(std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(0, false, std::move(figures), BouncePass::kVertexDirect) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const std::vector<SpatialSample>& samples = VertexSamples(ctx);
    const std::size_t cols = CubemapLayout(ctx.params.indirect_n).texel_count();
    std::unique_ptr<TransportSampler> sampler;
    if (ctx.computes_here()) {
      TransportSamplerOptions so;
      so.rays_per_texel = ctx.params.rays_per_texel;
      so.seed = SplitMix64(ctx.params.seed ^ 0x5650524Full);  // its own stream
      sampler = std::make_unique<TransportSampler>(*ctx.embree, ctx.params.indirect_n, so);
    }
    if (ctx.rank == 0) ctx.run_eta.StepStarted(driver_.name());
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      const std::size_t at = out.size();
      const std::size_t floats = static_cast<std::size_t>(range.count) * cols;
      float* rows = AppendJobResult(out, floats, 0);
      tbb::enumerable_thread_specific<uint64_t> rays(0);
      tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 16),
                        [&](const tbb::blocked_range<uint64_t>& r) {
                          for (uint64_t i = r.begin(); i != r.end(); ++i) {
                            const uint64_t v = range.first + i;
                            rays.local() +=
                                sampler->ComputeRow(samples[v], v, rows + i * cols).rays_traced;
                          }
                        });
      GatherStats s;
      for (uint64_t r : rays) s.rays_traced += r;
      FinishHeader(driver_, out, at, rows, floats, cols, range, s);
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      AddPassFigures(driver_, totals, 0);
    };
    driver_.RunJobs(ctx, jobs, start);
  }
};

class VertexBouncePhase final : public BouncePhase {
 public:
  VertexBouncePhase(int k, std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(k, false, std::move(figures), BouncePass::kVertexBounce), k_(k) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const std::vector<SpatialSample>& samples = VertexSamples(ctx);
    const uint64_t V = samples.size();
    const int C = ctx.params.channels, n = ctx.params.indirect_n;
    const std::size_t cols = CubemapLayout(n).texel_count();
    const int prev_channels = k_ == 1 ? 1 : C;
    std::vector<float> previous;
    driver_.ReadSceneRows(
        ctx, uint64_t(prev_channels) * V * cols * sizeof(float), "the vertices' previous bounce",
        [&] {
          ReadSupport(k_ == 1 ? ctx.folder.VertexDirectFile() : ctx.folder.VertexBounceFile(k_ - 1),
                      V, prev_channels, cols, n, previous, false);
        },
        {&previous});
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<BounceGatherer> gatherer;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, GatherOptionsOf(ctx));
    }
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      const std::size_t per_vertex = static_cast<std::size_t>(C) * cols;
      const std::size_t at = out.size();
      const std::size_t floats = static_cast<std::size_t>(range.count) * per_vertex;
      float* rows = AppendJobResult(out, floats, 0);
      tbb::enumerable_thread_specific<GatherStats> stats;
      tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 8),
                        [&](const tbb::blocked_range<uint64_t>& r) {
                          std::vector<GatherTerm> terms;
                          std::vector<float> near;
                          for (uint64_t i = r.begin(); i != r.end(); ++i) {
                            const uint64_t v = range.first + i;
                            stats.local() += gatherer->GatherRow(
                                samples[v], v, k_, C, previous.data(), V, prev_channels, cols,
                                rows + i * per_vertex, terms, near);
                          }
                        });
      GatherStats s;
      for (const GatherStats& l : stats) s += l;
      FinishHeader(driver_, out, at, rows, floats, per_vertex, range, s);
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      AddPassFigures(driver_, totals, k_);
    };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
  int k_;
};

class PixelGatherPhase final : public BouncePhase {
 public:
  explicit PixelGatherPhase(std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(1, false, std::move(figures), BouncePass::kPixelGather) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const uint64_t V = ctx.geometry.vertex_count();
    const int C = ctx.params.channels, K = ctx.params.bounces, n = ctx.params.indirect_n;
    const std::size_t cols = CubemapLayout(n).texel_count();
    // T⁰ at the vertices (one channel) and Σ_{k=1..K−1} Tᵏ (C channels; none when K = 1).
    std::vector<float> direct, higher;
    const uint64_t bytes = (uint64_t(1) + (K > 1 ? uint64_t(C) : 0)) * V * cols * sizeof(float);
    driver_.ReadSceneRows(
        ctx, bytes, "the vertices' support rows",
        [&] {
          ReadSupport(ctx.folder.VertexDirectFile(), V, 1, cols, n, direct, false);
          for (int k = 1; k < K; ++k)
            ReadSupport(ctx.folder.VertexBounceFile(k), V, C, cols, n, higher, k > 1);
        },
        {&direct, &higher});
    driver_.LoadCombination(ctx);
    std::unique_ptr<SceneSurfaces> surfaces;
    std::unique_ptr<BounceGatherer> gatherer;
    if (ctx.computes_here()) {
      surfaces = std::make_unique<SceneSurfaces>(ctx.geometry);
      gatherer = std::make_unique<BounceGatherer>(*ctx.embree, *surfaces, GatherOptionsOf(ctx));
    }
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.completes_stage = true;
    jobs.compute = [&](const RowRange& range, std::string& out) {
      const std::size_t per_pixel = static_cast<std::size_t>(C) * cols;
      const std::size_t at = out.size();
      const std::size_t floats = static_cast<std::size_t>(range.count) * per_pixel;
      float* rows = AppendJobResult(out, floats, 0);
      tbb::enumerable_thread_specific<GatherStats> stats;
      tbb::parallel_for(tbb::blocked_range<uint64_t>(0, range.count, 8),
                        [&](const tbb::blocked_range<uint64_t>& r) {
                          BounceGatherer::SumScratch scratch;
                          for (uint64_t i = r.begin(); i != r.end(); ++i) {
                            const uint64_t p = range.first + i;
                            float* dst = rows + i * per_pixel;
                            if (driver_.Combined(p) || ctx.samples[p].background) {
                              std::fill_n(dst, per_pixel, 0.0f);
                              continue;
                            }
                            stats.local() += gatherer->GatherSumRow(
                                ctx.samples[p], kPixelStream + p, ctx.pixel_edge[p], C, direct.data(),
                                higher.empty() ? nullptr : higher.data(), V, cols, dst, scratch);
                          }
                        });
      GatherStats s;
      for (const GatherStats& l : stats) s += l;
      FinishHeader(driver_, out, at, rows, floats, per_pixel, range, s);
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      AddPassFigures(driver_, totals, 0);
    };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
};

}  // namespace

std::unique_ptr<FarmPhase> MakeVertexDirectPhase(std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<VertexDirectPhase>(std::move(figures));
}

std::unique_ptr<FarmPhase> MakeVertexBouncePhase(int k,
                                                 std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<VertexBouncePhase>(k, std::move(figures));
}

std::unique_ptr<FarmPhase> MakePixelGatherPhase(std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<PixelGatherPhase>(std::move(figures));
}

}  // namespace prt
