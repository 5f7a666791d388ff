// Interreflection in prt-farm end to end under mpirun (docs/interreflection.md): the tiny scene
// with bounces farmed with 1, 2 and 3 ranks gives byte-identical bounce files equal to the
// worker kernels called directly (GatherBounces); bounces = 0 keeps the direct-only bytes; a
// run killed in a bounce resumes to the same bytes; an albedo edit re-runs the indirect stage
// and what follows it, not the rows.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "farm/sparse_jobs.h"
#include "formats/compressed_transport.h"
#include "formats/transport_file.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/scene.h"
#include "worker/bounce_gather.h"
#include "worker/embree_scene.h"
#include "worker/path_trace_reference.h"
#include "worker/sparse_indirect.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(PRT_TESTS_DATA_DIR) + "/tiny.toml";
const std::string kSmallJobs = " --max-job-rows 5 --rows-per-block 16 --log-interval 0.2";

testing::RunResult Farm(int ranks, const std::string& args) {
  return testing::RunPrtFarm(ranks, args);
}

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("gi_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

std::vector<float> Rows(const std::string& path) {
  const TransportFileReader r(path);
  std::vector<float> rows(static_cast<std::size_t>(r.info().rows * r.info().cols()));
  r.ReadRows(0, r.info().rows, rows.data());
  return rows;
}

nlohmann::json Report(const std::string& run) {
  return nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
}

// Vertex v's combination from combination.bin's pairs (empty: v gathers itself).
std::vector<SampleWeight> CombinationOf(const std::vector<uint32_t>& pairs, uint64_t slots,
                                        uint64_t v) {
  std::vector<SampleWeight> w;
  for (uint64_t j = 0; j < slots; ++j)
    if (pairs[(v * slots + j) * 2] != kNoSample) {
      float a = 0;
      std::memcpy(&a, &pairs[(v * slots + j) * 2 + 1], sizeof a);
      w.push_back({pairs[(v * slots + j) * 2], a});
    }
  return w;
}

// sparse_tiny.toml with 2 bounces by path tracing (8 paths) and `sparse_extra` appended to its
// [sparse] table, farmed with 1 and 2 ranks into dir/np1 and dir/np2, whose path-traced files
// must be the same; returns the scene file.
std::string FarmSparsePathTracing(const std::string& dir, const std::string& sparse_extra) {
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml");
  text.replace(text.find("method = \"sparse\""), 17,
               "method = \"sparse\"\nbounces = 2\nestimator = \"path\"\ngather_paths = 8");
  text += sparse_extra;  // the file ends in [sparse]
  const std::string scene_file = dir + "/path.toml";
  testing::WriteTestScene(text, scene_file);
  for (int ranks : {1, 2}) {
    const auto r =
        Farm(ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    EXPECT_EQ(r.exit_code, 0) << r.output;
  }
  EXPECT_TRUE(Rows(dir + "/np1/indirect/path-traced.prtt") ==
              Rows(dir + "/np2/indirect/path-traced.prtt"));
  return scene_file;
}

// The farm's path tracing for a scene with 2 bounces and `paths` paths per vertex.
PathTraceOptions FarmPathOptions(const SceneDescription& scene, int paths) {
  PathTraceOptions po;
  po.bounces = 2;
  po.paths = paths;
  po.rays_per_texel = scene.sampling.rays_per_texel;
  po.seed = scene.sampling.seed;
  return po;
}

// Per sample: 1 where the run's combination.bin gives no combination (a dense vertex).
std::vector<uint8_t> DenseOf(const std::string& run, uint64_t V) {
  uint64_t slots = 0;
  const std::vector<uint32_t> pairs =
      ReadCombinationFile(run + "/sparse/combination.bin", V, slots);
  std::vector<uint8_t> is_dense(V);
  for (uint64_t v = 0; v < V; ++v) is_dense[v] = CombinationOf(pairs, slots, v).empty();
  return is_dense;
}

// The kernels in one process: the tiny scene's direct rows and two gathered bounces on the
// n = 2 grid (n/4 of the scene's 8), the farm's seed and directions.
std::vector<std::vector<float>> KernelBounces() {
  const SceneDescription scene = LoadSceneFile(kScene);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  TransportSamplerOptions to;
  to.rays_per_texel = scene.sampling.rays_per_texel;
  to.seed = scene.sampling.seed;
  const TransportSampler sampler(embree, scene.cubemap_n, to);
  std::vector<float> direct(samples.size() * sampler.layout().texel_count());
  sampler.ComputeRows(samples, 0, direct.data());
  BounceGatherOptions go;
  go.paths = scene.sampling.gather_paths;
  go.seed = scene.sampling.seed;
  go.indirect_n = 2;  // the farm's near field traces on the indirect grid
  const BounceGatherer gatherer(embree, surfaces, go);
  return GatherBounces(gatherer, samples, sampler.layout(), CubemapLayout(2), direct, 2, 1);
}

TEST(InterreflectionMpiTest, BouncesAreByteIdenticalForOneTwoAndThreeRanksAndEqualTheKernels) {
  const std::string dir = WorkDir("ranks");
  const std::vector<std::vector<float>> kernels = KernelBounces();
  std::string compressed;
  for (int ranks : {1, 2, 3}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    const auto r = Farm(ranks, kScene + " --out " + run + kSmallJobs + " --bounces 2");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    for (int k = 1; k <= 2; ++k) {
      const std::vector<float> rows = Rows(run + "/indirect/bounce-" + std::to_string(k) + ".prtt");
      ASSERT_EQ(rows.size(), kernels[k - 1].size());
      EXPECT_EQ(std::memcmp(rows.data(), kernels[k - 1].data(), rows.size() * 4), 0)
          << ranks << " rank(s), bounce " << k;
    }
    const std::string c = ReadWholeFile(run + "/transport.prtc");
    if (compressed.empty()) compressed = c;
    EXPECT_TRUE(c == compressed) << ranks << " rank(s): transport.prtc differs";
    const nlohmann::json rep = Report(run);
    ASSERT_EQ(rep["interreflection"]["per_bounce"].size(), 2u);
    const double e1 = rep["interreflection"]["per_bounce"][0]["energy"][0].get<double>();
    const double e2 = rep["interreflection"]["per_bounce"][1]["energy"][0].get<double>();
    EXPECT_GT(e1, 0.0);
    EXPECT_LT(e2, 0.6 * e1);  // albedo ≤ 0.8 and most bounce light escapes the open scene
    EXPECT_GT(rep["interreflection"]["indirect_share"][0]["indirect_share"].get<double>(), 0.0);
  }
}

// Rows in place (docs/farm.md, "Where the rows go"): every rank reads the previous bounce from
// the run folder and writes its bounce rows there; rank 0 sees checksums and counters only. The
// files equal those of --rows-via-rank0 (rank 0 broadcasts the previous bounce and writes every
// row), for gathering and for path tracing.
TEST(InterreflectionMpiTest, BounceRowsInPlaceEqualRowsThroughRankZero) {
  const std::string dir = WorkDir("in_place");
  const std::string args = kSmallJobs + " --bounces 2";
  ASSERT_EQ(Farm(3, kScene + " --out " + dir + "/own" + args).exit_code, 0);
  ASSERT_EQ(Farm(3, kScene + " --out " + dir + "/funnel" + args + " --rows-via-rank0").exit_code,
            0);
  for (const char* f : {"/indirect/bounce-1.prtt", "/indirect/bounce-2.prtt", "/transport.prtc"})
    EXPECT_TRUE(ReadWholeFile(dir + "/own" + f) == ReadWholeFile(dir + "/funnel" + f)) << f;
  const nlohmann::json batches = Report(dir + "/own")["coordinator"]["batches"];
  ASSERT_EQ(batches.size(), 3u);  // brute, bounce-1, bounce-2
  for (const auto& b : batches) EXPECT_LE(b["bytes_per_item"].get<double>(), 64.0) << b.dump();
  const nlohmann::json through = Report(dir + "/funnel")["coordinator"]["batches"];
  // Bounce rows here are small (24 texels at the indirect n = 2: 96 bytes), so the rows that
  // come through rank 0 are only a few times its bookkeeping.
  EXPECT_GT(through[1]["bytes_in"].get<uint64_t>(), 3 * batches[1]["bytes_in"].get<uint64_t>());
}

TEST(InterreflectionMpiTest, ZeroBouncesKeepsTheDirectOnlyBytes) {
  const std::string dir = WorkDir("zero");
  ASSERT_EQ(Farm(2, kScene + " --out " + dir + "/a" + kSmallJobs).exit_code, 0);
  ASSERT_EQ(Farm(2, kScene + " --out " + dir + "/b" + kSmallJobs + " --bounces 0").exit_code, 0);
  ASSERT_EQ(Farm(2, kScene + " --out " + dir + "/c" + kSmallJobs + " --bounces 1").exit_code, 0);
  for (const char* f : {"/transport.prtt", "/transport.prtc", "/checkpoints/manifest.json"})
    EXPECT_TRUE(ReadWholeFile(dir + "/a" + f) == ReadWholeFile(dir + "/b" + f)) << f;
  EXPECT_FALSE(fs::exists(dir + "/b/indirect"));
  EXPECT_FALSE(Report(dir + "/b").contains("interreflection"));
  // With a bounce the direct rows are the same, the compressed transport is not.
  EXPECT_TRUE(ReadWholeFile(dir + "/a/transport.prtt") == ReadWholeFile(dir + "/c/transport.prtt"));
  EXPECT_FALSE(ReadWholeFile(dir + "/a/transport.prtc") ==
               ReadWholeFile(dir + "/c/transport.prtc"));
}

TEST(InterreflectionMpiTest, KilledInABounceThenResumeGivesTheSameBytes) {
  const std::string dir = WorkDir("kill");
  ASSERT_EQ(Farm(1, kScene + " --out " + dir + "/fresh" + kSmallJobs + " --bounces 2").exit_code,
            0);
  // The direct rows first (bounces are not their input), then the bounces, killed after 4 of
  // bounce 1's jobs (--fail-after-jobs counts a phase's jobs).
  const std::string run = dir + "/run";
  ASSERT_EQ(Farm(1, kScene + " --out " + run + kSmallJobs).exit_code, 0);
  const auto killed =
      Farm(1, kScene + " --out " + run + kSmallJobs + " --bounces 2 --resume --fail-after-jobs 4");
  EXPECT_NE(killed.exit_code, 0) << killed.output;
  EXPECT_TRUE(fs::exists(run + "/transport.prtt"));
  EXPECT_FALSE(fs::exists(run + "/indirect/bounce-1.prtt"));
  const auto resumed = Farm(1, kScene + " --out " + run + kSmallJobs + " --bounces 2 --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  for (const char* f : {"/indirect/bounce-1.prtt", "/indirect/bounce-2.prtt", "/transport.prtc"})
    EXPECT_TRUE(ReadWholeFile(dir + "/fresh" + f) == ReadWholeFile(run + f)) << f;
  const nlohmann::json rep = Report(run);
  EXPECT_EQ(rep["stages"][0]["status"], "reused");
  EXPECT_EQ(rep["stages"][1]["name"], "indirect");
  EXPECT_EQ(rep["stages"][1]["status"], "resumed");
  EXPECT_GT(rep["interreflection"]["per_bounce"][0]["jobs_reused"].get<int>(), 0);
}

TEST(InterreflectionMpiTest, AnAlbedoEditReRunsTheBouncesNotTheRows) {
  const std::string dir = WorkDir("albedo");
  const std::string run = dir + "/run";
  ASSERT_EQ(Farm(2, kScene + " --out " + run + kSmallJobs + " --bounces 1").exit_code, 0);
  const std::string rows = ReadWholeFile(run + "/transport.prtt");
  const std::string bounce = ReadWholeFile(run + "/indirect/bounce-1.prtt");
  std::string text = ReadWholeFile(kScene);
  const std::string from = "albedo = [0.5, 0.5, 0.5]";
  ASSERT_NE(text.find(from), std::string::npos);
  text.replace(text.find(from), from.size(), "albedo = [0.7, 0.7, 0.7]");
  const std::string edited = dir + "/edited.toml";
  testing::WriteTestScene(text, edited);
  const auto r = Farm(2, edited + " --out " + run + kSmallJobs + " --bounces 1 --resume");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json rep = Report(run);
  EXPECT_EQ(rep["stages"][0]["status"], "reused");
  EXPECT_EQ(rep["stages"][1]["status"], "ran");
  EXPECT_EQ(rep["stages"][2]["status"], "ran");  // compression
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtt") == rows);
  // The ground gathers from the box: brighter box, more bounce light.
  EXPECT_FALSE(ReadWholeFile(run + "/indirect/bounce-1.prtt") == bounce);
}

// Sparse precomputation with interreflection ([sparse] indirect = "combination", the default for
// method "sparse"): only the dense vertices gather; every other vertex's bounce rows are the
// combination (run/sparse/combination.bin) its direct row was reconstructed with. The bounce
// files are the same for 1 and 2 ranks and after a kill and resume inside a bounce, the dense
// rows are the gather kernel's on the sparse T⁰, the others Σ α·(dense rows) clamped at 0.
TEST(InterreflectionMpiTest, SparseBouncesGatherAtDenseVerticesAndCombineTheRest) {
  const std::string dir = WorkDir("sparse");
  const std::string sparse_scene = std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml";
  const std::string args = kSmallJobs + " --bounces 2";
  for (int ranks : {1, 2}) {
    const auto r =
        Farm(ranks, sparse_scene + " --out " + dir + "/np" + std::to_string(ranks) + args);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::string run = dir + "/np2";
  for (int k = 1; k <= 2; ++k) {
    const std::string f = "/indirect/bounce-" + std::to_string(k) + ".prtt";
    EXPECT_TRUE(ReadWholeFile(dir + "/np1" + f) == ReadWholeFile(run + f)) << f;
  }
  const SceneDescription scene = LoadSceneFile(sparse_scene);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const uint64_t V = samples.size();
  uint64_t slots = 0;
  const std::vector<uint32_t> pairs =
      ReadCombinationFile(run + "/sparse/combination.bin", V, slots);
  std::vector<uint8_t> combined(V, 0);
  uint64_t count = 0;
  for (uint64_t v = 0; v < V; ++v) count += combined[v] = pairs[v * slots * 2] != kNoSample;
  EXPECT_GT(count, V / 3);
  EXPECT_LT(count, V);
  EXPECT_EQ(Report(run)["interreflection"]["sparse_combined_vertices"].get<uint64_t>(), count);
  // Bounce 1's dense rows: the kernel on the run's (sparse) T⁰ coarsened to the indirect grid.
  const std::vector<float> direct = Rows(run + "/transport.prtt");
  const CubemapLayout fine(scene.cubemap_n), coarse(scene.cubemap_n / 4);
  const std::size_t cols = coarse.texel_count();
  std::vector<float> previous(V * cols);
  for (uint64_t v = 0; v < V; ++v)
    CoarsenRow(fine, coarse, direct.data() + v * fine.texel_count(), previous.data() + v * cols);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  BounceGatherOptions go;
  go.paths = scene.sampling.gather_paths;
  go.seed = scene.sampling.seed;
  go.indirect_n = coarse.n();
  const BounceGatherer gatherer(embree, surfaces, go);
  const std::vector<float> b1 = Rows(run + "/indirect/bounce-1.prtt");
  ASSERT_EQ(b1.size(), V * cols);
  std::vector<GatherTerm> terms;
  std::vector<float> near, row(cols);
  for (uint64_t v = 0; v < V; ++v) {
    if (combined[v]) {
      const std::vector<SampleWeight> w = CombinationOf(pairs, slots, v);
      for (const SampleWeight& x : w)
        ASSERT_FALSE(combined[x.sample]) << v << " combines " << x.sample << ", not dense";
      CombineRows(
          w, [&](uint32_t d) { return b1.data() + d * cols; }, cols, row.data());
    } else {
      gatherer.GatherRow(samples[v], v, 1, 1, previous.data(), V, 1, cols, row.data(), terms, near);
    }
    for (std::size_t j = 0; j < cols; ++j) ASSERT_EQ(b1[v * cols + j], row[j]) << v << " " << j;
  }
  // Killed inside bounce 2, then resumed: the same bytes.
  const std::string again = dir + "/again";
  ASSERT_EQ(Farm(1, sparse_scene + " --out " + again + kSmallJobs).exit_code, 0);
  const auto killed =
      Farm(1, sparse_scene + " --out " + again + args + " --resume --fail-after-jobs 3");
  EXPECT_NE(killed.exit_code, 0) << killed.output;
  const auto resumed = Farm(1, sparse_scene + " --out " + again + args + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  for (const char* f : {"/indirect/bounce-1.prtt", "/indirect/bounce-2.prtt", "/transport.prtc"})
    EXPECT_TRUE(ReadWholeFile(run + f) == ReadWholeFile(again + f)) << f;
}

// The same with per-element path tracing: the dense vertices trace paths on the indirect grid
// (the reference kernel's ComputeIndirect at indirect_n), the others combine them; 1 and 2 ranks
// agree.
TEST(InterreflectionMpiTest, SparsePathTracingTracesDenseVerticesOnTheIndirectGrid) {
  const std::string dir = WorkDir("sparse_path");
  const std::string scene_file = FarmSparsePathTracing(dir, "");
  const std::string run = dir + "/np2";
  const std::vector<float> a = Rows(run + "/indirect/path-traced.prtt");
  const SceneDescription scene = LoadSceneFile(scene_file);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const uint64_t V = samples.size();
  const int m = scene.cubemap_n / 4;
  EXPECT_EQ(TransportFileReader(run + "/indirect/path-traced.prtt").info().cubemap_n,
            static_cast<uint32_t>(m));
  uint64_t slots = 0;
  const std::vector<uint32_t> pairs =
      ReadCombinationFile(run + "/sparse/combination.bin", V, slots);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const PathTraceOptions po = FarmPathOptions(scene, 8);
  const PathTraceReference reference(embree, surfaces, m, po);
  const std::size_t cols = reference.layout().texel_count();
  ASSERT_EQ(a.size(), V * cols);
  std::vector<float> want(cols);
  uint64_t combined = 0;
  for (uint64_t v = 0; v < V; ++v) {
    const std::vector<SampleWeight> w = CombinationOf(pairs, slots, v);
    if (!w.empty()) {
      ++combined;
      CombineRows(
          w, [&](uint32_t d) { return a.data() + d * cols; }, cols, want.data());
    } else {
      reference.ComputeIndirect(samples[v], v, 1, {}, want.data());
    }
    for (std::size_t j = 0; j < cols; ++j) ASSERT_EQ(a[v * cols + j], want[j]) << v << " " << j;
  }
  EXPECT_GT(combined, V / 3);
}

// [sparse] indirect = "features" with path tracing: the dense vertices trace whole rows on the
// indirect grid, the others their feature texels, reconstructed by L1 (phase path-trace-sparse):
// the farm's file for 1 and 2 ranks is the in-process kernel's (RunSparseIndirect) bit for bit.
TEST(InterreflectionMpiTest, SparsePathFeaturesAreTheKernelsForAnyRankCount) {
  const std::string dir = WorkDir("sparse_features");
  const std::string scene_file = FarmSparsePathTracing(dir, "indirect = \"features\"\n");
  const std::string run = dir + "/np2";
  const std::vector<float> a = Rows(run + "/indirect/path-traced.prtt");
  EXPECT_TRUE(Report(run)["interreflection"].contains("path_trace_features"));
  const SceneDescription scene = LoadSceneFile(scene_file);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const uint64_t V = samples.size();
  const std::vector<uint8_t> is_dense = DenseOf(run, V);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const PathTraceOptions po = FarmPathOptions(scene, 8);
  const int m = scene.cubemap_n / 4;
  const PathTraceReference reference(embree, surfaces, m, po);
  const PathTracedIndirect component(reference, 1);
  const SparsePlan plan = PlanFromSettings(scene.sparse, g.diagonal(), scene.cubemap_n);
  const SparseIndirectOptions io = IndirectOptionsOf(plan, scene.cubemap_n, m);
  std::vector<float> want(V * component.cols());
  SparseIndirectStats st;
  RunSparseIndirect(component, samples, is_dense, plan.radius, plan.max_neighbors, io, want.data(),
                    st);
  EXPECT_GT(st.reconstructed, V / 4);
  ASSERT_EQ(a.size(), want.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], want[i]) << i;
  // Killed inside path-trace-sparse (its file removed, the dense one kept), then resumed: its
  // journaled jobs are re-used and the bytes are the same.
  const std::string again = dir + "/again";
  fs::copy(dir + "/np1", again, fs::copy_options::recursive);
  fs::remove(again + "/indirect/path-traced.prtt");
  const auto killed =
      Farm(1, scene_file + " --out " + again + kSmallJobs + " --resume --fail-after-jobs 3");
  EXPECT_NE(killed.exit_code, 0) << killed.output;
  const auto resumed = Farm(1, scene_file + " --out " + again + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("job(s) re-used from checkpoints"), std::string::npos)
      << resumed.output;
  EXPECT_TRUE(Rows(again + "/indirect/path-traced.prtt") == a);
}

// [sparse] indirect = "features" with gathering: bounce-k gathers at the dense vertices,
// bounce-k-sparse gathers the other vertices' feature texels with feature_paths directions and
// reconstructs them by L1; both bounces equal the in-process kernels (RunSparseIndirect with the
// fewer-direction gatherer as its sparse component) for 1 and 2 ranks.
TEST(InterreflectionMpiTest, SparseGatherFeaturesAreTheKernelsForAnyRankCount) {
  const std::string dir = WorkDir("sparse_gather_features");
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml");
  text.replace(text.find("method = \"sparse\""), 17,
               "method = \"sparse\"\nbounces = 2\ngather_paths = 256");
  text += "indirect = \"features\"\nfeature_paths = 32\n";  // the file ends in [sparse]
  const std::string scene_file = dir + "/gather.toml";
  testing::WriteTestScene(text, scene_file);
  for (int ranks : {1, 2}) {
    const auto r =
        Farm(ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::string run = dir + "/np2";
  const SceneDescription scene = LoadSceneFile(scene_file);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const uint64_t V = samples.size();
  const std::vector<uint8_t> is_dense = DenseOf(run, V);
  const CubemapLayout fine(scene.cubemap_n), coarse(scene.cubemap_n / 4);
  const std::size_t cols = coarse.texel_count();
  const std::vector<float> direct = Rows(run + "/transport.prtt");
  std::vector<float> previous(V * cols);
  for (uint64_t v = 0; v < V; ++v)
    CoarsenRow(fine, coarse, direct.data() + v * fine.texel_count(), previous.data() + v * cols);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  BounceGatherOptions go;
  go.paths = 256;
  go.seed = scene.sampling.seed;
  go.indirect_n = coarse.n();
  const BounceGatherer all(embree, surfaces, go);
  go.paths = 32;
  const BounceGatherer few(embree, surfaces, go);
  const SparsePlan plan = PlanFromSettings(scene.sparse, g.diagonal(), scene.cubemap_n);
  const SparseIndirectOptions io = IndirectOptionsOf(plan, scene.cubemap_n, coarse.n());
  for (int k = 1; k <= 2; ++k) {
    const GatheredBounce dense_rows(all, k, 1, previous.data(), V, 1, cols);
    const GatheredBounce features(few, k, 1, previous.data(), V, 1, cols);
    std::vector<float> want(V * cols);
    SparseIndirectStats st;
    RunSparseIndirect(dense_rows, samples, is_dense, plan.radius, plan.max_neighbors, io,
                      want.data(), st, {}, &features);
    EXPECT_GT(st.reconstructed, V / 4);
    const std::string f = "/indirect/bounce-" + std::to_string(k) + ".prtt";
    const std::vector<float> got = Rows(run + f);
    EXPECT_TRUE(got == Rows(dir + "/np1" + f)) << f;
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], want[i]) << k << " " << i;
    previous = got;
  }
  const nlohmann::json rep = Report(run);
  ASSERT_EQ(rep["interreflection"]["per_bounce"].size(), 2u);
  EXPECT_TRUE(rep["interreflection"]["per_bounce"][1].contains("features"));
}

// estimator = "path": the indirect stage is one phase of per-element path tracing, its file
// (Σ_k Tᵏ at n) the same for 1 and 2 ranks and equal to the reference kernel's rows minus T⁰.
TEST(InterreflectionMpiTest, PathTracedIndirectIsTheReferenceKernelsForAnyRankCount) {
  const std::string dir = WorkDir("path");
  std::string text = ReadWholeFile(kScene);
  text += "bounces = 2\nestimator = \"path\"\ngather_paths = 16\n";
  const std::string scene_file = dir + "/path.toml";
  testing::WriteTestScene(text, scene_file);
  for (int ranks : {1, 2}) {
    const auto r =
        Farm(ranks, scene_file + " --out " + dir + "/np" + std::to_string(ranks) + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const std::vector<float> a = Rows(dir + "/np1/indirect/path-traced.prtt");
  EXPECT_TRUE(a == Rows(dir + "/np2/indirect/path-traced.prtt"));
  const SceneDescription scene = LoadSceneFile(scene_file);
  const SceneGeometry g = BuildSceneGeometry(scene);
  const std::vector<SpatialSample> samples = SpatialSamplesOf(g);
  const EmbreeScene embree(g);
  const SceneSurfaces surfaces(g);
  const PathTraceOptions po = FarmPathOptions(scene, 16);
  const PathTraceReference reference(embree, surfaces, scene.cubemap_n, po);
  const std::size_t cols = reference.layout().texel_count();
  std::vector<float> row(cols), bounces(3 * cols);
  ASSERT_EQ(a.size(), samples.size() * cols);
  for (std::size_t v = 0; v < samples.size(); ++v) {
    PathTraceExtras ex;
    ex.bounce_rows = bounces.data();
    reference.ComputeRow(samples[v], v, 1, row.data(), ex);
    for (std::size_t j = 0; j < cols; ++j)
      ASSERT_EQ(a[v * cols + j], 0.0f + bounces[cols + j] + bounces[2 * cols + j]) << v << " " << j;
  }
  const nlohmann::json rep = Report(dir + "/np2");
  EXPECT_EQ(rep["interreflection"]["per_bounce"].size(), 2u);
  EXPECT_EQ(rep["stages"][1]["name"], "indirect");
}

// Coloured albedos: T has one row per colour channel through the farm. A red box on a grey
// ground: the bounce rows and transport.prtc hold 3 × 72 rows (prt-pack and the viewer take
// them: packager/, viewer/ tests), and the light the
// ground gets from the box is red (its channels in the box's albedo ratios).
TEST(InterreflectionMpiTest, ColouredAlbedosGiveOneRowPerChannelThroughTheCompression) {
  const std::string dir = WorkDir("colour");
  std::string text = ReadWholeFile(kScene);
  const std::string from = "albedo = [0.5, 0.5, 0.5]";
  text.replace(text.find(from), from.size(), "albedo = [0.8, 0.2, 0.1]");
  const std::string scene_file = dir + "/red.toml";
  testing::WriteTestScene(text, scene_file);
  const std::string run = dir + "/run";
  const auto r = Farm(2, scene_file + " --out " + run + kSmallJobs + " --bounces 1");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const TransportFileReader bounce(run + "/indirect/bounce-1.prtt");
  EXPECT_EQ(bounce.info().rows, 3u * 72u);
  const CompressedTransportHeader h = ReadCompressedTransportHeader(run + "/transport.prtc");
  EXPECT_EQ(h.channels, 3u);
  EXPECT_EQ(h.sample_count, 3u * 72u);
  EXPECT_EQ(Report(run)["interreflection"]["channels"], 3);
  // Σ over the ground's rows (samples 8…71) per channel: the box's red, green, blue ratios (the
  // ground's own albedo is grey, so bounce 1's light on it has the box's colour).
  const std::vector<float> rows = Rows(run + "/indirect/bounce-1.prtt");
  const std::size_t cols = bounce.info().cols();
  double sum[3] = {0, 0, 0};
  for (int c = 0; c < 3; ++c)
    for (std::size_t v = 8; v < 72; ++v)
      for (std::size_t j = 0; j < cols; ++j) sum[c] += rows[(c * 72 + v) * cols + j];
  ASSERT_GT(sum[0], 0.0);
  EXPECT_NEAR(sum[1] / sum[0], 0.2 / 0.8, 0.02);
  EXPECT_NEAR(sum[2] / sum[0], 0.1 / 0.8, 0.02);
  // A grey edit of the same scene is one channel again: the indirect stage and the compression
  // re-run, the rows do not.
  const auto grey = Farm(2, kScene + " --out " + run + kSmallJobs + " --bounces 1 --resume");
  ASSERT_EQ(grey.exit_code, 0) << grey.output;
  EXPECT_EQ(ReadCompressedTransportHeader(run + "/transport.prtc").channels, 1u);
  EXPECT_EQ(Report(run)["stages"][0]["status"], "reused");
}

}  // namespace
}  // namespace prt
