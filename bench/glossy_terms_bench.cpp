// glossy_terms_bench: how far the BRDF in-out factorisation of glossy vertex transport
// (docs/glossy-transport.md; Huang & Ramamoorthi 2010 Eq. 2–3) is from the exact BRDF on the same
// visibility, against the number of terms m and the GGX roughness r. On the bunny of
// scenes/bench/bunny-ggx-vertex-k0.toml (its geometry, camera and material weights), for
// vertices facing the camera drawn at random, under real environment maps (lighting cubemaps
// at n = 32):
//   exact  B(x) = Σ_j T_ω_o(x)[j]·L[j],   T_ω_o the image runs' glossy row for the camera's view
//                 (V·ρ̃(ω, ω_o) with the sampler's own rays, worker/glossy_pixels.h)
//   terms  B_m(x) = Σ_{i<m} g_i(ω_o)·Σ_j T_i(x)[j]·L[j],   T_i = V·f_i with the SAME rays (seed)
// so the difference is the factorisation's alone (no Monte-Carlo difference: both rows use the
// same jittered directions). Prints relative RMS over the vertices and colour channels per
// (r, m, environment) and the factorisation's own error, writes a CSV and (gnuplot) a PNG plot.
//
// With --run RUN_DIR and --pack PACK of the same scene (scenes/bench/bunny-ggx-vertex-k0.toml,
// its roughness and terms), it also splits the pipeline's error at the same vertices and view:
// the farm's term rows (transport.prtt: the sparse method's or brute force's rows) combined for
// the view, and the pack's relit radiance (after compression, RelightSession::CombineTerms),
// each against the exact row (its own rays: the Monte-Carlo noise of 4 rays per texel is in it).
//
// Usage: glossy_terms_bench [--vertices 256] [--env sunrise] [--env city] [--out DIR]
//        [--run RUN --pack PACK]
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "formats/transport_file.h"
#include "runtime/lighting.h"
#include "runtime/relight_session.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/hash.h"
#include "vocabulary/parallel.h"
#include "vocabulary/scene.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/brdf_factorisation.h"
#include "worker/embree_scene.h"
#include "worker/transport_sampler.h"

#ifndef PRT_DATA_DIR
#define PRT_DATA_DIR "data"
#endif
#ifndef PRT_SOURCE_DIR
#define PRT_SOURCE_DIR "."
#endif

