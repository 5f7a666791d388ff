// Image relighting in prt-farm end to end under mpirun (docs/image-relighting.md): the tiny
// scene seen by a 32×16 camera. Rows are the kernels' rows of the camera samples, byte-identical
// for any rank count, by brute force, by the sparse method and with path-traced bounces; a run
// killed mid-way resumes to the same bytes; the pack carries the image and prt-view writes it;
// gathered bounces (the vertices' support rows, then the pixels') are byte-identical too.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "formats/compressed_transport.h"
#include "formats/image_file.h"
#include "formats/transport_file.h"
#include "runtime/lighting.h"
#include "tests/run_prt_farm.h"
#include "viewer/environment_background.h"
#include "viewer/viewer_session.h"
#include "viewer/window_test_support.h"
#include "vocabulary/cubemap_resample.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"
#include "worker/camera_samples.h"
#include "worker/embree_scene.h"
#include "worker/glossy_pixels.h"
#include "worker/sparse_precomputation.h"
#include "worker/surface_hit.h"
#include "worker/transport_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kSmallJobs = " --max-job-rows 37 --rows-per-block 64 --log-interval 0.2";
// 2:1, so that the relit EXR reads back through the environment reader as a lat-long image.
constexpr int kWidth = 32, kHeight = 16;

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("image_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// tests/data/<base> seen by a camera; `sampling` is appended to its [sampling] table.
std::string ImageScene(const std::string& dir, const std::string& base,
                       const std::string& sampling = "", const std::string& camera = "") {
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/" + base);
  testing::ReplaceOnce(text, "[scene]\n", "[scene]\nsamples = \"camera\"\n");
  testing::ReplaceOnce(
      text, "[sampling]\n",
      "[camera]\neye = [0.4, 1.6, 3.2]\ntarget = [0.0, 0.2, 0.0]\nfov = 30.0\nwidth = " +
          std::to_string(kWidth) + "\nheight = " + std::to_string(kHeight) + "\n" + camera +
          "\n[sampling]\n" + sampling);
  return testing::WriteTestScene(text, dir + "/" + base);
}

// The kernels in one process: an image scene's geometry, camera samples and transport sampler
// with the scene's rays per texel and seed.
struct KernelScene {
  explicit KernelScene(const std::string& file)
      : scene(LoadSceneFile(file)),
        g(BuildSceneGeometry(scene)),
        embree(g),
        pixels(ComputeCameraSamples(embree, SceneSurfaces(g), scene.camera)),
        sampler(embree, scene.cubemap_n, Options(scene)) {}
  static TransportSamplerOptions Options(const SceneDescription& s) {
    TransportSamplerOptions so;
    so.rays_per_texel = s.sampling.rays_per_texel;
    so.seed = s.sampling.seed;
    return so;
  }
  SceneDescription scene;
  SceneGeometry g;
  EmbreeScene embree;
  CameraSamples pixels;
  TransportSampler sampler;
};

std::vector<float> Rows(const std::string& path) {
  const TransportFileReader r(path);
  std::vector<float> rows(static_cast<std::size_t>(r.info().rows * r.info().cols()));
  r.ReadRows(0, r.info().rows, rows.data());
  return rows;
}

// prt-pack packs run folder `run` into `pack`, and prt-view relights it under a uniform sky of
// radiance 1 with exact lighting into a linear EXR, read back (in `dir`: the logs, sky and EXR).
EnvironmentImage RelitUnderUniformSky(const std::string& dir, const std::string& run,
                                      const std::string& pack) {
  const int packed = std::system((std::string(PRT_PACK_EXE) + " pack " + run + " --out " + pack +
                                  " > " + dir + "/pack.log 2>&1")
                                     .c_str());
  EXPECT_EQ(packed, 0) << ReadWholeFile(dir + "/pack.log");
  const std::string sky = dir + "/sky.exr", exr = dir + "/relit.exr";
  EnvironmentImage uniform = EnvironmentImage::Zero(EnvmapLayout::kLatLong, 64, 32);
  for (int c = 0; c < 3; ++c) std::fill(uniform.Channel(c).begin(), uniform.Channel(c).end(), 1.f);
  WriteEnvironmentExr(uniform, sky);
  const int viewed = std::system((std::string(PRT_VIEW_EXE) + " " + pack + " --env " + sky +
                                  " --exact --exr " + exr + " > " + dir + "/view.log 2>&1")
                                     .c_str());
  EXPECT_EQ(viewed, 0) << ReadWholeFile(dir + "/view.log");
  return ReadEnvironment(exr);
}

// prt-farm on `ranks` ranks farms `scene_file` into `run`, whose transport.prtt must hold the
// kernels' rows to the bit.
void FarmAndExpectTheKernelsRows(int ranks, const std::string& scene_file, const std::string& run,
                                 const std::vector<float>& kernel) {
  const auto r = testing::RunPrtFarm(ranks, scene_file + " --out " + run + kSmallJobs);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<float> rows = Rows(run + "/transport.prtt");
  ASSERT_EQ(rows.size(), kernel.size());
  EXPECT_EQ(std::memcmp(rows.data(), kernel.data(), rows.size() * 4), 0) << ranks << " rank(s)";
}

TEST(ImageRelightingMpiTest, BruteRowsAreTheKernelsRowsForAnyRankCountAndThePackDrawsThem) {
  const std::string dir = WorkDir("brute");
  const std::string scene_file = ImageScene(dir, "tiny.toml");
  // The kernels in one process: the camera's samples and their rows.
  const KernelScene k(scene_file);
  const SceneGeometry& g = k.g;
  const CameraSamples& pixels = k.pixels;
  const TransportSampler& sampler = k.sampler;
  std::vector<float> kernel(pixels.samples.size() * sampler.layout().texel_count());
  sampler.ComputeRows(pixels.samples, 0, kernel.data());
  const std::size_t background = pixels.background_count();
  ASSERT_GT(background, 20u);
  ASSERT_LT(background, pixels.samples.size() / 2);

  std::string compressed;
  for (int ranks : {1, 2, 3}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    FarmAndExpectTheKernelsRows(ranks, scene_file, run, kernel);
    if (HasFatalFailure()) return;
    const ImageSamplesInfo info =
        ReadImageSamplesFile(run + "/image.prti", static_cast<uint32_t>(g.meshes.size()));
    EXPECT_EQ(info.pixel_mesh, pixels.pixel_mesh);
    EXPECT_EQ(info.camera.width, kWidth);
    const std::string c = ReadWholeFile(run + "/transport.prtc");
    if (compressed.empty()) compressed = c;
    EXPECT_TRUE(c == compressed) << ranks << " rank(s): transport.prtc differs";
  }
  // accuracy.json's groups are the meshes the pixels see, then the background: each with its
  // pixel count, and its Σ B² (from the figures: var / relative²) that of the kernels' rows
  // weighed by the mesh's albedo (uniform sky of radiance 1: B_c = ρ_c · Σ_j T_j).
  {
    const nlohmann::json acc = nlohmann::json::parse(ReadWholeFile(dir + "/np2/accuracy.json"));
    const nlohmann::json& mc = acc.at("monte_carlo");
    ASSERT_TRUE(mc.at("estimable").get<bool>());
    const std::size_t T = sampler.layout().texel_count();
    std::vector<uint64_t> count(g.meshes.size() + 1, 0);
    std::vector<double> norm(g.meshes.size() + 1, 0.0);
    for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
      const uint32_t m = pixels.pixel_mesh[p];
      const std::size_t grp = m == kImageBackground ? g.meshes.size() : m;
      ++count[grp];
      if (m == kImageBackground) continue;
      double sum = 0;
      for (std::size_t j = 0; j < T; ++j) sum += kernel[p * T + j];
      for (int c = 0; c < 3; ++c) norm[grp] += std::pow(g.meshes[m].albedo[c] * sum, 2);
    }
    ASSERT_EQ(mc.at("meshes").size(), g.meshes.size() + 1);
    const nlohmann::json& uniform = mc.at("environments").at(0);
    ASSERT_EQ(uniform.at("name"), "uniform");
    for (std::size_t m = 0; m <= g.meshes.size(); ++m) {
      const nlohmann::json& row = uniform.at("meshes").at(m);
      EXPECT_EQ(row.at("name"), m < g.meshes.size() ? g.meshes[m].name : "background");
      EXPECT_EQ(row.at("rows").get<uint64_t>(), count[m]) << m;
      EXPECT_EQ(mc.at("meshes").at(m).at("rows_covered").get<uint64_t>(), count[m]) << m;
      const double rel = row.at("relative_rms").get<double>();
      const double rms = row.at("rms_radiance").get<double>();
      if (m == g.meshes.size()) {  // zero rows: no error
        EXPECT_EQ(rel, 0.0);
        EXPECT_EQ(rms, 0.0);
        continue;
      }
      ASSERT_GT(rel, 0.0) << m;
      const double var = rms * rms * 3.0 * static_cast<double>(count[m]);
      EXPECT_NEAR(var / (rel * rel), norm[m], 1e-3 * norm[m]) << g.meshes[m].name;
      for (const char* c : {"r", "g", "b"})
        EXPECT_NEAR(row.at("relative_rms_per_channel").at(c).get<double>(), rel, 1e-6) << c;
    }
  }

  // The compressed transport's domain is the image: one 32×16 grid.
  const CompressedTransportHeader h = ReadCompressedTransportHeader(dir + "/np2/transport.prtc");
  ASSERT_EQ(h.domain.segments.size(), 1u);
  EXPECT_EQ(h.domain.segments[0].kind, SpatialSegment::Kind::kGrid2D);
  EXPECT_EQ(h.domain.segments[0].width, static_cast<uint32_t>(kWidth));
  EXPECT_EQ(h.domain.segments[0].height, static_cast<uint32_t>(kHeight));

  // prt-pack carries the image, prt-view writes it: a background pixel shows the environment
  // (a uniform sky of 1 here), a lit ground pixel albedo·Σ T.
  const std::string pack = dir + "/tiny-image.prtpack";
  const EnvironmentImage image = RelitUnderUniformSky(dir, dir + "/np2", pack);
  ASSERT_FALSE(HasFailure());
  const std::string sky = dir + "/sky.exr";  // written by RelitUnderUniformSky
  const EnvironmentImage uniform = ReadEnvironment(sky);
  ASSERT_EQ(image.width, kWidth);
  ASSERT_EQ(image.height, kHeight);
  std::size_t checked = 0;
  double err2 = 0, ref2 = 0, worst = 0;
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    if (pixels.pixel_mesh[p] == kImageBackground) {
      EXPECT_NEAR(image.r[p], 1.0f, 1e-6f);
      continue;
    }
    double sum = 0;
    for (std::size_t j = 0; j < sampler.layout().texel_count(); ++j)
      sum += kernel[p * sampler.layout().texel_count() + j];
    const float rho = g.meshes[pixels.pixel_mesh[p]].albedo[0];
    // Compression's error only (exact lighting through the compressed T).
    const double d = image.r[p] - rho * sum;
    err2 += d * d;
    ref2 += rho * sum * rho * sum;
    worst = std::max(worst, std::abs(d));
    ++checked;
  }
  EXPECT_GT(checked, 200u);
  // Keep 5 %, 9 bits: about a percent of relative RMS error, the worst pixel on a silhouette.
  EXPECT_LT(std::sqrt(err2 / ref2), 0.02);
  EXPECT_LT(worst, 0.05);

