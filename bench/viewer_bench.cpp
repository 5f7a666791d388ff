// The viewer's benchmark (docs/viewer.md, "Benchmark"): what relighting a pack costs and how
// good the lighting approximations are, every figure measured in this run on this machine.
//
//   1. Relighting frames per second for N = 30, 100, 300 NWA terms: the B = T·L step alone
//      (Eq. 8 from the compressed columns) and the whole frame (relight, shade, rasterise), and
//      the ratio of the measured time to the memory-bandwidth bound (bytes of T the N columns
//      hold / copy bandwidth measured with a memcpy loop in the same run).
//   2. Cheslack-Postava et al. 2008 Figure 9: relighting time of 2D (per-row) against adaptive
//      4D compression at equal image error (error against the uncompressed T under the same
//      lighting terms), over a sweep of budgets.
//   3. Overbeck et al. 2006 §6 / Figure 7: sunrise and city rotating about +Y for 120 frames,
//      then still: mean image error of PBI-30 against NWA-90, and the frames PBI needs after the
//      rotation stops to reach the exact-lighting image (relative RMS < 1e-3).
//   4. One frame side by side: exact | NWA | PBI (PNG in --out-dir).
//
// Usage: viewer_bench [scene.prtpack] [--n 16] [--rays 1] [--keep F] [--scheme S] [--deg 0.5]
// [--frames 120]
//                     [--hold 60] [--out-dir viewer_bench_out] [--quick]
// Without a pack, the default scene (bunny on a 64×64 ground, 41,802 samples) is traced here at
// reduced cost (cubemap n = 16, 1 ray per texel), compressed like scenes/default.toml
// (adaptive 4D, keep 5%, 9 bits) and packed to --out-dir, so that everything below reads the
// same pack prt-view would.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_scenes.h"
#include "formats/geometry_file.h"
#include "formats/image_file.h"
#include "formats/run_folder.h"
#include "formats/transport_file.h"
#include "packager/prtpack_transport.h"
#include "packager/prtpack_writer.h"
#include "runtime/compressed_relight.h"
#include "runtime/lighting.h"
#include "runtime/per_band_incremental.h"
#include "viewer/rotation_plot.h"
#include "viewer/viewer_session.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/errors.h"
#include "vocabulary/tbb_parallel.h"
#include "worker/column_order.h"
#include "worker/embree_scene.h"
#include "worker/transport_compressor.h"
#include "worker/transport_sampler.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

