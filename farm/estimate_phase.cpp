// prt-farm's estimate phase (docs/farm.md, "Accuracy estimates"): rank 0 turns the rows'
// Monte-Carlo variance sums (run/transport.variance, written by the sampling's finalize) into the
// relative RMS error of relit radiance B under a uniform sky of radiance 1 and under each of the
// scene's environments, per mesh (model and ground separately) and over the scene
// (worker/transport_error_estimate.h). The denominators Σ B² come from the rows of
// transport.prtt. Writes run/accuracy.json, keyed by the estimate stage's inputs, which the
// report (and prt-pack's META) carries.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "farm/farm_context.h"
#include "farm/progress.h"
#include "formats/transport_variance.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "worker/sparse_reconstruction.h"
#include "worker/transport_error_estimate.h"

namespace prt {

namespace {

using Json = nlohmann::ordered_json;

CubemapRgb UniformLight(int n) {
  CubemapRgb l;
  l.n = n;
  const std::size_t t = l.TexelCount();
  l.r.assign(t, 1.0f);
  l.g.assign(t, 1.0f);
  l.b.assign(t, 1.0f);
  return l;
}

double Ratio(double num, double den) {
  return den > 0 ? std::sqrt(std::max(0.0, num) / den) : 0.0;
}

// run/sparse/cross_validation.{json,bin} of the sparse method (farm/sparse_phase.cpp).
struct CrossValidation {
  bool present = false;
  uint64_t vertices = 0;                // cross-validated (fallbacks included)
  std::vector<uint64_t> samples;        // per mesh: cross-validated vertices in it
  std::vector<uint64_t> reconstructed;  // per mesh: vertices the pipeline reconstructed
  std::vector<std::pair<std::size_t, std::vector<float>>> rows;  // (mesh, Δ row) reconstructed
};

CrossValidation ReadCrossValidation(const FarmContext& ctx, std::size_t meshes) {
  CrossValidation cv;
  const std::filesystem::path dir = ctx.folder.sparse;
  const std::string json = (dir / "cross_validation.json").string();
  const std::string bin = (dir / "cross_validation.bin").string();
  if (ctx.report.method != "sparse" || !std::filesystem::exists(json)) return cv;
  const Json j = Json::parse(ReadWholeFile(json), nullptr, false);
  const std::size_t T = 6u * ctx.params.cubemap_n * ctx.params.cubemap_n;
  if (!j.is_object() || j.value("texels", std::size_t{0}) != T ||
      !j.contains("reconstructed_per_mesh") || j["reconstructed_per_mesh"].size() != meshes)
    throw InputError(json, "does not describe this run's cross-validation");
  const std::vector<uint32_t> ids = j.at("vertices").get<std::vector<uint32_t>>();
  cv.reconstructed = j["reconstructed_per_mesh"].get<std::vector<uint64_t>>();
  const std::string bytes = ReadWholeFile(bin);
  const std::size_t record = 4 + 4 * T;
  if (bytes.size() < ids.size() * record)
    throw InputError(bin, "holds fewer records than cross_validation.json lists");
  cv.samples.assign(meshes, 0);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::size_t m = ctx.GroupOfRow(ids[i]);
    if (m >= meshes) throw InputError(json, "names a vertex beyond the meshes");
    ++cv.samples[m];
    const char* rec = bytes.data() + i * record;
    if (static_cast<uint8_t>(rec[0]) != static_cast<uint8_t>(SparseOutcome::kReconstructed))
      continue;  // fell back: the pipeline traces such a vertex, its error is the rays'
    std::vector<float> diff(T);
    std::memcpy(diff.data(), rec + 4, T * sizeof(float));
    for (float d : diff)
      if (!std::isfinite(d)) throw InputError(bin, "holds a non-finite difference");
    cv.rows.emplace_back(m, std::move(diff));
  }
  cv.vertices = ids.size();
  cv.present = true;
  return cv;
}

}  // namespace

std::string AccuracyLine(const nlohmann::ordered_json& accuracy) {
  if (!accuracy.is_object() || !accuracy.contains("monte_carlo")) return "no error estimate";
  const Json& mc = accuracy["monte_carlo"];
  if (!mc.value("estimable", false))
    return "no Monte-Carlo error estimate (" + mc.value("why_not", std::string("?")) + ")";
  const bool total = accuracy.contains("total");
  std::string line = total ? "error of B (rays + reconstruction)" : "Monte-Carlo error of B";
  for (const Json& e : total ? accuracy["total"]["environments"] : mc["environments"]) {
    char buf[96];
    std::snprintf(buf, sizeof buf, " %.2f%% %s", 100 * e.value("relative_rms", 0.0),
                  e.value("name", std::string()).c_str());
    line += buf;
  }
  return line;
}