#ifdef PRT_VIEW_HAS_SDL2
  // The window shows the image pack's fixed view, as the headless render does (PBI under still
  // lighting is exact from frame 0), to one 8-bit code per channel.
  if (std::system("command -v xvfb-run >/dev/null 2>&1") == 0) {
    const std::string shot = testing::RunWindowScreenshot(
        PRT_VIEW_EXE, pack, sky, dir, "--window-frames 5 --lighting pbi --terms 50");
    ASSERT_FALSE(shot.empty()) << ReadWholeFile(dir + "/log.txt");
    const std::string npy = ReadWholeFile(shot);
    ASSERT_GT(npy.size(), 10u);
    const std::size_t header =
        10 + (static_cast<unsigned char>(npy[8]) | (static_cast<unsigned char>(npy[9]) << 8));
    std::vector<float> codes((npy.size() - header) / 4);
    std::memcpy(codes.data(), npy.data() + header, 4 * codes.size());
    const auto s = ViewerSession::Open(pack);
    const ImageRgb want = s->Render(
        s->camera(),
        s->Shade(s->RelightExact(ProjectLighting(ResampleToCubemap(uniform, k.scene.cubemap_n)))),
        EnvironmentBackground(std::make_shared<const EnvironmentLookup>(uniform)));
    ASSERT_EQ(codes.size(), want.pixels.size());
    EXPECT_LE(testing::LargestCodeDifference(codes, want), 1.0);
  }
