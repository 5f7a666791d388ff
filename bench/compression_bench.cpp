// compression_bench: storage against relit-radiance error for 2D (Ng et al. 2003), full 4D and
// adaptive 4D compression of a real transport matrix (Cheslack-Postava et al. 2008 §5.2, Fig. 7
// and Fig. 8), all through the same code (worker/transport_compressor.h).
//
// T comes from a farm run folder (run/transport.prtt + run/geometry.prtg) when one is given;
// otherwise it is traced here with TransportSampler: a mesh fitted to a unit box standing on a
// res×res ground grid (default ChineseDragon-10kv, 32×32 grid, n = 16, 2 rays per texel).
// For each scheme and budget it prints the stored terms, encoded bytes (and % of raw float32 T),
// the relative Frobenius error of T, and the relative RMS error of relit radiance B = T·L over
// the environment maps (each channel, all environments together), where B is computed from the
// compressed columns by Eq. 8 (relight_ms: one 3-channel Eq. 8 relighting with dense lighting,
// averaged over the environments) and the reference from the uncompressed T in double. It then
// prints the average chosen column depth per row-transform level (Fig. 8) for adaptive 4D.
//
// Usage: compression_bench [--run DIR] [--mesh FILE] [--n N] [--rays K] [--ground RES]
//                          [--bits B] [--keep f1,f2,...] [--budget column|global|both]
// Budget "column" is the paper's N terms per column (2D: per row, Ng et al. 2003); "global" keeps
// the largest f·samples·texels coefficients of the whole transformed matrix (not in the paper).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "vocabulary/compressed_relight.h"
#include "vocabulary/compressed_transport.h"
#include "vocabulary/envmap.h"
#include "vocabulary/mesh.h"
#include "vocabulary/scene.h"
#include "vocabulary/transport_file.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/row_transform.h"
#include "worker/transport_compressor.h"
#include "worker/transport_sampler.h"

#ifndef PRT_DATA_DIR
#define PRT_DATA_DIR "data"
#endif

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

struct Transport {
  std::vector<float> T;
  int n = 16;
  std::size_t S = 0;
  prt::SpatialDomain domain;
  std::string source;
};

Transport TraceTransport(const std::string& mesh_path, int n, int rays, int ground_res) {
  Transport t;
  t.n = n;
  prt::SceneGeometry geometry;
  prt::SceneMesh object;
  object.name = "object";
  object.mesh = prt::LoadMesh(mesh_path);
  prt::MeshInstance instance;
  instance.fit = prt::FitBox{};
  prt::TransformInstance(instance, object.mesh);
  geometry.meshes.push_back(std::move(object));
  prt::GroundPlane ground;
  ground.enabled = true;
  ground.resolution = ground_res;
  ground.size = 3.0;
  prt::SceneMesh g;
  g.name = "ground";
  g.mesh = prt::MakeGroundGrid(ground);
  g.is_ground = true;
  g.grid_resolution = ground_res;
  geometry.meshes.push_back(std::move(g));
  const prt::EmbreeScene scene(geometry);
  const prt::TransportSampler sampler(scene, n, {rays, 1});
  const std::vector<prt::SpatialSample> samples = prt::SpatialSamplesOf(geometry);
  t.S = samples.size();
  t.T.resize(t.S * sampler.layout().texel_count());
  const auto t0 = Clock::now();
  sampler.ComputeRows(samples, 0, t.T.data());
  t.domain = prt::SpatialDomainOf(geometry);
  std::ostringstream os;
  os << mesh_path << " + " << ground_res << "x" << ground_res << " ground, traced in "
     << Seconds(t0) << " s";
  t.source = os.str();
  return t;
}