EstimateLights& LoadEstimateLights(FarmContext& ctx) {
  if (EstimateLights* loaded = ctx.results.Find<EstimateLights>()) return *loaded;
  EstimateLights& e = ctx.results.Put(EstimateLights{});
  const int n = ctx.params.cubemap_n;
  e.names = {"uniform"};
  e.lights = {UniformLight(n)};
  Json skipped = Json::array();
  for (const std::string& path : ctx.scene.environments) {
    try {
      e.lights.push_back(ResampleToCubemap(ReadEnvironment(path), n));
      e.names.push_back(std::filesystem::path(path).filename().string());
    } catch (const std::exception& err) {
      skipped.push_back({{"path", path}, {"error", err.what()}});
      spdlog::warn("estimate: environment {} left out: {}", path, err.what());
    }
  }
  e.left_out_json = skipped.dump();
  return e;
}

namespace {

class EstimatePhase final : public FarmPhase {
 public:
  const char* name() const override { return "estimate"; }
  const char* stage() const override { return kStageEstimate; }
  // Over the raw rows' bytes: nearly free when the compression phase accumulated Σ B² as the
  // rows passed, else one read of transport.prtt (~400 MB/s on the 2-core VM).
  void PredictSteps(const FarmContext& ctx, std::vector<RunStep>& steps) const override {
    const double raw_bytes = static_cast<double>(ctx.params.rows) * 6.0 * ctx.params.cubemap_n *
                             ctx.params.cubemap_n * 4.0;
    steps.push_back(
        {"estimate", "estimate", raw_bytes, ctx.params.run_compression ? 1e-11 : 2.5e-9});
  }

  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    ctx.run_eta.StepStarted("estimate");
    const RunFolder& f = ctx.folder;
    Json out;
    out["key"] = ctx.estimate_key;
    const std::optional<TransportVariance> variance = ReadVariance(ctx);
    const EstimateLights& estimate = LoadEstimateLights(ctx);
    const std::vector<uint64_t> mesh_rows = ctx.RowGroups();
    const RadianceNormAccumulator norms = RadianceNorms(ctx, estimate, mesh_rows);
    const bool estimable = variance && variance->rays_per_texel >= 2;
    const CrossValidation cv = ReadCrossValidation(ctx, mesh_rows.size());
    const ErrorVariances ev =
        ComputeErrorVariances(ctx, estimable ? &*variance : nullptr, estimate, norms, cv);

    // One table per kind of error: Monte-Carlo, reconstruction (sparse), and both.
    Json mc = MonteCarloHeader(ctx, variance ? &*variance : nullptr, estimable);
    const auto [envs, worst] =
        ErrorTable(ctx, estimate, ev, [&](std::size_t l, std::size_t m) { return ev.mc[l][m]; });
    mc["environments"] = envs;
    mc["worst_relative_rms"] = worst;
    const Json skipped = Json::parse(estimate.left_out_json);
    if (!skipped.empty()) mc["environments_left_out"] = skipped;
    out["monte_carlo"] = mc;
    if (cv.present) {
      const auto [rec_envs, rec_worst] = ErrorTable(
          ctx, estimate, ev, [&](std::size_t l, std::size_t m) { return ev.reconstruction[l][m]; });
      Json rec;
      rec["cross_validated"] = cv.rows.size();
      rec["vertices"] = cv.vertices;
      rec["reconstructed_per_mesh"] = cv.reconstructed;
      rec["environments"] = rec_envs;
      rec["worst_relative_rms"] = rec_worst;
      out["reconstruction"] = rec;
      const auto [tot_envs, tot_worst] =
          ErrorTable(ctx, estimate, ev, [&](std::size_t l, std::size_t m) {
            Rgb3 t;
            for (int c = 0; c < 3; ++c) t[c] = ev.mc[l][m][c] + ev.reconstruction[l][m][c];
            return t;
          });
      out["total"] = {{"environments", tot_envs}, {"worst_relative_rms", tot_worst}};
    }
    WriteFileDurably(f.accuracy, out.dump(2) + "\n");
    ctx.run_eta.StepFinished("estimate");
    if (!ctx.options.quiet) spdlog::info("estimate: {}; in {}", AccuracyLine(out), f.accuracy);
  }