#endif

  // A vertex run forced into the folder leaves no image.prti behind.
  const std::string vertex_scene = std::string(PRT_TESTS_DATA_DIR) + "/tiny.toml";
  ASSERT_EQ(testing::RunPrtFarm(1, vertex_scene + " --out " + dir + "/np3 --force").exit_code, 0);
  EXPECT_FALSE(fs::exists(dir + "/np3/image.prti"));
}

TEST(ImageRelightingMpiTest, SparseRunsAreByteIdenticalAndKilledRunsResumeToTheSameBytes) {
  const std::string dir = WorkDir("sparse");
  const std::string scene_file = ImageScene(dir, "sparse_tiny.toml");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  EXPECT_TRUE(ReadWholeFile(dir + "/np1/transport.prtt") ==
              ReadWholeFile(dir + "/np2/transport.prtt"));
  const nlohmann::json rep = nlohmann::json::parse(ReadWholeFile(dir + "/np2/report.json"));
  EXPECT_GT(rep["sparse"]["sparse"].get<int>(), 0);  // some pixels were reconstructed

  // The in-process driver on the camera's samples gives the farm's bytes; background pixels
  // take no part (RunSparseSchedule's skip): zero rows, never dense, never reconstructed.
  const KernelScene k(scene_file);
  const CameraSamples& pixels = k.pixels;
  const TransportSampler& sampler = k.sampler;
  SparseReport report;
  const std::vector<float> kernel = RunSparsePrecomputation(
      sampler, pixels.samples, PlanFromSettings(k.scene.sparse, k.g.diagonal(), k.scene.cubemap_n),
      report);
  const std::vector<float> rows = Rows(dir + "/np2/transport.prtt");
  ASSERT_EQ(rows.size(), kernel.size());
  EXPECT_EQ(std::memcmp(rows.data(), kernel.data(), rows.size() * 4), 0);
  const std::size_t T = sampler.layout().texel_count();
  const std::size_t background = pixels.background_count();
  ASSERT_GT(background, 0u);
  std::size_t surface_dense = 0;
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    if (pixels.pixel_mesh[p] != kImageBackground) {
      surface_dense += report.is_dense[p];
      continue;
    }
    EXPECT_EQ(report.is_dense[p], 0) << p;
    for (std::size_t j = 0; j < T; ++j) ASSERT_EQ(rows[p * T + j], 0.0f) << p;
  }
  EXPECT_EQ(report.dense_initial + report.dense_by_rank + report.dense_fallback, surface_dense);
  EXPECT_EQ(surface_dense + report.sparse, pixels.samples.size() - background);
  EXPECT_EQ(rep["sparse"]["dense_total"].get<std::size_t>(), surface_dense);
  const auto killed = testing::RunPrtFarm(
      2, scene_file + " --out " + dir + "/kill" + kSmallJobs + " --fail-after-jobs 3");
  EXPECT_NE(killed.exit_code, 0);
  const auto resumed =
      testing::RunPrtFarm(2, scene_file + " --out " + dir + "/kill" + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  for (const char* f : {"/transport.prtt", "/transport.prtc", "/image.prti"})
    EXPECT_TRUE(ReadWholeFile(dir + "/np1" + f) == ReadWholeFile(dir + "/kill" + f)) << f;
}