double Seconds(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Fastest of `reps` runs of f (after one warm-up run): on a shared, loaded machine the minimum
// is the least disturbed estimate of the work itself.
// CPU seconds of the whole process (all threads): unlike wall time, not inflated by waiting for
// a core when other work shares the machine.
double ProcessCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Timing {
  double wall = 0;  // fastest wall time of the runs
  double cpu = 0;   // least CPU time (all threads) of the runs
};

template <typename F>
Timing BestTiming(int reps, F&& f) {
  f();
  Timing best{1e300, 1e300};
  for (int r = 0; r < reps; ++r) {
    const double c0 = ProcessCpuSeconds();
    const auto t0 = Clock::now();
    f();
    best.wall = std::min(best.wall, Seconds(t0));
    best.cpu = std::min(best.cpu, ProcessCpuSeconds() - c0);
  }
  return best;
}

template <typename F>
double BestSeconds(int reps, F&& f) {
  return BestTiming(reps, std::forward<F>(f)).wall;
}

// Copy bandwidth (bytes read + bytes written per second) of memcpy over 256 MiB buffers.
// Single-threaded; the least CPU time of 5 copies, which a loaded machine does not inflate.
double MeasureBandwidth() {
  const std::size_t bytes = std::size_t{256} << 20;
  std::vector<char> a(bytes, 1), b(bytes, 2);
  const Timing t = BestTiming(5, [&] {
    std::memcpy(b.data(), a.data(), bytes);
    a[bytes / 2] = b[bytes / 3];
  });
  return 2.0 * static_cast<double>(bytes) / std::min(t.wall, t.cpu);
}

struct Traced {
  prt::SceneDescription scene;
  prt::SceneGeometry geometry;
  std::vector<float> rows;
  double trace_s = 0;
  // An image run's pixels (docs/image-relighting.md): then the rows are pixels, the column
  // transform's domain is the image and each pixel has its mesh's albedo.
  std::optional<prt::ImageSamplesInfo> image;
  std::size_t samples() const { return image ? image->pixels() : geometry.vertex_count(); }
  prt::SpatialDomain Domain() const {
    return image ? prt::ImageDomain(static_cast<uint32_t>(image->camera.width),
                                    static_cast<uint32_t>(image->camera.height))
                 : prt::SpatialDomainOf(geometry, scene.compression.order_normal_weight);
  }
  // albedo ⊙ (rows · light) per sample, interleaved RGB, in the rows' order.
  std::vector<float> Relit(const prt::CubemapRgb& light) const {
    if (!image) return prt::bench::RelitRadiance(geometry, rows, light);
    std::vector<prt::Rgb> mesh_albedo;
    for (const prt::SceneMesh& m : geometry.meshes) mesh_albedo.push_back(m.albedo);
    return prt::bench::RelitRadiance(prt::PixelAlbedo(*image, mesh_albedo), rows, light);
  }
};

Traced TraceDefaultScene(int n, int rays) {
  Traced t;
  t.scene = prt::bench::BenchScene("default", n);
  t.geometry = prt::BuildSceneGeometry(t.scene);
  const prt::EmbreeScene embree(t.geometry);
  const prt::TransportSampler sampler(embree, n, {rays, 1});
  const std::vector<prt::SpatialSample> samples = prt::SpatialSamplesOf(t.geometry);
  t.rows.resize(samples.size() * sampler.layout().texel_count());
  const auto t0 = Clock::now();
  sampler.ComputeRows(samples, 0, t.rows.data());
  t.trace_s = Seconds(t0);
  return t;
}

// The default scene's rows as a farm run wrote them (`prt-farm --keep-raw`: RUN/transport.prtt),
// so that table 2 measures the transport prtfarm actually ships (its sampling method and rays per
// texel) instead of the in-process trace. An image run's (RUN/image.prti next to it): its pixels,
// geometry and camera, compressed with the default scene's [compression] settings.
Traced ReadDefaultSceneRaw(const std::string& path) {
  Traced t;
  const prt::TransportFileReader reader(path);
  const prt::TransportFileInfo& info = reader.info();
  t.scene = prt::bench::BenchScene("default", static_cast<int>(info.cubemap_n));
  const fs::path run = fs::path(path).parent_path();
  if (fs::exists(run / prt::kImageFileName)) {
    t.geometry = prt::ReadSceneGeometryFile((run / prt::kGeometryFileName).string());
    t.image = prt::ReadImageSamplesFile((run / prt::kImageFileName).string(),
                                        static_cast<uint32_t>(t.geometry.meshes.size()));
    t.scene.name = "image";
    t.scene.camera = t.image->camera;
  } else {
    t.geometry = prt::BuildSceneGeometry(t.scene);
  }
  if (info.rows != t.samples())
    throw prt::InputError(path, "holds " + std::to_string(info.rows) + " rows, the scene has " +
                                    std::to_string(t.samples()) + " samples");
  t.rows.resize(info.rows * info.cols());
  const auto t0 = Clock::now();
  reader.ReadRows(0, info.rows, t.rows.data());
  t.trace_s = Seconds(t0);
  return t;
}

std::string CameraJson(const prt::Camera& c) {
  char buf[512];
  std::snprintf(
      buf, sizeof buf,
      R"({"eye": [%.9g, %.9g, %.9g], "target": [%.9g, %.9g, %.9g], "up": [%.9g, %.9g, %.9g], "fov": %.9g, "width": %d, "height": %d})",
      c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z, c.up.x, c.up.y, c.up.z,
      c.fov_deg, c.width, c.height);
  return buf;
}

void WritePackOf(const Traced& t, const prt::CompressedTransport& ct, const std::string& path) {
  prt::pack::PackInput in;
  in.metadata_json = R"({"scene": {"scene": {"name": ")" + t.scene.name + R"("}, "camera": )" +
                     CameraJson(t.scene.camera) + "}}";
  in.meshes = prt::pack::PackMeshesOf(t.geometry);
  in.image = t.image;
  in.transport = prt::pack::MakeTransportInput(ct, 256);
  prt::pack::WriterOptions wo;
  wo.zstd_level = 3;
  prt::pack::WritePackFile(path, in, wo);
}

// Stored bytes of T's columns (index + value, 8 bytes per stored term, as CompressedRelighter
// holds them) for each column.
std::vector<std::size_t> ColumnBytes(const prt::CompressedTransport& ct) {
  std::vector<std::size_t> b(ct.header.column_count(), 0);
  for (const prt::CompressedColumn& c : ct.columns) b[c.column] = 8 * c.q.size();
  return b;
}

// Images of equal height next to each other, left to right.
prt::ImageRgb Row(const std::vector<const prt::ImageRgb*>& images) {
  int w = 0;
  for (const prt::ImageRgb* i : images) w += i->width;
  prt::ImageRgb out(w, images[0]->height);
  int x0 = 0;
  for (const prt::ImageRgb* i : images) {
    for (int y = 0; y < i->height; ++y)
      std::memcpy(out.At(x0, y), i->At(0, y),
                  3 * sizeof(float) * static_cast<std::size_t>(i->width));
    x0 += i->width;
  }
  return out;
}

std::vector<float> ShadeWith(const prt::ViewerSession& s, const prt::SampleRadiance& r) {
  return s.Shade(r);
}

int Run(int argc, char** argv) {
  std::string pack_path, out_dir = "viewer_bench_out";
  int n = 16, rays = 1, frames = 120, hold = 60;
  double deg = 0.5, pack_keep = 0.0;
  std::string pack_scheme, raw_path, truth_path;
  std::vector<double> sweep_2d, sweep_4d;
  // Overrides of the scene's [compression] settings, for the pack and for table 2's sweep (both
  // schemes alike), so that each can be measured against the Figure 9 comparison.
  prt::CompressionSettings overrides;
  bool quick = false;
  CLI::App app{"viewer_bench: relighting speed, 2D against 4D, PBI against NWA"};
  app.add_option("pack", pack_path, "a .prtpack (default: trace the default scene in-process)");
  app.add_option("--n", n, "cubemap resolution of the in-process pack");
  app.add_option("--rays", rays, "rays per texel of the in-process pack");
  app.add_option("--keep", pack_keep,
                 "kept fraction of the in-process pack's terms (default: the scene's)");
  app.add_option("--scheme", pack_scheme,
                 "compression scheme of the in-process pack, 2d | 4d | adaptive4d (default: the "
                 "scene's)");
  app.add_option("--raw", raw_path,
                 "the default scene's raw transport from a farm run (prt-farm --keep-raw: "
                 "RUN/transport.prtt) instead of the in-process trace");
  app.add_option("--truth", truth_path,
                 "an independent estimate of the same T (e.g. prt-farm --method brute with many "
                 "rays per texel, --keep-raw): table 2 then also gives every error against it");
  app.add_option("--sweep-2d", sweep_2d, "table 2's kept fractions for 2D (comma-separated)")
      ->delimiter(',');
  app.add_option("--sweep-4d", sweep_4d,
                 "table 2's kept fractions for adaptive 4D (comma-separated)")
      ->delimiter(',');
  app.add_option("--bits", overrides.bits, "quantisation bits (default: the scene's)");
  app.add_option("--column-wavelet", overrides.column_wavelet,
                 "column wavelet, legall53 | cdf97 (default: the scene's)");
  app.add_option("--budget", overrides.budget, "global | column (default: the scene's)");
  app.add_option("--light-weight", overrides.light_weight,
                 "global budget's row-level weight (default: the scene's)");
  app.add_option("--order-normal-weight", overrides.order_normal_weight,
                 "mesh column order's normal weight (default: the scene's)");
  app.add_option("--deg", deg, "rotation per frame, degrees");
  app.add_option("--frames", frames, "rotating frames");
  app.add_option("--hold", hold, "still frames");
  app.add_option("--out-dir", out_dir, "output folder");
  app.add_flag("--quick", quick, "fewer timing repetitions");
  CLI11_PARSE(app, argc, argv);
  fs::create_directories(out_dir);
  std::printf("# viewer_bench (prtfarm viewer), %u hardware threads\n",
              std::thread::hardware_concurrency());

  // ---- The pack ----
  Traced traced;
  const bool own_pack = pack_path.empty();
  if (own_pack) {
    traced = raw_path.empty() ? TraceDefaultScene(n, rays) : ReadDefaultSceneRaw(raw_path);
    if (!raw_path.empty()) n = traced.scene.cubemap_n;
    {
      prt::CompressionSettings& s = traced.scene.compression;
      if (app.count("--bits")) s.bits = overrides.bits;
      if (app.count("--column-wavelet")) s.column_wavelet = overrides.column_wavelet;
      if (app.count("--budget")) s.budget = overrides.budget;
      if (app.count("--light-weight")) s.light_weight = overrides.light_weight;
      if (app.count("--order-normal-weight")) s.order_normal_weight = overrides.order_normal_weight;
    }
    if (raw_path.empty())
      std::printf("default scene traced in-process: %zu samples, n = %d, %d ray(s)/texel, %.1f s\n",
                  traced.samples(), n, rays, traced.trace_s);
    else
      std::printf("%s's rows read from %s: %zu samples, n = %d, %.1f s\n",
                  traced.image ? "an image run" : "the default scene", raw_path.c_str(),
                  traced.samples(), n, traced.trace_s);
    prt::CompressionOptions o = prt::CompressionOptionsFrom(traced.scene.compression, "default");
    if (pack_keep > 0) o.keep_fraction = pack_keep;
    if (!pack_scheme.empty()) o.scheme = prt::ParseCompressionScheme(pack_scheme, "--scheme");
    const auto t0 = Clock::now();
    const prt::CompressedTransport ct =
        prt::CompressTransport(traced.rows.data(), n, traced.Domain(), o);
    pack_path =
        (fs::path(out_dir) / (traced.image ? "image.prtpack" : "default_scene.prtpack")).string();
    WritePackOf(traced, ct, pack_path);
    std::printf("compressed (%s, keep %.3g, %d bits) and packed in %.1f s: %s\n",
                prt::ToString(o.scheme), o.keep_fraction, o.bits, Seconds(t0), pack_path.c_str());
  }
  const auto session = prt::ViewerSession::Open(pack_path);
  n = session->cubemap_n();
  const std::size_t ns = session->sample_count();
  std::printf("pack %s: %zu samples, n = %d (%zu coefficients), %zu stored terms (%.1f MB of T)\n",
              pack_path.c_str(), ns, n, session->relighter().column_count(),
              session->transport_terms(), 8e-6 * static_cast<double>(session->transport_terms()));

  const auto envs = prt::bench::BenchEnvironments(n, {"sunrise", "city"});
  const prt::WaveletLighting sunrise = prt::ProjectLighting(envs[0].cube);
  const prt::HaarLightingBasis basis(n);

  // ---- 1. Frames per second and the bandwidth bound ----
  const double bandwidth = MeasureBandwidth();
  std::printf("\n## 1. Relighting speed (sunrise, NWA terms; copy bandwidth %.2f GB/s)\n",
              1e-9 * bandwidth);
  {
    const prt::pack::PackReader reader = prt::pack::PackReader::OpenFile(pack_path);
    const prt::CompressedTransport ct = prt::pack::ReadCompressedTransport(reader);
    const std::vector<std::size_t> col_bytes = ColumnBytes(ct);
    const prt::Camera cam = session->camera();
    // The rasteriser's share of a frame (the same for every N).
    const std::vector<float> rgb0 = ShadeWith(
        *session,
        session->transport().Apply(prt::NonlinearLightingApproximation(sunrise, basis, 30)));
    const Timing raster =
        BestTiming(quick ? 3 : 9, [&] { (void)session->Render(cam, rgb0, &envs[0].cube); });
    std::printf(
        "rasterising %zu triangles at %dx%d over the environment: %.2f ms wall, %.2f ms CPU\n",
        session->triangles().size(), cam.width, cam.height, 1e3 * raster.wall, 1e3 * raster.cpu);
    std::printf(
        "| N | T·L ms | T·L CPU ms | T·L fps | frame ms (%dx%d) | frame fps | T bytes/frame | "
        "bound ms | T·L / bound | T·L CPU / bound |\n|---|---|---|---|---|---|---|---|---|---|\n",
        cam.width, cam.height);
    for (std::size_t terms :
         {std::size_t{1}, std::size_t{30}, std::size_t{100}, std::size_t{300}}) {
      const std::vector<prt::LightingTerm> l =
          prt::NonlinearLightingApproximation(sunrise, basis, terms);
      std::size_t bytes = 0;
      for (const prt::LightingTerm& t : l) bytes += col_bytes[t.index];
      const int reps = quick ? 5 : 21;
      // B = T·L into the frame's radiance buffer, kept from frame to frame as a viewer's frame
      // loop keeps it (TransportOperator::Assign overwrites it: no clearing pass).
      prt::SampleRadiance b;
      const Timing relight = BestTiming(reps, [&] { session->transport().Assign(l, b); });
      const double frame = BestSeconds(quick ? 3 : 9, [&] {
        session->transport().Assign(l, b);
        const std::vector<float> rgb = ShadeWith(*session, b);
        (void)session->Render(cam, rgb, &envs[0].cube);
      });
      const double bound = static_cast<double>(bytes) / bandwidth;
      std::printf("| %zu | %.3f | %.3f | %.1f | %.2f | %.1f | %zu | %.4f | %.2f | %.2f |\n", terms,
                  1e3 * relight.wall, 1e3 * relight.cpu, 1.0 / relight.wall, 1e3 * frame,
                  1.0 / frame, bytes, 1e3 * bound, bound > 0 ? relight.wall / bound : 0.0,
                  bound > 0 ? relight.cpu / bound : 0.0);
    }
    std::printf(
        "(bound = stored bytes of the N columns / single-core copy bandwidth; CPU = all\n"
        " threads' CPU time, which waiting for a core on a shared machine does not inflate;\n"
        " the Eq. 8 path also runs one inverse column transform over 3 × %zu floats per frame)\n",
        ns);
  }

  // ---- 2. Figure 9: 2D against adaptive 4D at equal error ----
  if (own_pack) {
    std::printf(
        "\n## 2. 2D vs adaptive 4D relighting (Cheslack-Postava et al. Fig. 9): sunrise, "
        "NWA-N lighting, error vs uncompressed T under the same N terms\n");
    const std::vector<std::size_t> term_counts = {30, 100, 300};
    std::vector<std::vector<prt::LightingTerm>> lights;
    std::vector<std::vector<float>> refs;  // uncompressed T (texel basis) under each lighting
    // The errors are computed in the pack's order (the traced rows'), with its albedo.
    std::vector<prt::Rgb> albedo(ns);
    for (std::size_t p = 0; p < ns; ++p) albedo[session->pack_sample()[p]] = session->albedo()[p];
    // Relit samples of uncompressed rows (texel basis) under lighting q, in the pack's order
    // (the traced rows', the scene's global order) with the scene's albedo.
    const auto relit = [&](const Traced& t, std::size_t q) {
      return t.Relit(prt::ReconstructLighting(n, lights[q]));
    };
    for (std::size_t terms : term_counts) {
      lights.push_back(prt::NonlinearLightingApproximation(sunrise, basis, terms));
      refs.push_back(relit(traced, lights.size() - 1));
    }
    // The same lighting through an independent estimate of T: how far each relit image is from
    // the truth, the uncompressed T's own estimation error included.
    std::vector<std::vector<float>> truths;
    if (!truth_path.empty()) {
      const Traced truth = ReadDefaultSceneRaw(truth_path);
      if (truth.scene.cubemap_n != n)
        throw prt::InputError(truth_path, "has n = " + std::to_string(truth.scene.cubemap_n) +
                                              ", the transport compared has " + std::to_string(n));
      for (std::size_t q = 0; q < term_counts.size(); ++q) {
        truths.push_back(relit(truth, q));
        std::printf("N = %zu: the uncompressed T against %s: image error %.4g\n", term_counts[q],
                    truth_path.c_str(), prt::RelativeRmsError(refs[q], truths[q]));
      }
    }
    struct Point {
      double error, ms;
    };
    std::vector<double> keeps = quick ? std::vector<double>{0.003, 0.01, 0.05}
                                      : std::vector<double>{0.003, 0.01, 0.03, 0.1};
    // 2D one keep further, so that its errors bracket 4D's at keep 0.03 (2D needs more terms
    // for the same error) and the table has a row at that lower error too.
    std::vector<double> keeps_2d =
        quick ? keeps : std::vector<double>{0.003, 0.01, 0.03, 0.1, 0.25};
    if (!sweep_4d.empty()) keeps = sweep_4d;
    if (!sweep_2d.empty()) keeps_2d = sweep_2d;
    // Every compression first (errors in the pack's order: refs, albedo), then the timings in
    // interleaved rounds, each configuration a few repetitions per round and its fastest over
    // all rounds kept: a machine whose speed drifts over the minutes of the sweep slows 2D and
    // 4D alike instead of whichever was timed in the slow minute. Timed as the viewer relights
    // (its session's coefficient order, the frame's buffer kept), for both schemes alike.
    struct Config {
      prt::CompressionScheme scheme;
      double keep;
      std::unique_ptr<prt::CompressedTransport> ct;
      std::unique_ptr<prt::CompressedRelighter> relighter;
      std::unique_ptr<prt::CompressedTransportOperator> fast;
      std::vector<double> error;        // per N, against the uncompressed T
      std::vector<double> error_truth;  // per N, against --truth
      std::vector<Timing> best;         // per N
    };
    std::vector<Config> configs;
    for (prt::CompressionScheme scheme : {prt::CompressionScheme::k2D, prt::CompressionScheme::k4D,
                                          prt::CompressionScheme::kAdaptive4D}) {
      for (double keep : scheme == prt::CompressionScheme::k2D ? keeps_2d : keeps) {
        prt::CompressionOptions o =
            prt::CompressionOptionsFrom(traced.scene.compression, "default");
        o.scheme = scheme;
        o.keep_fraction = keep;
        Config c{scheme, keep, nullptr, nullptr, nullptr, {}, {}, {}};
        c.ct = std::make_unique<prt::CompressedTransport>(
            prt::CompressTransport(traced.rows.data(), n, traced.Domain(), o));
        c.relighter = std::make_unique<prt::CompressedRelighter>(*c.ct);
        c.fast = std::make_unique<prt::CompressedTransportOperator>(
            *c.relighter, prt::SampleOrder::kCoefficients);
        const prt::CompressedTransportOperator op(*c.relighter);
        for (std::size_t q = 0; q < term_counts.size(); ++q) {
          const std::vector<float> rgb = prt::ShadeSamples(op.Apply(lights[q]), albedo);
          c.error.push_back(prt::RelativeRmsError(rgb, refs[q]));
          if (!truths.empty()) c.error_truth.push_back(prt::RelativeRmsError(rgb, truths[q]));
        }
        c.best.assign(term_counts.size(), Timing{1e300, 1e300});
        configs.push_back(std::move(c));
      }
    }
    const int rounds = quick ? 2 : 7;
    prt::SampleRadiance frame;
    for (int round = 0; round < rounds; ++round) {
      for (Config& c : configs) {
        for (std::size_t q = 0; q < term_counts.size(); ++q) {
          const Timing t = BestTiming(3, [&] { c.fast->Assign(lights[q], frame); });
          c.best[q].wall = std::min(c.best[q].wall, t.wall);
          c.best[q].cpu = std::min(c.best[q].cpu, t.cpu);
        }
      }
    }
    const bool with_truth = !truths.empty();
    std::printf(
        "| scheme | keep | stored terms | N | image error |%s relight ms | relight CPU ms |\n"
        "|---|---|---|---|---|%s---|---|\n",
        with_truth ? " error vs truth |" : "", with_truth ? "---|" : "");
    // curves[reference][scheme][N index]: reference 0 the uncompressed T, 1 the truth.
    std::map<std::string, std::vector<std::vector<Point>>> curves[2];
    for (const Config& c : configs) {
      for (auto& by_scheme : curves) by_scheme[prt::ToString(c.scheme)].resize(term_counts.size());
      for (std::size_t q = 0; q < term_counts.size(); ++q) {
        const Timing& t = c.best[q];
        const double ms = 1e3 * std::min(t.wall, t.cpu);
        curves[0][prt::ToString(c.scheme)][q].push_back({c.error[q], ms});
        if (with_truth) curves[1][prt::ToString(c.scheme)][q].push_back({c.error_truth[q], ms});
        char truth_cell[32] = "";
        if (with_truth) std::snprintf(truth_cell, sizeof truth_cell, " %.4g |", c.error_truth[q]);
        std::printf("| %s | %.3g | %zu | %zu | %.4g |%s %.3f | %.3f |\n", prt::ToString(c.scheme),
                    c.keep, c.ct->term_count(), term_counts[q], c.error[q], truth_cell,
                    1e3 * t.wall, 1e3 * t.cpu);
      }
    }
    // Equal error: 2D's time interpolated (log-log) at each adaptive-4D point's error.
    for (int r = 0; r < (with_truth ? 2 : 1); ++r) {
      std::printf(
          "\n| N | image error%s | adaptive 4D ms | 2D ms (interpolated) | 2D / 4D time |\n"
          "|---|---|---|---|---|\n",
          r == 0 ? "" : " vs truth");
      for (std::size_t q = 0; q < term_counts.size(); ++q) {
        std::vector<Point> c2 = curves[r]["2d"][q];
        std::sort(c2.begin(), c2.end(),
                  [](const Point& a, const Point& b) { return a.error < b.error; });
        for (const Point& p : curves[r]["adaptive4d"][q]) {
          for (std::size_t k = 0; k + 1 < c2.size(); ++k) {
            if (p.error >= c2[k].error && p.error <= c2[k + 1].error && c2[k].error > 0) {
              const double u =
                  std::log(p.error / c2[k].error) / std::log(c2[k + 1].error / c2[k].error);
              const double ms2 =
                  std::exp(std::log(c2[k].ms) + u * std::log(c2[k + 1].ms / c2[k].ms));
              std::printf("| %zu | %.4g | %.3f | %.3f | %.2f |\n", term_counts[q], p.error, p.ms,
                          ms2, ms2 / p.ms);
            }
          }
        }
      }
    }
    std::printf(
        "(times: the lesser of wall and CPU time, fastest of %d interleaved rounds of 3\n"
        " repetitions; rows appear only where 2D's measured errors bracket the 4D point)\n",
        rounds);
    // An image run: the relit image of the uncompressed T, the pack's, and their difference
    // (×10), under sunrise with every lighting coefficient.
    if (traced.image) {
      const int w = traced.image->camera.width, h = traced.image->camera.height;
      const std::vector<float> ref = traced.Relit(envs[0].cube);
      const std::vector<float> got =
          session->ToPackOrder(session->Shade(session->RelightExact(sunrise)));
      prt::ImageRgb a(w, h), b(w, h);
      a.pixels = ref;
      b.pixels = got;
      const std::string png = (fs::path(out_dir) / "image_error_sunrise.png").string();
      prt::WritePng(prt::SideBySide(a, b, true, 10.0), png);
      std::printf(
          "\nimage error under sunrise, exact lighting: %.4g relative RMS (uncompressed | pack | "
          "10 × difference: %s)\n",
          prt::RelativeRmsError(got, ref), png.c_str());
    }
  } else {
    std::printf("\n## 2. skipped: the 2D/4D sweep needs the uncompressed T (run without a pack)\n");
  }

  // ---- 3. Rotation: PBI-30 vs NWA-90 ----
  if (frames < 1) {
    std::printf("\n## 3. skipped (--frames 0)\n");
    return 0;
  }
  std::printf(
      "\n## 3. Rotating environment (Overbeck et al. Fig. 7): %.2f deg/frame for %d "
      "frames, then %d still\n",
      deg, frames, hold);
  std::printf(
      "| environment | mean image error PBI-30 | NWA-90 | NWA-30 | BI-30 | PBI-30 frames "
      "to < 1e-3 after stop | seconds |\n|---|---|---|---|---|---|---|\n");
  for (const std::string name : {"sunrise", "city"}) {
    const prt::EnvironmentImage env =
        prt::ReadEnvironment(prt::bench::DataDir() + "/envmaps/" + name + ".exr");
    prt::RotationOptions o30;
    o30.degrees_per_frame = deg;
    o30.rotate_frames = frames;
    o30.hold_frames = hold;
    o30.terms = 30;
    prt::RotationOptions o90 = o30;
    o90.terms = 90;
    o90.hold_frames = 0;
    const auto t0 = Clock::now();
    prt::ImageRgb side;
    const auto f30 = prt::RunRotation(*session, env, o30, [&](const prt::RotationFrameView& v) {
      if (name == "sunrise" && v.errors.frame == frames) {
        const prt::Camera cam = session->camera();
        const prt::ImageRgb ex = session->Render(cam, v.exact_rgb, &v.cube);
        const prt::ImageRgb nwa = session->Render(cam, v.approx_rgb[0], &v.cube);
        const prt::ImageRgb pbi = session->Render(cam, v.approx_rgb[2], &v.cube);
        side = Row({&ex, &nwa, &pbi});
      }
    });
    const auto f90 = prt::RunRotation(*session, env, o90);
    const double secs = Seconds(t0);
    double pbi = 0, bi = 0, nwa30 = 0, nwa90 = 0;
    for (int f = 1; f <= frames; ++f) {
      pbi += f30[static_cast<std::size_t>(f)].image_error[2];
      bi += f30[static_cast<std::size_t>(f)].image_error[1];
      nwa30 += f30[static_cast<std::size_t>(f)].image_error[0];
      nwa90 += f90[static_cast<std::size_t>(f)].image_error[0];
    }
    const int conv = prt::FramesToConverge(f30, o30, 2, 1e-3);
    std::printf("| %s | %.4g | %.4g | %.4g | %.4g | %d | %.1f |\n", name.c_str(), pbi / frames,
                nwa90 / frames, nwa30 / frames, bi / frames, conv, secs);
    const std::string csv = (fs::path(out_dir) / ("rotation_" + name + "_30.csv")).string();
    prt::WriteRotationCsv(f30, 30, csv);
    prt::PlotRotationErrors(csv, (fs::path(out_dir) / ("rotation_" + name + "_30.png")).string(),
                            o30);
    if (!side.pixels.empty()) {
      const std::string p = (fs::path(out_dir) / "sunrise_exact_nwa30_pbi30.png").string();
      prt::WritePng(side, p);
      std::printf("(frame %d of sunrise, exact | NWA-30 | PBI-30: %s)\n", frames, p.c_str());
    }
  }
  std::printf(
      "(mean over the rotating frames 1..%d; image error = relative RMS of shaded sample "
      "radiance against exact lighting through the same compressed T)\n",
      frames);
  return 0;
}

}  // namespace

// Bad input (a missing or foreign --raw / --truth file, a bad pack) ends with one line naming the
// file and what is wrong.
int main(int argc, char** argv) {
  prt::UseTbbParallelism();  // the core vocabulary's and the runtime's loops on TBB
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "viewer_bench: %s\n", e.what());
    return 1;
  }
}