 private:
  // Per light and mesh: the Monte-Carlo and reconstruction variances of Σ B (albedo-weighted)
  // and Σ B² of the mesh's rows, the tables' numerators and denominators.
  // Per colour channel too: [light][mesh][channel].
  using Rgb3 = std::array<double, 3>;
  struct ErrorVariances {
    std::vector<std::vector<Rgb3>> mc, reconstruction, norm;  // [light][mesh][channel]
  };
  static double Sum3(const Rgb3& v) { return v[0] + v[1] + v[2]; }

  // transport.variance, checked against this run (nothing when an older prt-farm left none).
  static std::optional<TransportVariance> ReadVariance(const FarmContext& ctx) {
    const RunFolder& f = ctx.folder;
    if (!std::filesystem::exists(f.variance)) return std::nullopt;
    TransportVariance variance = DecodeTransportVariance(ReadWholeFile(f.variance), f.variance);
    if (ctx.params.image && variance.cubemap_n == static_cast<uint32_t>(ctx.params.cubemap_n) &&
        variance.sums.size() == 1 && ctx.RowGroups().size() != 1) {
      // An image run of a prt-farm before the pixels were grouped by mesh: one group of all
      // pixels, which the per-mesh tables cannot split.
      spdlog::warn("{}: one group of all pixels (an older prt-farm's); no Monte-Carlo estimate",
                   f.variance);
      return std::nullopt;
    }
    if (variance.cubemap_n != static_cast<uint32_t>(ctx.params.cubemap_n) ||
        variance.sums.size() != ctx.RowGroups().size())
      throw InputError(f.variance, "does not describe this run's rows and meshes");
    return variance;
  }

  // Σ B² per light, mesh and channel: accumulated by the compression phase as the rows passed
  // through it, else read here from the rows.
  static RadianceNormAccumulator RadianceNorms(FarmContext& ctx, const EstimateLights& estimate,
                                               const std::vector<uint64_t>& mesh_rows) {
    RadianceNormAccumulator norms(estimate.lights, mesh_rows, 1, ctx.SampleGroups());
    if (estimate.have_norms) {
      norms.Set(estimate.norms);
      return norms;
    }
    const TransportFileReader reader(ctx.folder.transport);
    const TransportFileInfo& info = reader.info();
    Progress progress("estimate", info.block_count(), FarmProgressOptions(ctx, "blocks"));
    std::vector<float> block;
    for (uint64_t b = 0; b < info.block_count(); ++b) {
      block.resize(static_cast<std::size_t>(info.RowsInBlock(b) * info.cols()));
      reader.ReadBlock(b, block);
      norms.AddRows(info.FirstRowOfBlock(b), info.RowsInBlock(b), block.data());
      progress.Advance(1);
    }
    progress.Finish();
    return norms;
  }

  // accuracy.json "monte_carlo" before its tables: what the estimate covers, or why there is none.
  static Json MonteCarloHeader(const FarmContext& ctx, const TransportVariance* variance,
                               bool estimable) {
    Json mc;
    mc["rays_per_texel"] = ctx.params.rays_per_texel;
    mc["estimable"] = estimable;
    if (!variance) {
      mc["why_not"] = "transport.variance is missing (rows of an older prt-farm)";
    } else if (!estimable) {
      mc["why_not"] = "one ray per texel: no two strata to compare";
    }
    mc["method"] = ctx.report.method;
    mc["covers"] = ctx.report.method == "sparse"
                       ? "traced texels: every texel of the dense rows, the traced features of "
                         "the reconstructed rows (their other texels' error is the fit's)"
                       : "every texel";
    const std::vector<uint64_t> mesh_rows = ctx.RowGroups();
    Json meshes = Json::array();
    for (std::size_t m = 0; m < mesh_rows.size(); ++m) {
      meshes.push_back({{"name", ctx.GroupName(m)},
                        {"rows", mesh_rows[m]},
                        {"rows_covered", variance ? variance->rows_covered[m] : 0}});
    }
    mc["meshes"] = meshes;
    return mc;
  }