namespace {

// The pipeline's error split at the picked vertices (see the header).
int SplitPipelineError(const std::string& run, const std::string& pack,
                       const prt::SceneDescription& scene, const prt::SceneGeometry& geometry,
                       const prt::EmbreeScene& embree,
                       const std::vector<prt::SpatialSample>& picked,
                       const std::vector<uint32_t>& index,
                       const std::vector<prt::CubemapRgb>& lights,
                       const std::vector<std::string>& envs) {
  using namespace prt;
  const GlossyFactorTable table =
      ParseGlossyFactors(ReadWholeFile(run + "/glossy.prtf"), run + "/glossy.prtf");
  const BrdfFactors& factors = table.factors.at(table.mesh_factor.at(0));
  const GlossyPixels glossy = ResolveGlossyMaterials(scene, geometry);
  const Material& m = glossy.materials.at(0);
  const Vec3 eye = scene.camera.eye;
  const TransportFileReader rows(run + "/transport.prtt");
  const std::size_t V = geometry.vertex_count(), texels = rows.info().cols();
  const int n = static_cast<int>(rows.info().cubemap_n);
  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  so.seed = 7;
  const TransportSampler exact(embree, n, so, GlossySampling{{m}, eye});
  const auto session = RelightSession::Open(pack);
  std::printf("%-10s %14s %14s   (relative RMS vs the exact BRDF row, %zu vertices)\n", "env",
              "farm rows", "pack", index.size());
  for (std::size_t e = 0; e < lights.size(); ++e) {
    const SampleRadiance packed = session->RelightExact(ProjectLighting(lights[e]));
    const std::vector<float> shaded = session->ToPackOrder(session->Shade(packed, eye));
    double n_rows = 0, n_pack = 0, den = 0;
    std::vector<float> row(texels);
    for (std::size_t k = 0; k < index.size(); ++k) {
      const uint32_t v = index[k];
      SpatialSample s = picked[k];
      s.glossy_material = 0;
      exact.ComputeRow(s, 5000 + k, row.data());
      double ref[3] = {0, 0, 0}, b[3] = {0, 0, 0};
      for (int c = 0; c < 3; ++c)
        for (std::size_t j = 0; j < texels; ++j) ref[c] += double(row[j]) * lights[e].Channel(c)[j];
      float g[16];
      factors.GAll(MakeFactorFrame(s.normal).ToLocal(eye - s.position), g);
      for (int t = 0; t < table.terms; ++t) {
        rows.ReadRows(uint64_t(t) * V + v, 1, row.data());
        for (int c = 0; c < 3; ++c) {
          double x = 0;
          for (std::size_t j = 0; j < texels; ++j) x += double(row[j]) * lights[e].Channel(c)[j];
          b[c] += g[t] * x;
        }
      }
      for (int c = 0; c < 3; ++c) {
        const double w = table.mesh_weight[0][c];
        const double p = shaded[3 * v + c] / w;
        n_rows += (b[c] - ref[c]) * (b[c] - ref[c]);
        n_pack += (p - ref[c]) * (p - ref[c]);
        den += ref[c] * ref[c];
      }
    }
    std::printf("%-10s %13.2f%% %13.2f%%\n", envs[e].c_str(), 100 * std::sqrt(n_rows / den),
                100 * std::sqrt(n_pack / den));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace prt;
  CLI::App app{"glossy_terms_bench: factorised glossy transport against the exact BRDF"};
  int vertices = 256;
  std::vector<std::string> envs{"sunrise", "city"};
  std::string out = "bench-out/glossy-terms";
  app.add_option("--vertices", vertices, "random camera-facing bunny vertices");
  app.add_option("--env", envs, "environment names in data/envmaps");
  app.add_option("--out", out, "folder for table.csv and terms.png");
  std::string run, pack;
  app.add_option("--run", run, "a farm run of the scene: split the pipeline's error");
  app.add_option("--pack", pack, "that run's pack");
  CLI11_PARSE(app, argc, argv);
  UseTbbParallelism();
  // With --run: that run's own scene (its roughness and terms).
  const std::string scene_file =
      run.empty() ? std::string(PRT_SOURCE_DIR) + "/scenes/bench/bunny-ggx-vertex-k0.toml"
                  : run + "/scene.toml";
  const SceneDescription scene = LoadSceneFile(scene_file, {PRT_DATA_DIR});
  const SceneGeometry geometry = BuildSceneGeometry(scene);
  const EmbreeScene embree(geometry);
  const std::vector<SpatialSample> all = SpatialSamplesOf(geometry);
  const Vec3 eye = scene.camera.eye;
  const int n = 32;
  // Camera-facing bunny vertices (mesh 0), drawn by a fixed seed.
  std::vector<SpatialSample> picked;
  std::vector<uint32_t> picked_index;  // their vertex indices (mesh 0 comes first)
  const std::size_t bunny = geometry.meshes[0].mesh.positions.size();
  for (uint64_t k = 0; picked.size() < static_cast<std::size_t>(vertices) && k < 100 * bunny; ++k) {
    const uint64_t v = SplitMix64(k + 17) % bunny;
    const SpatialSample& s = all[v];
    if (Dot(s.normal, eye - s.position) > 0.1 * Length(eye - s.position)) {
      picked.push_back(s);
      picked_index.push_back(static_cast<uint32_t>(v));
    }
  }
  std::vector<CubemapRgb> lights;
  for (const std::string& e : envs)
    lights.push_back(ResampleToCubemap(
        ReadEnvironment(std::string(PRT_DATA_DIR) + "/envmaps/" + e + ".exr"), n));
  std::filesystem::create_directories(out);
  if (!run.empty())
    return SplitPipelineError(run, pack, scene, geometry, embree, picked, picked_index, lights,
                              envs);
  std::ofstream csv(out + "/table.csv");
  csv << "roughness,terms,environment,relative_rms,factorisation_error\n";
  std::printf("%-6s %-5s %-10s %10s %12s\n", "r", "m", "env", "rel RMS", "factor err");
  const int kMaxTerms = 16;
  TransportSamplerOptions so;
  so.rays_per_texel = 4;
  so.seed = 1;
  const std::size_t texels = 6ull * n * n;
  for (double r : {0.2, 0.35, 0.5, 0.8}) {
    Material m;
    m.model = BrdfModel::kGgx;
    m.roughness = r;
    m.diffuse = {0.375f, 0.375f, 0.375f};  // albedo 0.3, specular 0.5 as the scene
    m.specular = {0.625f, 0.625f, 0.625f};
    FactorisationOptions fo;
    fo.terms = kMaxTerms;
    auto table = std::make_shared<GlossyFactorTable>();
    table->terms = kMaxTerms;
    table->mesh_factor = {0};
    table->mesh_weight = {Rgb{1, 1, 1}};
    std::vector<double> trunc;  // the SVD's truncation error, m = 1…16
    table->factors.push_back(FactorBrdf(m, fo, &trunc));
    // The first t of the 16 terms are the t-term factorisation (one SVD serves every t).
    std::vector<double> factor_error(kMaxTerms + 1, 0);
    for (int t : {1, 2, 4, 8, 16}) factor_error[t] = LookupError(m, table->factors[0], t, fo);
    std::printf("r = %.2f truncation error (SVD grid) m = 1/2/4/8/16: %.1f/%.1f/%.1f/%.1f/%.1f%%\n",
                r, 100 * trunc[0], 100 * trunc[1], 100 * trunc[3], 100 * trunc[7], 100 * trunc[15]);
    const TransportSampler exact(embree, n, so, GlossySampling{{m}, eye});
    const TransportSampler terms(embree, n, so, GlossySampling{{}, {}, table});
    // Per vertex: exact B and the 8 term radiances, per environment and channel.
    const std::size_t nv = picked.size(), ne = lights.size();
    std::vector<double> b_exact(nv * ne * 3), b_term(nv * ne * 3 * kMaxTerms);
    std::vector<float> g_all(nv * kMaxTerms);
    ParallelFor(nv, [&](std::size_t v) {
      std::vector<float> row(texels);
      SpatialSample s = picked[v];
      s.glossy_material = 0;
      auto relight = [&](double* dst) {
        for (std::size_t e = 0; e < ne; ++e)
          for (int c = 0; c < 3; ++c) {
            const std::vector<float>& l = lights[e].Channel(c);
            double b = 0;
            for (std::size_t j = 0; j < texels; ++j) b += double(row[j]) * l[j];
            dst[e * 3 + c] = b;
          }
      };
      const uint64_t index = 1000 + v;  // same rays for every row of this vertex
      exact.ComputeRow(s, index, row.data());
      std::vector<double> tmp(ne * 3);
      relight(tmp.data());
      for (std::size_t k = 0; k < ne * 3; ++k) b_exact[v * ne * 3 + k] = tmp[k];
      for (int t = 0; t < kMaxTerms; ++t) {
        s.term = static_cast<uint8_t>(t);
        terms.ComputeRow(s, index, row.data());
        relight(tmp.data());
        for (std::size_t k = 0; k < ne * 3; ++k) b_term[(v * kMaxTerms + t) * ne * 3 + k] = tmp[k];
      }
      table->factors[0].GAll(MakeFactorFrame(s.normal).ToLocal(eye - s.position),
                             g_all.data() + v * kMaxTerms);
    });
    for (int mt : {1, 2, 4, 8, 16})
      for (std::size_t e = 0; e < ne; ++e) {
        double num = 0, den = 0;
        for (std::size_t v = 0; v < nv; ++v)
          for (int c = 0; c < 3; ++c) {
            double b = 0;
            for (int t = 0; t < mt; ++t)
              b += g_all[v * kMaxTerms + t] * b_term[(v * kMaxTerms + t) * ne * 3 + e * 3 + c];
            const double ref = b_exact[v * ne * 3 + e * 3 + c];
            num += (b - ref) * (b - ref);
            den += ref * ref;
          }
        const double rel = std::sqrt(num / den);
        std::printf("%-6.2f %-5d %-10s %9.2f%% %11.1f%%\n", r, mt, envs[e].c_str(), 100 * rel,
                    100 * factor_error[mt]);
        csv << r << "," << mt << "," << envs[e] << "," << rel << "," << factor_error[mt] << "\n";
      }
  }
  csv.close();
  std::printf(
      "vertices %zu (camera-facing bunny vertices), n = %d, %d rays per texel; %s/table.csv\n",
      picked.size(), n, so.rays_per_texel, out.c_str());
  // The plot: relit error against m, one line per (r, environment), from series.dat (one block
  // per line, as gnuplot's `index` reads them).
  {
    std::ifstream in(out + "/table.csv");
    std::string line;
    std::getline(in, line);
    std::vector<std::vector<std::string>> rowsv;
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::size_t a0 = 0, b0;
      while ((b0 = line.find(',', a0)) != std::string::npos) {
        f.push_back(line.substr(a0, b0 - a0));
        a0 = b0 + 1;
      }
      f.push_back(line.substr(a0));
      rowsv.push_back(f);
    }
    std::ofstream series(out + "/series.dat");
    std::ofstream g(out + "/terms.gp");
    g << "set terminal pngcairo size 800,500\nset output '" << out << "/terms.png'\n"
      << "set logscale y\nset logscale x 2\nset xrange [0.8:20]\nset xlabel 'BRDF terms m'\n"
      << "set ylabel 'relit error vs exact BRDF (relative RMS)'\nset key outside right\n"
      << "set xtics (1,2,4,8,16)\nset grid\nplot ";
    int block = 0;
    for (double r : {0.2, 0.35, 0.5, 0.8})
      for (const std::string& e : envs) {
        char key[32];
        std::snprintf(key, sizeof key, "%g", r);
        for (const auto& f : rowsv)
          if (std::abs(std::stod(f[0]) - r) < 1e-9 && f[2] == e)
            series << f[1] << " " << f[3] << "\n";
        series << "\n\n";
        g << (block ? ", " : "") << "'" << out << "/series.dat' index " << block
          << " with linespoints title 'r = " << key << ", " << e << "'";
        ++block;
      }
    g << "\n";
  }
  const std::string gp = out + "/terms.gp";
  if (std::system(("gnuplot " + gp + " 2>/dev/null").c_str()) == 0)
    std::printf("plot: %s/terms.png\n", out.c_str());
  return 0;
}