TEST(ImageRelightingMpiTest, PathTracedBouncesAreByteIdentical) {
  const std::string dir = WorkDir("bounces");
  const std::string scene_file =
      ImageScene(dir, "tiny.toml", "bounces = 1\nestimator = \"path\"\ngather_paths = 4\n");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::vector<float> a = Rows(dir + "/np1/indirect/path-traced.prtt");
  EXPECT_TRUE(a == Rows(dir + "/np2/indirect/path-traced.prtt"));
  double bounce = 0;
  for (float x : a) bounce += x;
  EXPECT_GT(bounce, 0.0);  // the box and the ground light each other
}

// Supersampling (docs/image-relighting.md, "Supersampling"): 3×3 rays per pixel. The rows are
// the kernels' (the footprints weighed by the albedos), byte-identical for 1 and 2 ranks by brute
// force and by the sparse method; image.prti carries k, coverage and weights; the pack is 1.5 and
// prt-view blends the environment into partly covered pixels; changing k re-samples; bounces
// are refused naming the keys.
TEST(ImageRelightingMpiTest, SupersampledRowsAreByteIdenticalAndThePackBlendsTheEnvironment) {
  const std::string dir = WorkDir("supersample");
  const std::string scene_file = ImageScene(dir, "tiny.toml", "", "supersample = 3\n");
  const KernelScene k(scene_file);
  ASSERT_EQ(k.scene.camera.supersample, 3);
  // The kernels: the camera's footprints (seeded with the scene's seed), weighed by albedo.
  CameraSamples pixels = ComputeCameraSamples(k.embree, SceneSurfaces(k.g), k.scene.camera,
                                              "camera", k.scene.sampling.seed);
  std::vector<Rgb> albedo;
  for (const SceneMesh& m : k.g.meshes) albedo.push_back(m.albedo);
  WeighFootprints(pixels, albedo);
  const TransportSampler sampler(k.embree, k.scene.cubemap_n, KernelScene::Options(k.scene),
                                 GlossySampling{}, pixels.footprints);
  const std::size_t T = sampler.layout().texel_count();
  std::vector<float> kernel(pixels.samples.size() * T);
  sampler.ComputeRows(pixels.samples, 0, kernel.data());
  std::size_t partial = 0;
  for (float c : pixels.coverage) partial += c > 0.f && c < 1.f ? 1 : 0;
  ASSERT_GT(partial, 10u);

  for (int ranks : {1, 2}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    FarmAndExpectTheKernelsRows(ranks, scene_file, run, kernel);
    if (HasFatalFailure()) return;
    const ImageSamplesInfo info =
        ReadImageSamplesFile(run + "/image.prti", static_cast<uint32_t>(k.g.meshes.size()));
    EXPECT_EQ(info.supersample, 3);
    EXPECT_EQ(info.pixel_mesh, pixels.pixel_mesh);
    EXPECT_EQ(info.coverage, pixels.coverage);
    ASSERT_EQ(info.pixel_weight.size(), pixels.pixel_weight.size());
    for (std::size_t p = 0; p < info.pixels(); ++p)
      ASSERT_EQ(info.pixel_weight[p][0], pixels.pixel_weight[p][0]) << p;
    const std::string manifest = ReadWholeFile(run + "/checkpoints/manifest.json");
    EXPECT_NE(manifest.find("\"supersample\""), std::string::npos) << manifest;
  }
  EXPECT_TRUE(ReadWholeFile(dir + "/np1/transport.prtc") ==
              ReadWholeFile(dir + "/np2/transport.prtc"));

  // The pack under a uniform sky of 1: B = w·Σ R + (1 − cov)·1 on every pixel.
  const std::string pack = dir + "/tiny-ss.prtpack";
  const EnvironmentImage image = RelitUnderUniformSky(dir, dir + "/np2", pack);
  ASSERT_FALSE(HasFailure());
  double err2 = 0, ref2 = 0;
  std::size_t blended = 0;
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    double sum = 0;
    for (std::size_t j = 0; j < T; ++j) sum += kernel[p * T + j];
    const double want = pixels.pixel_weight[p][0] * sum + (1.0 - pixels.coverage[p]);
    const double d = image.r[p] - want;
    err2 += d * d;
    ref2 += want * want;
    if (pixels.coverage[p] > 0.f && pixels.coverage[p] < 1.f) {
      ++blended;
      EXPECT_NEAR(image.r[p], want, 0.08) << p;
    }
  }
  EXPECT_GT(blended, 10u);
  EXPECT_LT(std::sqrt(err2 / ref2), 0.02);
  const std::string inspect = dir + "/inspect.txt";
  ASSERT_EQ(std::system((std::string(PRT_PACK_EXE) + " inspect " + pack + " > " + inspect).c_str()),
            0);
  EXPECT_NE(ReadWholeFile(inspect).find("supersample: 3x3 rays per pixel"), std::string::npos)
      << ReadWholeFile(inspect);
  EXPECT_NE(ReadWholeFile(inspect).find("1.5"), std::string::npos) << ReadWholeFile(inspect);

  // The sparse method on the footprints: the same bytes for 1 and 2 ranks.
  const std::string sparse_file = ImageScene(dir, "sparse_tiny.toml", "", "supersample = 2\n");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, sparse_file + " --out " + dir + "/sparse" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  EXPECT_TRUE(ReadWholeFile(dir + "/sparse1/transport.prtt") ==
              ReadWholeFile(dir + "/sparse2/transport.prtt"));

  // Another k re-samples the rows on --resume (the stage key holds it).
  const std::string k2 = ImageScene(dir, "tiny.toml", "", "supersample = 2\n");
  const auto again = testing::RunPrtFarm(1, k2 + " --out " + dir + "/np1 --resume" + kSmallJobs);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_FALSE(Rows(dir + "/np1/transport.prtt") == kernel);
  EXPECT_EQ(ReadImageSamplesFile(dir + "/np1/image.prti", 2).supersample, 2);

  // Gathered bounces from the footprints: the same bytes for 1 and 2 ranks, some bounce light;
  // the path tracer is refused with the keys to change.
  const std::string gather =
      ImageScene(dir, "tiny.toml", "bounces = 1\ngather_paths = 8\n", "supersample = 2\n");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, gather + " --out " + dir + "/gather" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::vector<float> g1 = Rows(dir + "/gather1/indirect/pixel-gather.prtt");
  EXPECT_TRUE(g1 == Rows(dir + "/gather2/indirect/pixel-gather.prtt"));
  double bounce = 0;
  for (float x : g1) bounce += x;
  EXPECT_GT(bounce, 0.0);
  const std::string path =
      ImageScene(dir, "tiny.toml", "bounces = 1\nestimator = \"path\"\n", "supersample = 2\n");
  const auto refused = testing::RunPrtFarm(1, path + " --out " + dir + "/path");
  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_NE(refused.output.find("supersample = 1"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("bounces = 0"), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("estimator = \"gather\""), std::string::npos) << refused.output;
}