  // `variance`: nullptr when the Monte-Carlo error cannot be estimated (its variances are 0).
  // The sparse method's reconstruction error, from its cross-validation (farm/sparse_phase.cpp
  // CrossValidate): per light, mesh and channel, Σ over the mesh's reconstructed vertices of
  // E|ΔB|², as the mesh's cross-validated mean of |ΔB|² less a dense row's own Monte-Carlo
  // variance (the reference it was compared with is itself an estimate), times the number of
  // vertices the pipeline reconstructed.
  static ErrorVariances ComputeErrorVariances(const FarmContext& ctx,
                                              const TransportVariance* variance,
                                              const EstimateLights& estimate,
                                              const RadianceNormAccumulator& norms,
                                              const CrossValidation& cv) {
    const std::vector<CubemapRgb>& lights = estimate.lights;
    const std::size_t meshes = ctx.RowGroups().size();
    ErrorVariances ev;
    ev.mc.resize(lights.size());
    ev.reconstruction.resize(lights.size());
    ev.norm.resize(lights.size());
    for (std::size_t l = 0; l < lights.size(); ++l) {
      for (std::size_t m = 0; m < meshes; ++m) {
        const Rgb rho = ctx.GroupAlbedo(m);
        const std::array<double, 3> v =
            variance ? MeshRadianceVariance(*variance, m, lights[l]) : std::array<double, 3>{};
        Rgb3 var_m{}, norm_m{};
        for (int c = 0; c < 3; ++c) {
          const double r2 = double(rho[c]) * rho[c];
          var_m[c] = r2 * v[c];
          norm_m[c] = r2 * norms.norms()[l][m][c];
        }
        ev.mc[l].push_back(var_m);
        ev.norm[l].push_back(norm_m);
        ev.reconstruction[l].push_back(Rgb3{});
      }
      if (!cv.present) continue;
      // Σ |ΔB_c|² of each mesh's cross-validated vertices under this light.
      std::vector<Rgb3> sum(meshes, Rgb3{});
      for (const auto& [m, diff] : cv.rows) {
        const Rgb rho = ctx.GroupAlbedo(m);
        for (int c = 0; c < 3; ++c) {
          double b = 0;
          const float* L = lights[l].Channel(c).data();
          for (std::size_t j = 0; j < diff.size(); ++j) b += double(diff[j]) * L[j];
          sum[m][c] += double(rho[c]) * rho[c] * b * b;
        }
      }
      for (std::size_t m = 0; m < meshes; ++m) {
        if (cv.samples[m] == 0) continue;
        const bool covered =
            variance && !variance->rows_covered.empty() && variance->rows_covered[m] != 0;
        for (int c = 0; c < 3; ++c) {
          const double mean = sum[m][c] / static_cast<double>(cv.samples[m]);
          const double per_row_mc =
              covered ? ev.mc[l][m][c] / static_cast<double>(variance->rows_covered[m]) : 0.0;
          ev.reconstruction[l][m][c] =
              static_cast<double>(cv.reconstructed[m]) * std::max(0.0, mean - per_row_mc);
        }
      }
    }
    return ev;
  }

  // One table of accuracy.json: per environment, the relative RMS error of B (the variance
  // `var_of(light, mesh)`, per channel, over Σ B²), per mesh (and per colour channel) and over
  // all; and the worst environment's.
  template <class VarianceOf>
  static std::pair<Json, double> ErrorTable(const FarmContext& ctx, const EstimateLights& estimate,
                                            const ErrorVariances& ev, VarianceOf&& var_of) {
    const std::vector<uint64_t> mesh_rows = ctx.RowGroups();
    Json envs = Json::array();
    double worst = 0;
    for (std::size_t l = 0; l < estimate.lights.size(); ++l) {
      Json per_mesh = Json::array();
      double var_all = 0, norm_all = 0;
      for (std::size_t m = 0; m < mesh_rows.size(); ++m) {
        const Rgb3 var_c = var_of(l, m);
        const double var_m = Sum3(var_c);
        var_all += var_m;
        norm_all += Sum3(ev.norm[l][m]);
        Json channels = Json::object();
        for (int c = 0; c < 3; ++c)
          channels[std::string(1, "rgb"[c])] = Ratio(var_c[c], ev.norm[l][m][c]);
        per_mesh.push_back(
            {{"name", ctx.GroupName(m)},
             {"rows", mesh_rows[m]},
             {"relative_rms", Ratio(var_m, Sum3(ev.norm[l][m]))},
             {"relative_rms_per_channel", channels},
             {"rms_radiance",
              mesh_rows[m] ? std::sqrt(var_m / (3.0 * static_cast<double>(mesh_rows[m]))) : 0.0}});
      }
      const double rel = Ratio(var_all, norm_all);
      worst = std::max(worst, rel);
      envs.push_back({{"name", estimate.names[l]}, {"relative_rms", rel}, {"meshes", per_mesh}});
    }
    return {envs, worst};
  }
};

}  // namespace

// accuracy.json, when the estimate stage runs.
void AddEstimatePhase(const FarmContext& ctx, PhaseList& phases) {
  if (ctx.params.run_estimate) phases.push_back(std::make_unique<EstimatePhase>());
}

}  // namespace prt
