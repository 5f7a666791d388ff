// prt-farm's estimate phase (docs/farm.md, "Accuracy estimates"): rank 0 turns the rows'
// Monte-Carlo variance sums (run/transport.variance, written by the sampling's finalize) into the
// relative RMS error of relit radiance B under a uniform sky of radiance 1 and under each of the
// scene's environments, per mesh (model and ground separately) and over the scene
// (worker/transport_error_estimate.h). The denominators Σ B² come from the rows of
// transport.prtt. Writes run/accuracy.json, keyed by the estimate stage's inputs, which the
// report (and prt-pack's META) carries.
#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "farm/farm_context.h"
#include "farm/progress.h"
#include "formats/transport_variance.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
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

}  // namespace

void LoadEstimateLights(FarmContext& ctx) {
  EstimateLights& e = ctx.estimate;
  if (e.loaded) return;
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
  e.loaded = true;
}

namespace {

class EstimatePhase final : public FarmPhase {
 public:
  const char* name() const override { return "estimate"; }

  void Run(FarmContext& ctx) override {
    if (ctx.rank != 0) return;
    ctx.run_eta.StepStarted("estimate");
    const RunFolder& f = ctx.folder;
    const int n = ctx.params.cubemap_n;
    Json out;
    out["key"] = ctx.estimate_key;
    TransportVariance variance;
    bool have_variance = std::filesystem::exists(f.variance);
    if (have_variance) {
      variance = DecodeTransportVariance(ReadWholeFile(f.variance), f.variance);
      if (variance.cubemap_n != static_cast<uint32_t>(n) ||
          variance.sums.size() != ctx.geometry.meshes.size())
        throw InputError(f.variance, "does not describe this run's rows and meshes");
    }

    LoadEstimateLights(ctx);
    const std::vector<std::string>& names = ctx.estimate.names;
    const std::vector<CubemapRgb>& lights = ctx.estimate.lights;
    const Json skipped = Json::parse(ctx.estimate.left_out_json);

    // Σ B² per light, mesh and channel: accumulated by the compression phase as the rows passed
    // through it, else read here from the rows.
    std::vector<uint64_t> mesh_rows;
    for (const SceneMesh& m : ctx.geometry.meshes) mesh_rows.push_back(m.mesh.positions.size());
    RadianceNormAccumulator norms(lights, mesh_rows);
    if (ctx.estimate.have_norms) {
      norms.Set(ctx.estimate.norms);
    } else {
      const TransportFileReader reader(f.transport);
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
    }

    const bool estimable = have_variance && variance.rays_per_texel >= 2;
    Json mc;
    mc["rays_per_texel"] = ctx.params.rays_per_texel;
    mc["estimable"] = estimable;
    if (!have_variance) {
      mc["why_not"] = "transport.variance is missing (rows of an older prt-farm)";
    } else if (!estimable) {
      mc["why_not"] = "one ray per texel: no two strata to compare";
    }
    mc["method"] = ctx.report.method;
    mc["covers"] = ctx.report.method == "sparse"
                       ? "traced texels: every texel of the dense rows, the traced features of "
                         "the reconstructed rows (their other texels' error is the fit's)"
                       : "every texel";
    Json meshes = Json::array();
    for (std::size_t m = 0; m < mesh_rows.size(); ++m) {
      meshes.push_back({{"name", ctx.geometry.meshes[m].name},
                        {"rows", mesh_rows[m]},
                        {"rows_covered", have_variance ? variance.rows_covered[m] : 0}});
    }
    mc["meshes"] = meshes;
    Json envs = Json::array();
    double worst = 0;
    for (std::size_t l = 0; l < lights.size(); ++l) {
      Json per_mesh = Json::array();
      double var_all = 0, norm_all = 0;
      for (std::size_t m = 0; m < mesh_rows.size(); ++m) {
        const Rgb& rho = ctx.geometry.meshes[m].albedo;
        const std::array<double, 3> v =
            estimable ? MeshRadianceVariance(variance, m, lights[l]) : std::array<double, 3>{};
        double var_m = 0, norm_m = 0;
        for (int c = 0; c < 3; ++c) {
          const double r2 = double(rho[c]) * rho[c];
          var_m += r2 * v[c];
          norm_m += r2 * norms.norms()[l][m][c];
        }
        var_all += var_m;
        norm_all += norm_m;
        per_mesh.push_back(
            {{"name", ctx.geometry.meshes[m].name},
             {"relative_rms", Ratio(var_m, norm_m)},
             {"rms_radiance",
              mesh_rows[m] ? std::sqrt(var_m / (3.0 * static_cast<double>(mesh_rows[m]))) : 0.0}});
      }
      const double rel = Ratio(var_all, norm_all);
      worst = std::max(worst, rel);
      envs.push_back({{"name", names[l]}, {"relative_rms", rel}, {"meshes", per_mesh}});
    }
    mc["environments"] = envs;
    mc["worst_relative_rms"] = worst;
    if (!skipped.empty()) mc["environments_left_out"] = skipped;
    out["monte_carlo"] = mc;
    WriteFileDurably(f.accuracy, out.dump(2) + "\n");
    ctx.run_eta.StepFinished("estimate");
    if (!ctx.options.quiet) {
      if (estimable) {
        std::string line;
        for (const Json& e : envs) {
          char buf[96];
          std::snprintf(buf, sizeof buf, "%s%s %.3f%%", line.empty() ? "" : ", ",
                        e["name"].get<std::string>().c_str(),
                        100 * e["relative_rms"].get<double>());
          line += buf;
        }
        spdlog::info("estimate: Monte-Carlo error of B (relative RMS): {}; in {}", line,
                     f.accuracy);
      } else {
        spdlog::info("estimate: no Monte-Carlo error estimate ({}); in {}",
                     mc["why_not"].get<std::string>(), f.accuracy);
      }
    }
  }
};

}  // namespace

std::unique_ptr<FarmPhase> MakeEstimatePhase() {
  return std::make_unique<EstimatePhase>();
}

}  // namespace prt