// Gathering, the default estimator (docs/image-relighting.md, "Interreflection"): the vertices'
// support rows (vertex-direct, vertex-bounce-1), then the pixels' Σ_k Tᵏ (pixel-gather), the
// same bytes for 1 and 2 ranks and after a kill; zero rows for background pixels; [sparse]
// indirect = "features" is refused naming the key to change.
TEST(ImageRelightingMpiTest, GatheredBouncesAreByteIdenticalAndResume) {
  const std::string dir = WorkDir("gather");
  const std::string scene_file = ImageScene(dir, "tiny.toml", "bounces = 2\ngather_paths = 16\n");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const char* files[] = {"/indirect/vertex-direct.prtt", "/indirect/vertex-bounce-1.prtt",
                         "/indirect/pixel-gather.prtt", "/transport.prtc"};
  for (const char* f : files)
    EXPECT_TRUE(ReadWholeFile(dir + "/np1" + f) == ReadWholeFile(dir + "/np2" + f)) << f;
  const TransportFileReader pixels(dir + "/np1/indirect/pixel-gather.prtt");
  EXPECT_EQ(pixels.info().rows, uint64_t{kWidth} * kHeight);  // one channel: grey albedos
  EXPECT_EQ(pixels.info().cubemap_n, 2u);                     // the indirect grid, n / 4
  const std::vector<float> gathered = Rows(dir + "/np1/indirect/pixel-gather.prtt");
  const ImageSamplesInfo image = ReadImageSamplesFile(dir + "/np1/image.prti", 2);
  const std::size_t cols = pixels.info().cols();
  double surface = 0;
  for (std::size_t p = 0; p < image.pixel_mesh.size(); ++p) {
    double s = 0;
    for (std::size_t j = 0; j < cols; ++j) s += gathered[p * cols + j];
    if (image.pixel_mesh[p] == kImageBackground)
      EXPECT_EQ(s, 0.0) << p;
    else
      surface += s;
  }
  EXPECT_GT(surface, 0.0);
  const nlohmann::json rep = nlohmann::json::parse(ReadWholeFile(dir + "/np2/report.json"));
  const auto& passes = rep["interreflection"]["image_passes"];
  ASSERT_EQ(passes.size(), 3u);
  EXPECT_EQ(passes[0]["phase"], "vertex-direct");
  EXPECT_EQ(passes[2]["phase"], "pixel-gather");

  const auto killed = testing::RunPrtFarm(
      2, scene_file + " --out " + dir + "/kill" + kSmallJobs + " --fail-after-jobs 17");
  EXPECT_NE(killed.exit_code, 0);
  const auto resumed =
      testing::RunPrtFarm(2, scene_file + " --out " + dir + "/kill" + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  for (const char* f : files)
    EXPECT_TRUE(ReadWholeFile(dir + "/np1" + f) == ReadWholeFile(dir + "/kill" + f)) << f;

  std::string features = ReadWholeFile(ImageScene(dir, "sparse_tiny.toml", "bounces = 1\n"));
  testing::ReplaceOnce(features, "[sparse]\n", "[sparse]\nindirect = \"features\"\n");
  const std::string features_file = dir + "/features.toml";
  std::ofstream(features_file) << features;
  const auto refused = testing::RunPrtFarm(1, features_file + " --out " + dir + "/features");
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("set it to \"full\""), std::string::npos) << refused.output;

  // The sparse method: with [sparse] indirect unset an image run's pixels all gather ("full",
  // vocabulary/scene.cpp), with "combination" only the dense ones; both byte-identical for 1 and
  // 2 ranks, and they differ (the sparse pixels' rows are combined in one, gathered in the other).
  for (const char* indirect : {"", "indirect = \"combination\"\n"}) {
    std::string text = ReadWholeFile(ImageScene(dir, "sparse_tiny.toml", "bounces = 1\n"));
    testing::ReplaceOnce(text, "[sparse]\n", std::string("[sparse]\n") + indirect);
    const std::string name = *indirect ? "combination" : "default";
    const std::string file = dir + "/" + name + ".toml";
    std::ofstream(file) << text;
    EXPECT_EQ(LoadSceneFile(file).sparse.indirect, *indirect ? "combination" : "full");
    for (int ranks : {1, 2}) {
      const auto r = testing::RunPrtFarm(
          ranks, file + " --out " + dir + "/" + name + std::to_string(ranks) + kSmallJobs);
      ASSERT_EQ(r.exit_code, 0) << r.output;
    }
    EXPECT_TRUE(ReadWholeFile(dir + "/" + name + "1/indirect/pixel-gather.prtt") ==
                ReadWholeFile(dir + "/" + name + "2/indirect/pixel-gather.prtt"))
        << name;
  }
  EXPECT_FALSE(ReadWholeFile(dir + "/default1/transport.prtc") ==
               ReadWholeFile(dir + "/combination1/transport.prtc"));
}

