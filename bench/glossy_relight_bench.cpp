// glossy_relight_bench: what a frame of a glossy vertex pack (docs/glossy-transport.md) costs
// against a diffuse pack of the same geometry, in one run (the machine is shared: compare the
// ratios). For each pack: open, then under the environment map, the median of --repeats of
//   lighting change, exact:  RelightSession::RelightExact  (every Haar coefficient, m·V rows)
//   lighting change, NWA-N:  RelightApproximate(nwa, N)    (the N largest terms)
//   camera move:             Shade(radiance, new eye)       (a glossy pack: the m-term sum per
//                                                            vertex, CombineTerms, then albedo)
// and the pack's size. The camera move orbits the eye about the camera target by 10° a frame.
//
// Usage: glossy_relight_bench GLOSSY.prtpack DIFFUSE.prtpack --env map.exr [--terms 100]
//        [--repeats 9]
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "runtime/relight_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/tbb_parallel.h"

namespace {

template <class F>
double MedianMs(int repeats, F&& f) {
  std::vector<double> t;
  for (int i = 0; i < repeats; ++i) {
    const auto a = std::chrono::steady_clock::now();
    f(i);
    t.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - a).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace prt;
  CLI::App app{"glossy_relight_bench: a glossy vertex pack's frame against a diffuse pack's"};
  std::vector<std::string> packs;
  std::string env;
  std::size_t terms = 100;
  int repeats = 9;
  app.add_option("packs", packs, "glossy pack, then diffuse pack")->required()->expected(2);
  app.add_option("--env", env, "environment map")->required();
  app.add_option("--terms", terms, "NWA terms");
  app.add_option("--repeats", repeats, "frames per figure (median)");
  CLI11_PARSE(app, argc, argv);
  UseTbbParallelism();
  const EnvironmentImage image = ReadEnvironment(env);
  std::printf("%-10s %9s %6s %10s %11s %11s %11s %10s\n", "pack", "vertices", "terms", "size MB",
              "exact ms", "NWA ms", "camera ms", "shade ms");
  double base[4] = {0, 0, 0, 0};
  for (std::size_t k = 0; k < packs.size(); ++k) {
    const auto s = RelightSession::Open(packs[k]);
    const WaveletLighting lighting = ProjectLighting(ResampleToCubemap(image, s->cubemap_n()));
    const double exact = MedianMs(repeats, [&](int) { (void)s->RelightExact(lighting); });
    const double nwa = MedianMs(repeats, [&](int) {
      (void)RelightApproximate(s->transport(), lighting, LightingMode::kNwa, terms);
    });
    const SampleRadiance radiance = s->RelightExact(lighting);
    const Camera c = s->camera();
    const double camera = MedianMs(repeats, [&](int i) {
      const double a = (i + 1) * 10.0 * 3.14159265358979 / 180.0;
      const Vec3 d = c.eye - c.target;
      const Vec3 eye = c.target + Vec3{std::cos(a) * d.x + std::sin(a) * d.z, d.y,
                                       -std::sin(a) * d.x + std::cos(a) * d.z};
      (void)s->Shade(radiance, eye);
    });
    // A diffuse pack's colours for a still view: the albedo product alone.
    const double shade = MedianMs(repeats, [&](int) { (void)s->Shade(radiance, c.eye); });
    const double mb = static_cast<double>(std::filesystem::file_size(packs[k])) / 1e6;
    std::printf("%-10s %9zu %6zu %10.1f %11.2f %11.2f %11.2f %10.2f\n",
                k == 0 ? "glossy" : "diffuse", s->sample_count(), s->terms(), mb, exact, nwa,
                camera, shade);
    if (k == 1) {
      std::printf(
          "glossy / diffuse: size %.2fx, exact %.2fx, NWA-%zu %.2fx, camera move %.2fx of "
          "the diffuse frame's shade (%.2f ms vs %.2f ms)\n",
          base[0] / mb, base[1] / exact, terms, base[2] / nwa, base[3] / shade, base[3], shade);
    } else {
      base[0] = mb;
      base[1] = exact;
      base[2] = nwa;
      base[3] = camera;
    }
  }
  return 0;
}
