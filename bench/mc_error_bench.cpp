// prt-mc-check (scripts/bench.sh mc-error; docs/farm.md "Accuracy estimates"): are the farm's
// error estimates right? Two runs of the same scene — two seeds of one method (prt-farm --seed),
// or the sparse method against brute force — give two estimates T_a and T_b of the same T. The
// relative RMS difference of their relit radiances,
//   D = sqrt(Σ_v ‖B_a,v − B_b,v‖²) / sqrt(Σ_v ‖(B_a,v + B_b,v)/2‖²),
// is measured under a uniform sky and every environment of the scene, per mesh, and compared
// with what the runs' accuracy.json predict for it, sqrt(e_a² + e_b²), where e is each run's
// estimate of its own error ("total" for the sparse method: rays and reconstruction; else
// "monte_carlo"). The errors of two brute-force seeds are independent, so the prediction holds
// exactly when the estimates do; two sparse seeds share most of their reconstruction's error
// (the same geometry, much the same dense vertices), so their D shows only its variable part.
//
//   prt-mc-check RUN_A RUN_B [--data-dir DIR]
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench/bench_scenes.h"
#include "formats/geometry_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/scene.h"
#include "vocabulary/tbb_parallel.h"

namespace {

using prt::CubemapRgb;

// Per light and mesh: Σ‖B_a − B_b‖² and Σ‖(B_a + B_b)/2‖² over the mesh's vertices.
struct Sums {
  double diff2 = 0, mean2 = 0;
};

}  // namespace

int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  std::string run_a, run_b;
  std::vector<std::string> data_dirs;
  CLI::App app("prt-mc-check: the farm's Monte-Carlo error estimate against two seeds");
  app.add_option("run_a", run_a, "run folder of one seed")->required();
  app.add_option("run_b", run_b, "run folder of another seed (same scene otherwise)")->required();
  app.add_option("--data-dir", data_dirs, "folders to look up the scene's environments in");
  CLI11_PARSE(app, argc, argv);
  try {
    const prt::RunFolder a(run_a), b(run_b);
    const prt::SceneGeometry geometry = prt::ReadSceneGeometryFile(a.geometry);
    std::vector<std::string> dirs = data_dirs;
    dirs.push_back(prt::bench::DataDir());
    const prt::SceneDescription scene =
        prt::ParseScene(prt::ReadWholeFile(a.scene_copy), a.scene_copy, "", dirs);
    const prt::TransportFileReader ta(a.transport), tb(b.transport);
    if (!(ta.info().rows == tb.info().rows && ta.info().cubemap_n == tb.info().cubemap_n))
      throw std::runtime_error("the two runs do not hold the same matrix shape");
    const int n = static_cast<int>(ta.info().cubemap_n);
    std::vector<std::string> names = {"uniform"};
    std::vector<CubemapRgb> lights(1);
    lights[0].n = n;
    for (int c = 0; c < 3; ++c) lights[0].Channel(c).assign(6u * n * n, 1.0f);
    for (const std::string& p : scene.environments) {
      lights.push_back(
          prt::ResampleToCubemap(prt::ReadEnvironment(prt::ResolveScenePath(scene, p)), n));
      names.push_back(std::filesystem::path(p).filename().string());
    }
    const std::size_t M = geometry.meshes.size(), T = ta.info().cols();
    std::vector<std::vector<Sums>> sums(lights.size(), std::vector<Sums>(M));
    std::vector<float> ra, rb;
    for (uint64_t blk = 0; blk < ta.info().block_count(); ++blk) {
      ra = ta.ReadBlock(blk);
      rb = tb.ReadBlock(blk);
      const uint64_t first = ta.info().FirstRowOfBlock(blk);
      for (uint64_t r = 0; r < ta.info().RowsInBlock(blk); ++r) {
        const std::size_t m = geometry.MeshOfVertex(first + r);
        const prt::Rgb& rho = geometry.meshes[m].albedo;
        for (std::size_t l = 0; l < lights.size(); ++l) {
          for (int c = 0; c < 3; ++c) {
            const float* L = lights[l].Channel(c).data();
            double ba = 0, bb = 0;
            for (std::size_t j = 0; j < T; ++j) {
              ba += double(ra[r * T + j]) * L[j];
              bb += double(rb[r * T + j]) * L[j];
            }
            ba *= rho[c];
            bb *= rho[c];
            sums[l][m].diff2 += (ba - bb) * (ba - bb);
            sums[l][m].mean2 += 0.25 * (ba + bb) * (ba + bb);
          }
        }
      }
    }
    const nlohmann::json acc_a = nlohmann::json::parse(prt::ReadWholeFile(a.accuracy));
    const nlohmann::json acc_b = nlohmann::json::parse(prt::ReadWholeFile(b.accuracy));
    const char* kind_a = acc_a.contains("total") ? "total" : "monte_carlo";
    const char* kind_b = acc_b.contains("total") ? "total" : "monte_carlo";
    std::printf("estimates: run a accuracy.json \"%s\", run b \"%s\"\n", kind_a, kind_b);
    std::printf("%-14s %-10s %11s %11s %11s %11s %8s\n", "light", "mesh", "measured D",
                "estimate a", "estimate b", "predicted", "pred/D");
    double worst = 1;
    for (std::size_t l = 0; l < lights.size(); ++l) {
      const nlohmann::json& ea = acc_a[kind_a]["environments"][l];
      const nlohmann::json& eb = acc_b[kind_b]["environments"][l];
      Sums all;
      for (std::size_t m = 0; m <= M; ++m) {
        Sums s = m < M ? sums[l][m] : all;
        if (m < M) {
          all.diff2 += s.diff2;
          all.mean2 += s.mean2;
        }
        const double measured = s.mean2 > 0 ? std::sqrt(s.diff2 / s.mean2) : 0.0;
        const double est_a =
            m < M ? ea["meshes"][m].value("relative_rms", 0.0) : ea.value("relative_rms", 0.0);
        const double est_b =
            m < M ? eb["meshes"][m].value("relative_rms", 0.0) : eb.value("relative_rms", 0.0);
        const double predicted = std::sqrt(est_a * est_a + est_b * est_b);
        const double ratio = measured > 0 ? predicted / measured : 0.0;
        if (ratio > 0) worst = std::max(worst, std::max(ratio, 1 / ratio));
        std::printf("%-14s %-10s %10.4f%% %10.4f%% %10.4f%% %10.4f%% %8.3f\n", names[l].c_str(),
                    m < M ? geometry.meshes[m].name.c_str() : "all", 100 * measured, 100 * est_a,
                    100 * est_b, 100 * predicted, ratio);
      }
    }
    std::printf("largest factor between prediction and measurement: %.3f\n", worst);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "prt-mc-check: %s\n", e.what());
    return 1;
  }
}