// Glossy pixels (docs/image-relighting.md, "Glossy pixels"): the box in GGX (roughness 0.5,
// albedo 0.2, specular 0.6: k_d = 0.25, k_s = 0.75, weight 0.8). Brute force with 1 and 2 ranks
// gives the kernels' rows (the sampler with the box's pixels marked glossy), the image file
// carries the weight, and the pack relights a glossy pixel under a uniform sky of 1 to
// weight·Σ T (= albedo + specular·E for an unoccluded one), a diffuse one as before; the
// sparse method is byte-identical for 1 and 2 ranks.
std::string GlossyImageScene(const std::string& dir, const std::string& base) {
  const std::string file = ImageScene(dir, base);
  std::string text = ReadWholeFile(file);
  testing::ReplaceOnce(text, "albedo = [0.5, 0.5, 0.5]",
                       "albedo = [0.2, 0.2, 0.2]\nbrdf = \"ggx\"\nroughness = 0.5\n"
                       "specular = [0.6, 0.6, 0.6]");
  std::ofstream(file) << text;
  return file;
}

TEST(ImageRelightingMpiTest,
     GlossyPixelsAreTheKernelsRowsForAnyRankCountAndRelightWithTheirWeight) {
  const std::string dir = WorkDir("glossy");
  const std::string scene_file = GlossyImageScene(dir, "tiny.toml");
  const SceneDescription scene = LoadSceneFile(scene_file);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const EmbreeScene embree(g);
  CameraSamples pixels = ComputeCameraSamples(embree, SceneSurfaces(g), scene.camera);
  const GlossyPixels glossy = ResolveGlossyPixels(scene, g);
  ASSERT_EQ(glossy.glossy, (std::vector<uint8_t>{1, 0}));
  MarkGlossyPixels(glossy, pixels.pixel_mesh, pixels.samples);
  const TransportSampler sampler(embree, scene.cubemap_n, KernelScene::Options(scene),
                                 {glossy.materials, scene.camera.eye});
  const std::size_t T = sampler.layout().texel_count();
  std::vector<float> kernel(pixels.samples.size() * T);
  sampler.ComputeRows(pixels.samples, 0, kernel.data());
  std::size_t glossy_pixels = 0;
  for (uint32_t m : pixels.pixel_mesh) glossy_pixels += m == 0 ? 1 : 0;
  ASSERT_GT(glossy_pixels, 20u);
  for (int ranks : {1, 2}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    FarmAndExpectTheKernelsRows(ranks, scene_file, run, kernel);
    if (HasFatalFailure()) return;
    const ImageSamplesInfo info = ReadImageSamplesFile(run + "/image.prti", 2);
    EXPECT_EQ(info.glossy_mesh, glossy.glossy);
    EXPECT_NEAR(info.glossy_weight[0][1], 0.8f, 1e-6f);
  }
  const EnvironmentImage image = RelitUnderUniformSky(dir, dir + "/np2", dir + "/glossy.prtpack");
  ASSERT_FALSE(HasFailure());
  double err2[2] = {0, 0}, ref2[2] = {0, 0};
  for (std::size_t p = 0; p < pixels.samples.size(); ++p) {
    const uint32_t m = pixels.pixel_mesh[p];
    if (m == kImageBackground) continue;
    double sum = 0;
    for (std::size_t j = 0; j < T; ++j) sum += kernel[p * T + j];
    // Glossy box: its weight albedo + specular = 0.8; the diffuse ground: its albedo.
    const double want = (m == 0 ? 0.8 : g.meshes[m].albedo[1]) * sum;
    err2[m] += (image.g[p] - want) * (image.g[p] - want);
    ref2[m] += want * want;
  }
  // Compression's error only (keep 5 %, 9 bits), glossy and diffuse pixels alike.
  EXPECT_LT(std::sqrt(err2[0] / ref2[0]), 0.03);
  EXPECT_LT(std::sqrt(err2[1] / ref2[1]), 0.03);

  // The sparse method: the same bytes on 1 and 2 ranks, and glossy pixels reconstructed.
  const std::string sparse_file = GlossyImageScene(dir, "sparse_tiny.toml");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, sparse_file + " --out " + dir + "/sparse" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  EXPECT_TRUE(ReadWholeFile(dir + "/sparse1/transport.prtt") ==
              ReadWholeFile(dir + "/sparse2/transport.prtt"));
  // Gathered bounces: the glossy pixels gather through their lobe (worker/bounce_gather.h,
  // GatherLobe), the same bytes on 1 and 2 ranks; their bounce light differs from a diffuse
  // gather's.
  const auto with_sampling = [&](const std::string& file, const std::string& name,
                                 const std::string& keys, const std::string& sparse = "") {
    std::string text = ReadWholeFile(file);
    testing::ReplaceOnce(text, "[sampling]\n", "[sampling]\n" + keys);
    if (!sparse.empty()) testing::ReplaceOnce(text, "[sparse]\n", "[sparse]\n" + sparse);
    const std::string out = dir + "/" + name + ".toml";
    std::ofstream(out) << text;
    return out;
  };
  const std::string gathered = with_sampling(scene_file, "gathered", "bounces = 1\n");
  for (int ranks : {1, 2}) {
    const auto r = testing::RunPrtFarm(
        ranks, gathered + " --out " + dir + "/gathered" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::string g1 = ReadWholeFile(dir + "/gathered1/indirect/pixel-gather.prtt");
  EXPECT_TRUE(g1 == ReadWholeFile(dir + "/gathered2/indirect/pixel-gather.prtt"));
  EXPECT_TRUE(ReadWholeFile(dir + "/gathered1/transport.prtc") ==
              ReadWholeFile(dir + "/gathered2/transport.prtc"));
  // Refused, naming the keys: the path tracer, and the sparse pixels' combination.
  const auto refused = testing::RunPrtFarm(
      1, with_sampling(scene_file, "path", "bounces = 1\nestimator = \"path\"\n") + " --out " +
             dir + "/path");
  EXPECT_EQ(refused.exit_code, 2) << refused.output;
  EXPECT_NE(refused.output.find("estimator = \"gather\""), std::string::npos) << refused.output;
  EXPECT_NE(refused.output.find("bounces = 0"), std::string::npos) << refused.output;
  const auto combined = testing::RunPrtFarm(
      1,
      with_sampling(sparse_file, "combination", "bounces = 1\n", "indirect = \"combination\"\n") +
          " --out " + dir + "/combination");
  EXPECT_EQ(combined.exit_code, 2) << combined.output;
  EXPECT_NE(combined.output.find("indirect = \"full\""), std::string::npos) << combined.output;
}

}  // namespace
}  // namespace prt
