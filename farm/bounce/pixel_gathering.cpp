// An image run's interreflection by bounce gathering (docs/image-relighting.md,
// "Interreflection"; worker/bounce_gather.h; the indirect part on the low-resolution grid as in
// Huang & Ramamoorthi 2010 §4.2 and §7). A pixel's gather interpolates the previous bounce
// at the vertices of the triangle its direction hits, so the run computes support rows at the
// mesh vertices first, on the indirect grid (m = indirect_n), never shipped:
//   "vertex-direct"       T⁰(v): rays_per_texel jittered shadow rays per coarse texel
//                         (indirect/vertex-direct.prtt, one channel);
//   "vertex-bounce-<k>"   Tᵏ(v), k = 1 … K−1, gathered from Tᵏ⁻¹ exactly as a vertex run's
//                         bounce k (near field in bounce 1; indirect/vertex-bounce-<k>.prtt) by
//                         farm/bounce/gathering.cpp's phase on the vertices;
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
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "farm/bounce/driver.h"
#include "farm/bounce/estimators.h"
#include "vocabulary/errors.h"
#include "vocabulary/hash.h"

namespace prt {

const std::vector<SpatialSample>& ImageVertexSamples(FarmContext& ctx) {
  struct Kept {
    std::vector<SpatialSample> samples;
  };
  if (const Kept* v = ctx.results.Find<Kept>()) return v->samples;
  return ctx.results.Put(Kept{SpatialSamplesOf(ctx.geometry)}).samples;
}

void ReadSupportRows(const std::string& path, uint64_t rows, int channels,
                     const CubemapLayout& grid, std::vector<float>& out, bool add) {
  const TransportFileReader reader(path);
  if (reader.info().rows != uint64_t(channels) * rows ||
      reader.info().cubemap_n != uint32_t(grid.n()))
    throw InputError(path, "does not hold " + std::to_string(channels) + " × " +
                               std::to_string(rows) + " rows at n = " + std::to_string(grid.n()));
  const std::size_t floats = static_cast<std::size_t>(channels * rows) * grid.texel_count();
  if (!add) {
    out.resize(floats);
    reader.ReadRows(0, reader.info().rows, out.data());
    return;
  }
  std::vector<float> more(floats);
  reader.ReadRows(0, reader.info().rows, more.data());
  for (std::size_t i = 0; i < floats; ++i) out[i] += more[i];
}

void AddImagePassFigures(BounceDriver& driver, const BounceTotals& totals, int k) {
  nlohmann::ordered_json f = TracedFigures(totals, k);
  f["phase"] = driver.name();
  driver.figures()["image_passes"].push_back(std::move(f));
}

namespace {

// The gathers of pixels draw from their own stream: pixel p gathers as index kPixelStream + p.
constexpr uint64_t kPixelStream = uint64_t{1} << 48;

class VertexDirectPhase final : public BouncePhase {
 public:
  explicit VertexDirectPhase(std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(0, false, std::move(figures), BouncePass::kVertexDirect) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const std::vector<SpatialSample>& samples = ImageVertexSamples(ctx);
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
      ComputeJobRows(driver_.name(), range, cols, out, [&](uint64_t v, float* dst) {
        GatherStats st;
        st.rays_traced = sampler->ComputeRow(samples[v], v, dst).rays_traced;
        return st;
      });
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      AddImagePassFigures(driver_, totals, 0);
    };
    driver_.RunJobs(ctx, jobs, start);
  }
};

class PixelGatherPhase final : public BouncePhase {
 public:
  explicit PixelGatherPhase(std::shared_ptr<nlohmann::ordered_json> figures)
      : BouncePhase(1, false, std::move(figures), BouncePass::kPixelGather) {}

  void Run(FarmContext& ctx) override {
    const double start = FarmNow();
    const uint64_t V = ctx.geometry.vertex_count();
    const int C = ctx.params.channels, K = ctx.params.bounces;
    const CubemapLayout grid(ctx.params.indirect_n);
    const std::size_t cols = grid.texel_count();
    // T⁰ at the vertices (one channel) and Σ_{k=1..K−1} Tᵏ (C channels; none when K = 1).
    std::vector<float> direct, higher;
    const uint64_t bytes = (uint64_t(1) + (K > 1 ? uint64_t(C) : 0)) * V * cols * sizeof(float);
    driver_.ReadSceneRows(
        ctx, bytes, "the vertices' support rows",
        [&] {
          ReadSupportRows(ctx.folder.VertexDirectFile(), V, 1, grid, direct, false);
          for (int k = 1; k < K; ++k)
            ReadSupportRows(ctx.folder.VertexBounceFile(k), V, C, grid, higher, k > 1);
        },
        {&direct, &higher});
    driver_.LoadCombination(ctx);
    const GatherKernels kernels(ctx);
    const BounceGatherer* gatherer = kernels.gatherer.get();
    BounceDriver::Jobs jobs;
    jobs.cols = cols;
    jobs.completes_stage = true;
    // Zero rows for background pixels and combined ones (rank 0 fills those).
    jobs.compute = [&](const RowRange& range, std::string& out) {
      const std::size_t per_pixel = static_cast<std::size_t>(C) * cols;
      ComputeJobRows(driver_.name(), range, per_pixel, out, [&](uint64_t p, float* dst) {
        if (driver_.Combined(p) || ctx.samples[p].background) {
          std::fill_n(dst, per_pixel, 0.0f);
          return GatherStats{};
        }
        thread_local BounceGatherer::SumScratch scratch;
        // A supersampled pixel gathers from its footprint's sub-samples (docs/image-relighting.md,
        // "Supersampling"); a glossy point (the pixel's, or a sub-sample's) through its lobe, with
        // the view from the camera ("Glossy pixels").
        GatherSite where;
        if (ctx.samples[p].supersampled && ctx.footprints) {
          where.footprint = ctx.footprints.get();
          where.first = ctx.footprints->offset[p];
          where.count = ctx.footprints->offset[p + 1] - ctx.footprints->offset[p];
        }
        const GatherLobe lobe{ctx.glossy_pixels.materials, ctx.params.camera.eye};
        if (ctx.glossy_pixels.any()) where.lobe = &lobe;
        return gatherer->GatherSumRow(ctx.samples[p], kPixelStream + p, ctx.pixel_edge[p], C,
                                      direct.data(), higher.empty() ? nullptr : higher.data(), V,
                                      cols, dst, scratch, where);
      });
    };
    jobs.report = [&](FarmContext&, const BounceTotals& totals) {
      AddImagePassFigures(driver_, totals, 0);
    };
    driver_.RunJobs(ctx, jobs, start);
  }

 private:
};

}  // namespace

std::unique_ptr<FarmPhase> MakeVertexDirectPhase(std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<VertexDirectPhase>(std::move(figures));
}

std::unique_ptr<FarmPhase> MakePixelGatherPhase(std::shared_ptr<nlohmann::ordered_json> figures) {
  return std::make_unique<PixelGatherPhase>(std::move(figures));
}

}  // namespace prt