Transport ReadRun(const std::string& dir) {
  Transport t;
  const prt::TransportFileReader reader(dir + "/" + prt::kTransportFileName);
  t.n = static_cast<int>(reader.info().cubemap_n);
  t.S = reader.info().rows;
  t.T.resize(t.S * reader.info().cols());
  reader.ReadRows(0, t.S, t.T.data());
  t.domain = prt::SpatialDomainOf(prt::ReadSceneGeometryFile(dir + "/" + prt::kGeometryFileName));
  t.source = dir;
  return t;
}

std::vector<double> Split(const std::string& s) {
  std::vector<double> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) v.push_back(std::atof(item.c_str()));
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  std::string run, mesh = std::string(PRT_DATA_DIR) + "/meshes/ChineseDragon-10kv.off";
  int n = 16, rays = 2, ground = 32, bits = 9;
  std::string budget = "both";  // column | global | both
  std::vector<double> keeps = {0.0025, 0.005, 0.01, 0.02, 0.05};
  std::string keep_arg;
  CLI::App app{"compression_bench: storage against relit error for 2D, 4D and adaptive 4D"};
  app.add_option("--run", run, "farm run folder to read T from (instead of tracing)");
  app.add_option("--mesh", mesh, "mesh to trace on a ground plane");
  app.add_option("--n", n, "cubemap resolution");
  app.add_option("--rays", rays, "rays per texel");
  app.add_option("--ground", ground, "ground grid resolution");
  app.add_option("--bits", bits, "quantisation bits");
  app.add_option("--budget", budget, "column | global | both");
  app.add_option("--keep", keep_arg, "comma-separated keep fractions");
  CLI11_PARSE(app, argc, argv);
  if (!keep_arg.empty()) keeps = Split(keep_arg);
  Transport tr;
  try {
    tr = run.empty() ? TraceTransport(mesh, n, rays, ground) : ReadRun(run);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "compression_bench: %s\n", e.what());
    return 1;
  }
  n = tr.n;
  const std::size_t S = tr.S, M = static_cast<std::size_t>(6) * n * n;
  std::printf("transport: %s\n  %zu samples x %zu texels (n = %d), %zu segments, raw %.1f MB\n",
              tr.source.c_str(), S, M, n, tr.domain.segments.size(),
              static_cast<double>(S * M) * 4.0 / 1e6);

  // Lighting: the real environment maps resampled to the cubemap.
  std::vector<std::vector<float>> lights;
  std::vector<std::string> names;
  for (const char* e : {"sunrise", "city", "studio", "interior"}) {
    const std::string path = std::string(PRT_DATA_DIR) + "/envmaps/" + e + ".exr";
    if (!std::filesystem::exists(path)) continue;
    const prt::CubemapRgb cube = prt::ResampleToCubemap(prt::ReadEnvironment(path), n);
    std::vector<float> L;
    for (int c = 0; c < 3; ++c) L.insert(L.end(), cube.Channel(c).begin(), cube.Channel(c).end());
    lights.push_back(std::move(L));
    names.push_back(e);
  }
  if (lights.empty()) {
    std::fprintf(stderr, "compression_bench: no environment maps in %s/envmaps\n", PRT_DATA_DIR);
    return 1;
  }
  std::printf("environments:");
  for (const auto& s : names) std::printf(" %s", s.c_str());
  std::printf("\n");
  // Reference radiance from the uncompressed T, in double.
  std::vector<std::vector<double>> ref(lights.size(), std::vector<double>(3 * S));
  double ref_energy = 0;
  for (std::size_t e = 0; e < lights.size(); ++e)
    for (int c = 0; c < 3; ++c)
      for (std::size_t s = 0; s < S; ++s) {
        double a = 0;
        const float* row = tr.T.data() + s * M;
        const float* L = lights[e].data() + c * M;
        for (std::size_t j = 0; j < M; ++j) a += static_cast<double>(row[j]) * L[j];
        ref[e][c * S + s] = a;
        ref_energy += a * a;
      }
  double t_energy = 0;
  for (float v : tr.T) t_energy += static_cast<double>(v) * v;

  const std::vector<uint8_t> row_levels = prt::RowCoefficientLevels(n);
  const int row_depth = prt::RowTransformDepth(n);
  std::printf("\n%-11s %-7s %7s %10s %10s %7s %10s %10s %8s %10s\n", "scheme", "budget", "keep",
              "terms", "bytes", "%raw", "T_relF", "B_relRMS", "time_s", "relight_ms");
  std::vector<std::string> depth_lines;
  std::vector<bool> modes;
  if (budget != "global") modes.push_back(false);
  if (budget != "column") modes.push_back(true);
  for (bool global : modes)
    for (prt::CompressionScheme scheme : {prt::CompressionScheme::k2D, prt::CompressionScheme::k4D,
                                          prt::CompressionScheme::kAdaptive4D}) {
      for (double keep : keeps) {
        prt::CompressionOptions o;
        o.scheme = scheme;
        o.keep_fraction = keep;
        o.bits = bits;
        o.global_budget = global;
        std::vector<prt::ColumnStats> stats;
        const auto t0 = Clock::now();
        const prt::CompressedTransport ct =
            prt::CompressTransport(tr.T.data(), n, tr.domain, o, &stats);
        const double secs = Seconds(t0);
        const std::size_t bytes = prt::EncodeCompressedTransport(ct).size();
        // Relit error by Eq. 8 from the compressed columns.
        const prt::CompressedRelighter relighter(ct);
        double err = 0, relight_s = 0;
        std::vector<float> B(3 * S);
        for (std::size_t e = 0; e < lights.size(); ++e) {
          const std::vector<float> Lhat =
              prt::LightingToRowWaveletBasis(o.row_wavelet, n, lights[e], 3);
          const auto r0 = Clock::now();
          relighter.Relight(Lhat, 3, B);
          relight_s += Seconds(r0);
          for (std::size_t i = 0; i < 3 * S; ++i) {
            const double d = B[i] - ref[e][i];
            err += d * d;
          }
        }
        const std::vector<float> back = prt::DecompressTransport(ct);
        double terr = 0;
        for (std::size_t i = 0; i < back.size(); ++i) {
          const double d = static_cast<double>(back[i]) - tr.T[i];
          terr += d * d;
        }
        std::printf("%-11s %-7s %7.4f %10zu %10zu %7.3f %10.5f %10.5f %8.2f %10.2f\n",
                    prt::ToString(scheme),
                    global ? "global" : (scheme == prt::CompressionScheme::k2D ? "row" : "column"),
                    keep, ct.term_count(), bytes,
                    100.0 * static_cast<double>(bytes) / (static_cast<double>(S * M) * 4.0),
                    std::sqrt(terr / t_energy), std::sqrt(err / ref_energy), secs,
                    1e3 * relight_s / static_cast<double>(lights.size()));
        std::fflush(stdout);
        if (scheme == prt::CompressionScheme::kAdaptive4D) {
          std::vector<double> sum(row_depth + 1, 0.0), cnt(row_depth + 1, 0.0);
          for (const auto& st : stats) {
            sum[row_levels[st.column]] += st.depth;
            cnt[row_levels[st.column]] += 1;
          }
          std::ostringstream os;
          os << (global ? "global" : "column") << " keep " << keep << ":";
          for (int l = 0; l <= row_depth; ++l) {
            char buf[32];
            std::snprintf(buf, sizeof buf, " %6.2f", cnt[l] > 0 ? sum[l] / cnt[l] : 0.0);
            os << buf;
          }
          depth_lines.push_back(os.str());
        }
      }
    }
  std::printf(
      "\naverage adaptive column depth by row-transform level (0 = scaling … %d = finest;"
      " max depth %d):\n",
      row_depth, prt::MaxColumnDepth(tr.domain));
  for (const auto& l : depth_lines) std::printf("  %s\n", l.c_str());
  return 0;
}
