// prt-farm end to end under mpirun (docs/farm.md): the tiny scene of tests/data farmed with 1, 2
// and 3 ranks gives byte-identical transport files equal to the worker kernels called directly;
// a run killed mid-way (coordinator or worker) and resumed gives the same bytes without redoing
// the journaled jobs; a hung worker ends the run with exit code 4; bad input gives the
// documented exit codes and messages.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "farm/farm_options.h"
#include "formats/geometry_file.h"
#include "formats/transport_file.h"
#include "formats/transport_variance.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/errors.h"
#include "vocabulary/scene.h"
#include "worker/embree_scene.h"
#include "worker/sparse_precomputation.h"
#include "worker/transport_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(PRT_TESTS_DATA_DIR) + "/tiny.toml";
// Small jobs and blocks so that 72 samples make many jobs and several blocks.
const std::string kSmallJobs = " --max-job-rows 5 --rows-per-block 16 --log-interval 0.2";

using testing::RunResult;

RunResult Farm(int ranks, const std::string& args) {
  return testing::RunPrtFarm(ranks, args + " --keep-raw");  // these tests read transport.prtt
}

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

nlohmann::json ReadReport(const std::string& run) {
  return nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
}

int JournalJobs(const std::string& run) {
  std::ifstream in(run + "/checkpoints/journal.txt");
  std::string line;
  int jobs = 0;
  while (std::getline(in, line)) jobs += line.rfind("job ", 0) == 0 ? 1 : 0;
  return jobs;
}

// The reference: the worker kernels called directly on the scene, no MPI, no farm.
struct Reference {
  std::vector<float> rows;
  SampleStats stats;
  SceneGeometry geometry;
};

const Reference& KernelReference() {
  static const Reference ref = [] {
    Reference r;
    const SceneDescription scene = LoadSceneFile(kScene);
    r.geometry = BuildSceneGeometry(scene);
    const std::vector<SpatialSample> samples = SpatialSamplesOf(r.geometry);
    const EmbreeScene embree(r.geometry);
    TransportSamplerOptions options;
    options.rays_per_texel = scene.sampling.rays_per_texel;
    options.seed = scene.sampling.seed;
    const TransportSampler sampler(embree, scene.cubemap_n, options);
    r.rows.resize(samples.size() * sampler.layout().texel_count());
    r.stats = sampler.ComputeRows(samples, 0, r.rows.data());
    return r;
  }();
  return ref;
}

void ExpectEqualsKernels(const std::string& transport) {
  const Reference& ref = KernelReference();
  TransportFileReader reader(transport);
  ASSERT_EQ(reader.info().rows, 72u);
  ASSERT_EQ(reader.info().cols(), 384u);
  EXPECT_EQ(reader.info().rows_per_block, 16u);
  EXPECT_EQ(reader.info().block_count(), 5u);
  EXPECT_EQ(reader.FindCorruptBlock(), -1);
  std::vector<float> rows(ref.rows.size());
  reader.ReadRows(0, reader.info().rows, rows.data());
  ASSERT_EQ(std::memcmp(rows.data(), ref.rows.data(), rows.size() * sizeof(float)), 0)
      << "the farmed rows differ from the worker kernels' rows";
  // Not all zero and not all equal: the box shadows part of the ground.
  float lo = rows[0], hi = rows[0];
  for (float v : rows) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  EXPECT_EQ(lo, 0.0f);
  EXPECT_GT(hi, 0.0f);
}

TEST(FarmMpiTest, OneTwoAndThreeRanksGiveByteIdenticalFilesEqualToTheKernels) {
  const std::string dir = WorkDir("ranks");
  std::string reference_bytes;
  for (int ranks : {1, 2, 3}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    const RunResult r = Farm(ranks, kScene + " --out " + run + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("[brute]"), std::string::npos) << "no progress line:\n" << r.output;
    ExpectEqualsKernels(run + "/transport.prtt");
    const std::string bytes = ReadWholeFile(run + "/transport.prtt");
    if (reference_bytes.empty()) {
      reference_bytes = bytes;
    } else {
      EXPECT_TRUE(bytes == reference_bytes) << ranks << " ranks changed the file's bytes";
    }
    EXPECT_FALSE(fs::exists(run + "/transport.prtt.partial"));

    const nlohmann::json rep = ReadReport(run);
    const Reference& ref = KernelReference();
    EXPECT_EQ(rep["status"], "ok");
    EXPECT_EQ(rep["ranks"], ranks);
    EXPECT_EQ(rep["rows"], 72);
    EXPECT_EQ(rep["jobs"]["rows_done"], 72);
    EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], 0);
    EXPECT_EQ(rep["jobs"]["done"], JournalJobs(run));
    EXPECT_GE(rep["jobs"]["done"].get<int>(), 72 / 5 + 1);  // jobs of at most 5 rows
    EXPECT_EQ(rep["rays_traced"], ref.stats.rays_traced);
    EXPECT_EQ(rep["texels_skipped_below_horizon"], ref.stats.texels_below_horizon);
    ASSERT_EQ(rep["rank_details"].size(), static_cast<std::size_t>(ranks));
    uint64_t rows_by_ranks = 0;
    for (const auto& rank : rep["rank_details"]) rows_by_ranks += rank["rows"].get<uint64_t>();
    EXPECT_EQ(rows_by_ranks, 72u);
    EXPECT_GE(rep["load_imbalance"].get<double>(), 1.0);
    std::vector<std::string> phases;
    for (const auto& p : rep["phases"]) phases.push_back(p["name"]);
    ASSERT_GE(phases.size(), 3u);  // the compression phase follows (compression_phase.h)
    EXPECT_EQ(std::vector<std::string>(phases.begin(), phases.begin() + 3),
              (std::vector<std::string>{"setup", "brute", "finalize"}));
  }
  // What later stages read without the original files: the scene text and the exact geometry.
  const std::string run = dir + "/np2";
  EXPECT_EQ(ReadWholeFile(run + "/scene.toml"), ReadWholeFile(kScene));
  const SceneGeometry g = ReadSceneGeometryFile(run + "/geometry.prtg");
  const SceneGeometry& ref = KernelReference().geometry;
  ASSERT_EQ(g.meshes.size(), 2u);
  EXPECT_EQ(g.meshes[0].name, "box");
  EXPECT_TRUE(g.meshes[1].is_ground);
  EXPECT_EQ(g.meshes[1].grid_resolution, 8);
  for (std::size_t m = 0; m < 2; ++m) {
    EXPECT_EQ(g.meshes[m].mesh.positions, ref.meshes[m].mesh.positions);
    EXPECT_EQ(g.meshes[m].mesh.normals, ref.meshes[m].mesh.normals);
    EXPECT_EQ(g.meshes[m].mesh.triangles, ref.meshes[m].mesh.triangles);
    EXPECT_EQ(g.meshes[m].albedo, ref.meshes[m].albedo);
  }
}

// The variance sums of two runs: the same bytes (the sums are exact, so the order jobs finish in
// does not matter; docs/farm.md, "Determinism"), and not all zero.
void ExpectSameVariance(const std::string& a, const std::string& b) {
  const TransportVariance va = DecodeTransportVariance(ReadWholeFile(a), a);
  double largest = 0;
  for (std::size_t m = 0; m < va.sums.size(); ++m)
    for (double x : va.MeshSums(m)) largest = std::max(largest, x);
  ASSERT_GT(largest, 0.0);
  EXPECT_TRUE(ReadWholeFile(a) == ReadWholeFile(b)) << a << " and " << b << " differ";
}

// Rows stay where they are computed (docs/farm.md, "Where the rows go"): with 3 ranks sharing the
// run folder every computing rank writes its own rows and variance records, and rank 0 exchanges
// only bookkeeping with the others (envelopes, checksums, counters: at most 64 B per row);
// --rows-via-rank0 sends every row through rank 0. Both give the same transport, compressed
// transport and variance sums, and so does a run whose worker was killed, then resumed (its
// re-used jobs' records come from the killed run's rank logs).
TEST(FarmMpiTest, RanksWriteTheirOwnRowsAndRankZeroSeesOnlyBookkeeping) {
  const std::string dir = WorkDir("in_place");
  const std::string own = dir + "/own", funnel = dir + "/funnel", killed = dir + "/killed";
  ASSERT_EQ(Farm(3, kScene + " --out " + own + kSmallJobs).exit_code, 0);
  ASSERT_EQ(Farm(3, kScene + " --out " + funnel + kSmallJobs + " --rows-via-rank0").exit_code, 0);
  for (const char* file : {"/transport.prtt", "/transport.prtc"})
    EXPECT_TRUE(ReadWholeFile(own + file) == ReadWholeFile(funnel + file)) << file;
  ExpectSameVariance(own + "/transport.variance", funnel + "/transport.variance");
  ExpectEqualsKernels(own + "/transport.prtt");

  const nlohmann::json a = ReadReport(own)["coordinator"];
  EXPECT_TRUE(a["rows_in_place"].get<bool>());
  ASSERT_EQ(a["batches"].size(), 1u);
  const nlohmann::json& brute = a["batches"][0];
  EXPECT_EQ(brute["batch"], "brute");
  EXPECT_EQ(brute["items"], 72);
  EXPECT_GT(brute["bytes_in"].get<uint64_t>(), 0u);
  EXPECT_LE(brute["bytes_per_item"].get<double>(), 64.0);
  // The workers wrote rows (rank 0 computes too) and logged their variance records themselves.
  const nlohmann::json ranks = ReadReport(own)["rank_details"];
  EXPECT_GT(ranks[1]["rows"].get<uint64_t>(), 0u);
  EXPECT_TRUE(fs::exists(own + "/checkpoints/variance.rank-1.log"));

  const nlohmann::json f = ReadReport(funnel)["coordinator"];
  EXPECT_FALSE(f["rows_in_place"].get<bool>());
  EXPECT_GT(f["batches"][0]["bytes_in"].get<uint64_t>(),
            ranks[1]["rows"].get<uint64_t>() * 384u * 4u);  // rank 1's rows at least

  const RunResult k =
      Farm(3, kScene + " --out " + killed + kSmallJobs + " --fail-after-jobs 3 --fail-rank 1");
  EXPECT_NE(k.exit_code, 0) << k.output;
  ASSERT_EQ(Farm(3, kScene + " --out " + killed + kSmallJobs + " --resume").exit_code, 0);
  EXPECT_GT(ReadReport(killed)["jobs"]["reused_from_checkpoints"].get<int>(), 0);
  EXPECT_TRUE(ReadWholeFile(killed + "/transport.prtt") == ReadWholeFile(own + "/transport.prtt"));
  ExpectSameVariance(killed + "/transport.variance", own + "/transport.variance");
}

// Kill, then --resume: the file is the same, and exactly the journaled jobs are re-used.
void KillAndResume(const std::string& name, int ranks, const std::string& kill_args) {
  const std::string run = WorkDir(name) + "/run";
  const RunResult killed = Farm(ranks, kScene + " --out " + run + kSmallJobs + kill_args);
  EXPECT_NE(killed.exit_code, 0) << killed.output;
  EXPECT_FALSE(fs::exists(run + "/transport.prtt"));
  EXPECT_TRUE(fs::exists(run + "/transport.prtt.partial"));
  const int journaled = JournalJobs(run);

  const RunResult again = Farm(ranks, kScene + " --out " + run + kSmallJobs);
  EXPECT_EQ(again.exit_code, kExitUsage) << again.output;  // needs --resume or --force
  EXPECT_NE(again.output.find("--resume"), std::string::npos) << again.output;
  EXPECT_FALSE(fs::exists(run + "/report.json"));  // a refused run leaves the folder alone

  const RunResult resumed = Farm(ranks, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  ExpectEqualsKernels(run + "/transport.prtt");
  const nlohmann::json rep = ReadReport(run);
  EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], journaled);
  EXPECT_EQ(rep["jobs"]["checkpoints_rejected"], 0);
  EXPECT_EQ(rep["jobs"]["rows_done"].get<int>() + rep["jobs"]["rows_reused"].get<int>(), 72);
  EXPECT_EQ(rep["jobs"]["done"].get<int>() + journaled, JournalJobs(run));
  EXPECT_EQ(rep["rays_traced_including_reused"], KernelReference().stats.rays_traced);
}

TEST(FarmMpiTest, CoordinatorKilledMidwayThenResumeRedoesOnlyUnfinishedJobs) {
  // Rank 0 exits abruptly right after its 4th journaled job: the whole run dies.
  const std::string run = WorkDir("kill0") + "/run";
  const RunResult killed =
      Farm(2, kScene + " --out " + run + kSmallJobs + " --fail-after-jobs 4 --fail-rank 0");
  EXPECT_EQ(killed.exit_code, 4) << killed.output;
  EXPECT_EQ(JournalJobs(run), 4);
  const RunResult resumed = Farm(2, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  ExpectEqualsKernels(run + "/transport.prtt");
  const nlohmann::json rep = ReadReport(run);
  EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], 4);
  EXPECT_LT(rep["jobs"]["rows_done"].get<int>(), 72);
  EXPECT_EQ(rep["jobs"]["rows_done"].get<int>() + rep["jobs"]["rows_reused"].get<int>(), 72);
  EXPECT_NE(resumed.output.find("re-used from checkpoints"), std::string::npos);
}

TEST(FarmMpiTest, WorkerKilledMidwayThenResumeGivesTheSameFile) {
  // Rank 0 only coordinates, so the worker surely reaches its 2nd job before the run could end
  // (otherwise, on a loaded machine, rank 0's own thread may finish every job first).
  KillAndResume("kill1", 2, " --coordinator-only --fail-after-jobs 2 --fail-rank 1");
}

TEST(FarmMpiTest, SingleRankKilledMidwayThenResumeGivesTheSameFile) {
  KillAndResume("kill_np1", 1, " --fail-after-jobs 3 --fail-rank 0");
}

// A finished run resumed with the same inputs has nothing to do: every file, the report
// included, stays as it is. Without its rows file (as after --discard-raw) it still has nothing
// to do while its compressed transport is there; without both it traces again, to the same
// bytes.
TEST(FarmMpiTest, ResumingAFinishedRunHasNothingToDoAndKeepsTheBytes) {
  const std::string run = WorkDir("finished") + "/run";
  ASSERT_EQ(Farm(1, kScene + " --out " + run + kSmallJobs).exit_code, 0);
  const std::string before = ReadWholeFile(run + "/transport.prtt");
  const std::string report = ReadWholeFile(run + "/report.json");
  const RunResult r = Farm(1, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("nothing to do"), std::string::npos) << r.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtt") == before);
  EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);
  fs::remove(run + "/transport.prtt");
  const RunResult discarded = Farm(1, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(discarded.exit_code, 0) << discarded.output;
  EXPECT_NE(discarded.output.find("nothing to do"), std::string::npos) << discarded.output;
  EXPECT_FALSE(fs::exists(run + "/transport.prtt"));
  fs::remove(run + "/transport.prtc");
  const RunResult again = Farm(2, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtt") == before);
  EXPECT_EQ(ReadReport(run)["stages"][0]["status"], "ran");
}

TEST(FarmMpiTest, HungWorkerEndsTheRunWithExitCode4AndAReport) {
  const std::string run = WorkDir("hang") + "/run";
  const RunResult r = Farm(2, kScene + " --out " + run + kSmallJobs +
                                  " --fail-after-jobs 1 --fail-rank 1 --fail-mode hang "
                                  "--rank-timeout 1");
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("rank 1 has not returned its job"), std::string::npos) << r.output;
  const nlohmann::json rep = ReadReport(run);
  EXPECT_EQ(rep["status"], "failed");
  EXPECT_EQ(rep["exit_code"], 4);
  EXPECT_EQ(rep["jobs"]["done"], JournalJobs(run));  // what was counted is on disk
}

struct BadCase {
  int ranks;
  std::string args;
  int exit_code;
  std::string message;
};

void ExpectExitCodes(const std::vector<BadCase>& cases) {
  for (const BadCase& c : cases) {
    const RunResult r = Farm(c.ranks, c.args);
    EXPECT_EQ(r.exit_code, c.exit_code) << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.message), std::string::npos) << c.args << "\n" << r.output;
  }
}

TEST(FarmMpiTest, BadInputAndUnwritableOutputGiveExitCodes2And3) {
  const std::string dir = WorkDir("bad_input");
  std::ofstream(dir + "/invalid.toml") << "[scene]\nn = 12\n";
  std::ofstream(dir + "/nomesh.toml") << "[[mesh]]\npath = \"missing.off\"\n";
  std::ofstream(dir + "/a_file") << "not a folder";
  ExpectExitCodes({
      {2, dir + "/missing.toml --out " + dir + "/r1", 2, "missing.toml: scene file not found"},
      {1, dir + "/invalid.toml --out " + dir + "/r2", 2, "not a power of two"},
      {1, dir + "/nomesh.toml --out " + dir + "/r3", 2, "missing.off"},
      {2, kScene + " --out " + dir + "/a_file/run", 3, "cannot create the run folder"},
  });
  EXPECT_FALSE(fs::exists(dir + "/r1"));  // nothing is created for a scene that does not load
}

// ------------------------------------------------------------------------------ sparse method

// 264 samples (a box on a 16×16 ground, n = 8), method = "sparse" in the scene.
const std::string kSparseScene = std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml";
// Jobs of 7 items (fewer in each phase's guided tail): with one rank the job sequence is fixed.
const std::string kSparseJobs =
    " --initial-job-rows 7 --max-job-rows 7 --rows-per-block 16 --log-interval 0.2";

struct SparseReference {
  std::vector<float> rows;
  SparseReport report;
};

// The in-process driver (RunSparsePrecomputation) on the same scene and settings.
const SparseReference& SparseKernelReference() {
  static const SparseReference ref = [] {
    SparseReference r;
    const SceneDescription scene = LoadSceneFile(kSparseScene);
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    const std::vector<SpatialSample> samples = SpatialSamplesOf(geometry);
    const EmbreeScene embree(geometry);
    TransportSamplerOptions options;
    options.rays_per_texel = scene.sampling.rays_per_texel;
    options.seed = scene.sampling.seed;
    const TransportSampler sampler(embree, scene.cubemap_n, options);
    const SparsePlan plan = PlanFromSettings(scene.sparse, geometry.diagonal(), scene.cubemap_n);
    r.rows = RunSparsePrecomputation(sampler, samples, plan, r.report);
    return r;
  }();
  return ref;
}

void ExpectEqualsSparseReference(const std::string& run) {
  const SparseReference& ref = SparseKernelReference();
  TransportFileReader reader(run + "/transport.prtt");
  ASSERT_EQ(reader.info().rows, 264u);
  ASSERT_EQ(reader.info().cols(), 384u);
  EXPECT_EQ(reader.FindCorruptBlock(), -1);
  std::vector<float> rows(ref.rows.size());
  reader.ReadRows(0, reader.info().rows, rows.data());
  ASSERT_EQ(std::memcmp(rows.data(), ref.rows.data(), rows.size() * sizeof(float)), 0)
      << "the farmed sparse rows differ from RunSparsePrecomputation's";
}

// Journal lines per sparse phase, in journal order.
std::vector<std::string> JournalPhases(const std::string& run) {
  std::ifstream in(run + "/checkpoints/journal.txt");
  std::string line;
  std::vector<std::string> phases;
  while (std::getline(in, line)) {
    if (line.rfind("sjob ", 0) != 0) continue;
    std::istringstream words(line);
    std::string tag, phase;
    words >> tag >> phase;
    phases.push_back(phase);
  }
  return phases;
}

TEST(FarmMpiSparseTest, OneTwoAndThreeRanksGiveTheInProcessDriversBytes) {
  const std::string dir = WorkDir("sparse_ranks");
  const SparseReference& ref = SparseKernelReference();
  // The scene says method = "sparse": no --method needed.
  for (int ranks : {1, 2, 3}) {
    const std::string run = dir + "/np" + std::to_string(ranks);
    const RunResult r = Farm(ranks, kSparseScene + " --out " + run + kSparseJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("[sparse-reconstruct]"), std::string::npos) << r.output;
    ExpectEqualsSparseReference(run);
    const nlohmann::json rep = ReadReport(run);
    EXPECT_EQ(rep["method"], "sparse");
    EXPECT_EQ(rep["ranks"], ranks);
    const nlohmann::json& sp = rep["sparse"];
    EXPECT_EQ(sp["dense_initial"], ref.report.dense_initial);
    EXPECT_EQ(sp["dense_by_rank"], ref.report.dense_by_rank);
    EXPECT_EQ(sp["dense_fallback"], ref.report.dense_fallback);
    EXPECT_EQ(sp["sparse"], ref.report.sparse);
    EXPECT_EQ(sp["sparse"].get<uint64_t>() + sp["dense_total"].get<uint64_t>(), 264u);
    EXPECT_GT(ref.report.sparse, 100u);        // most vertices are reconstructed,
    EXPECT_GT(ref.report.dense_fallback, 0u);  // some fall back
    EXPECT_EQ(sp["fallbacks"]["too_few_neighbors"],
              ref.report.sparse_stats.fallback_too_few_neighbors);
    EXPECT_EQ(sp["fallbacks"]["solve_failed"], ref.report.sparse_stats.fallback_solve_failed);
    EXPECT_EQ(sp["fallbacks"]["poor_fit"], ref.report.sparse_stats.fallback_poor_fit);
    EXPECT_EQ(sp["l1_solver"]["lars"], ref.report.sparse_stats.solved_lars);
    EXPECT_EQ(sp["l1_solver"]["admm"], ref.report.sparse_stats.solved_admm);
    EXPECT_EQ(sp["l1_solver"]["zero"], ref.report.sparse_stats.zero_systems);
    EXPECT_DOUBLE_EQ(sp["sampled_fraction"].get<double>(), ref.report.SampledFraction());
    EXPECT_LT(sp["sampled_fraction"].get<double>(), 0.5);
    EXPECT_EQ(rep["rays_traced"], ref.report.dense_angular.trace.rays_traced +
                                      ref.report.sparse_stats.trace.rays_traced);
    std::vector<std::string> phases;
    for (const auto& p : sp["phases"]) phases.push_back(p["name"]);
    EXPECT_EQ(phases,
              (std::vector<std::string>{"dense-initial", "rank-1", "dense-rank-1", "rank-2",
                                        "dense-rank-2", "rank-3", "dense-rank-3",
                                        "sparse-reconstruct", "cross-validate", "dense-fallback"}));
    // The reconstruction's cross-validation: every vertex of the initial dense set (fewer than
    // 400 here), reconstructed or fallen back; its rays are not T's; accuracy.json adds its
    // error to the rays' (the total is at least either).
    const nlohmann::json& cv = sp["cross_validation"];
    EXPECT_EQ(cv["reconstructed"].get<uint64_t>() + cv["fallbacks"].get<uint64_t>(),
              ref.report.dense_initial);
    EXPECT_GT(cv["reconstructed"].get<uint64_t>(), 0u);
    const nlohmann::json acc = nlohmann::json::parse(ReadWholeFile(run + "/accuracy.json"));
    ASSERT_TRUE(acc.contains("reconstruction") && acc.contains("total")) << acc.dump();
    EXPECT_EQ(acc["reconstruction"]["cross_validated"], cv["reconstructed"]);
    for (std::size_t l = 0; l < acc["total"]["environments"].size(); ++l) {
      const double mc = acc["monte_carlo"]["environments"][l]["relative_rms"].get<double>();
      const double re = acc["reconstruction"]["environments"][l]["relative_rms"].get<double>();
      const double total = acc["total"]["environments"][l]["relative_rms"].get<double>();
      EXPECT_NEAR(total * total, mc * mc + re * re, 1e-12);
      EXPECT_GT(re, 0.0);
    }
    std::vector<std::string> top;
    for (const auto& p : rep["phases"]) top.push_back(p["name"]);
    ASSERT_GE(top.size(), 3u);  // later phases (compression) may follow
    EXPECT_EQ(std::vector<std::string>(top.begin(), top.begin() + 3),
              (std::vector<std::string>{"setup", "sparse", "finalize"}));
    EXPECT_EQ(rep["jobs"]["done"], JournalPhases(run).size());
    EXPECT_EQ(rep["jobs"]["rows_done"], 264);
    ASSERT_EQ(rep["rank_details"].size(), static_cast<std::size_t>(ranks));
    EXPECT_GE(rep["load_imbalance"].get<double>(), 1.0);
  }
  // Resuming the finished single-rank run has nothing to do and keeps the bytes and report.
  {
    const std::string run = dir + "/np1";
    const std::string before = ReadWholeFile(run + "/transport.prtt");
    const std::string report = ReadWholeFile(run + "/report.json");
    const RunResult r = Farm(1, kSparseScene + " --out " + run + kSparseJobs + " --resume");
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_NE(r.output.find("nothing to do"), std::string::npos) << r.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtt") == before);
    EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);
    EXPECT_EQ(ReadReport(run)["sparse"]["sparse"], ref.report.sparse);
  }
  // --method brute overrides the scene's method.
  const std::string run = dir + "/brute";
  const RunResult r = Farm(1, kSparseScene + " --method brute --out " + run + kSparseJobs);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(ReadReport(run)["method"], "brute");
  EXPECT_FALSE(ReadReport(run).contains("sparse"));
}

// Rank `fail_rank` dies after `fail_after` journaled jobs (which must land in `phase`); the
// resumed run re-uses exactly the journaled jobs and writes the in-process driver's bytes.
void SparseKillAndResume(const std::string& name, int ranks, int fail_rank, int fail_after,
                         const std::string& phase) {
  const std::string run = WorkDir(name) + "/run";
  const RunResult killed =
      Farm(ranks, kSparseScene + " --out " + run + kSparseJobs + " --fail-after-jobs " +
                      std::to_string(fail_after) + " --fail-rank " + std::to_string(fail_rank));
  EXPECT_EQ(killed.exit_code, 4) << killed.output;
  EXPECT_FALSE(fs::exists(run + "/transport.prtt"));
  const std::vector<std::string> journaled = JournalPhases(run);
  ASSERT_FALSE(journaled.empty());
  if (!phase.empty()) {
    EXPECT_EQ(journaled.back(), phase) << "the kill landed elsewhere";
  }
  if (fail_rank == 0) {
    EXPECT_EQ(journaled.size(), static_cast<std::size_t>(fail_after));
  }

  const RunResult resumed = Farm(ranks, kSparseScene + " --out " + run + kSparseJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  ExpectEqualsSparseReference(run);
  const nlohmann::json rep = ReadReport(run);
  EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], journaled.size());
  EXPECT_EQ(rep["jobs"]["checkpoints_rejected"], 0);
  EXPECT_EQ(rep["jobs"]["rows_done"].get<int>() + rep["jobs"]["rows_reused"].get<int>(), 264);
  EXPECT_EQ(rep["jobs"]["done"].get<std::size_t>() + journaled.size(), JournalPhases(run).size());
  const SparseReference& ref = SparseKernelReference();
  EXPECT_EQ(rep["sparse"]["sparse"], ref.report.sparse);
  EXPECT_DOUBLE_EQ(rep["sparse"]["sampled_fraction"].get<double>(), ref.report.SampledFraction());
  EXPECT_EQ(rep["rays_traced_including_reused"],
            ref.report.dense_angular.trace.rays_traced + ref.report.sparse_stats.trace.rays_traced);
}

// The number of journaled jobs before the first job of `phase` in a whole single-rank run
// (its job sequence is fixed), plus `offset`.
int SingleRankJobsBefore(const std::string& phase, int offset) {
  static const std::vector<std::string> phases = [] {
    const std::string probe = WorkDir("sparse_probe") + "/run";
    const RunResult r = Farm(1, kSparseScene + " --out " + probe + kSparseJobs);
    EXPECT_EQ(r.exit_code, 0) << r.output;
    return JournalPhases(probe);
  }();
  const auto at = std::find(phases.begin(), phases.end(), phase);
  EXPECT_NE(at, phases.end()) << phase;
  return static_cast<int>(at - phases.begin()) + offset;
}

// Rows in place with the sparse method (docs/farm.md, "Where the rows go"): with 3 ranks the
// workers write dense rows (T, visibility and features, downsampled rows) and reconstructed rows
// themselves and read the rows their jobs need from the run folder; rank 0's jobs carry sample
// ids and its results checksums, counters and compact combination records. The files are those
// of --rows-via-rank0, where every row passes through rank 0.
TEST(FarmMpiSparseTest, RowsInPlaceGiveTheBytesOfRowsThroughRankZero) {
  const std::string dir = WorkDir("sparse_in_place");
  const std::string own = dir + "/own", funnel = dir + "/funnel";
  ASSERT_EQ(Farm(3, kSparseScene + " --out " + own + kSparseJobs).exit_code, 0);
  ASSERT_EQ(
      Farm(3, kSparseScene + " --out " + funnel + kSparseJobs + " --rows-via-rank0").exit_code, 0);
  ExpectEqualsSparseReference(own);
  for (const char* file : {"/transport.prtt", "/transport.prtc", "/sparse/combination.bin",
                           "/sparse/cross_validation.bin"})
    EXPECT_TRUE(ReadWholeFile(own + file) == ReadWholeFile(funnel + file)) << file;
  ExpectSameVariance(own + "/transport.variance", funnel + "/transport.variance");
  const nlohmann::json a = ReadReport(own), f = ReadReport(funnel);
  EXPECT_EQ(a["sparse"]["dense_rows_shipped"], 0);
  EXPECT_GT(f["sparse"]["dense_rows_shipped"].get<uint64_t>(), 0u);
  const std::size_t row_bytes = 384 * 4;
  for (const auto& batch : a["coordinator"]["batches"]) {
    // Ids, neighbour lists, checksums, counters, combinations: far below a row per item.
    EXPECT_LT(batch["bytes_per_item"].get<double>(), 0.5 * row_bytes) << batch.dump();
  }
  uint64_t in_place = 0, through = 0;
  for (const auto& b : a["coordinator"]["batches"])
    in_place += b["bytes_in"].get<uint64_t>() + b["bytes_out"].get<uint64_t>();
  for (const auto& b : f["coordinator"]["batches"])
    through += b["bytes_in"].get<uint64_t>() + b["bytes_out"].get<uint64_t>();
  EXPECT_LT(10 * in_place, through) << in_place << " vs " << through;
}

TEST(FarmMpiSparseTest, SingleRankKilledInTheDenseAndRankPhasesThenResume) {
  SparseKillAndResume("sparse_kill_initial", 1, 0, 1, "dense-initial");
  SparseKillAndResume("sparse_kill_rank", 1, 0, SingleRankJobsBefore("rank-2", 2), "rank-2");
  SparseKillAndResume("sparse_kill_dense_rank", 1, 0, SingleRankJobsBefore("dense-rank-1", 1),
                      "dense-rank-1");
}

TEST(FarmMpiSparseTest, SingleRankKilledInTheSparseAndFallbackPhasesThenResume) {
  SparseKillAndResume("sparse_kill_sparse", 1, 0, SingleRankJobsBefore("sparse-reconstruct", 3),
                      "sparse-reconstruct");
  SparseKillAndResume("sparse_kill_fallback", 1, 0, SingleRankJobsBefore("dense-fallback", 1),
                      "dense-fallback");
}

TEST(FarmMpiSparseTest, WorkerOrCoordinatorKilledWithTwoRanksThenResume) {
  SparseKillAndResume("sparse_kill_worker", 2, 1, 12, "");
  SparseKillAndResume("sparse_kill_coordinator", 2, 0, 30, "");
}

// The rest of the command line is tested without MPI in farm/farm_options_test.cpp.
TEST(FarmMpiTest, UsageErrorsHelpAndForeignCheckpoints) {
  const std::string dir = WorkDir("usage");
  ExpectExitCodes({
      {2, "--no-such-option", 1, "--no-such-option"},
      {1, "--help", 0, "Exit codes: 0 ok, 1 usage error"},
  });
  // Checkpoints of a run with other sampling inputs are never mixed with new rows: --resume
  // traces again from zero, says why, and writes what a fresh run with the new inputs writes.
  // --seed overrides the scene's (another estimate of the same T) and is such an input.
  const std::string run = dir + "/mixed";
  ASSERT_EQ(Farm(1, kScene + " --out " + run + kSmallJobs + " --no-compress").exit_code, 0);
  const std::string seed3 = ReadWholeFile(run + "/transport.prtt");
  const RunResult seeded =
      Farm(2, kScene + " --out " + run + kSmallJobs + " --no-compress --seed 7 --resume");
  ASSERT_EQ(seeded.exit_code, 0) << seeded.output;
  EXPECT_NE(seeded.output.find("stage rows: ran (changed: seed 3 -> 7)"), std::string::npos)
      << seeded.output;
  const nlohmann::json rep = ReadReport(run);
  EXPECT_EQ(rep["seed"], 7);
  EXPECT_EQ(rep["stages"][0]["status"], "ran");
  EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], 0);
  const std::string other = dir + "/seed7";
  ASSERT_EQ(Farm(1, kScene + " --out " + other + kSmallJobs + " --no-compress --seed 7").exit_code,
            0);
  EXPECT_EQ(ReadReport(other)["seed"], 7);
  EXPECT_TRUE(ReadWholeFile(other + "/transport.prtt") == ReadWholeFile(run + "/transport.prtt"));
  EXPECT_FALSE(ReadWholeFile(other + "/transport.prtt") == seed3);
  const RunResult rays =
      Farm(1, kScene + " --out " + run + kSmallJobs + " --no-compress --rays-per-texel 9 --resume");
  ASSERT_EQ(rays.exit_code, 0) << rays.output;
  EXPECT_NE(rays.output.find("rays_per_texel 4 -> 9"), std::string::npos) << rays.output;
  EXPECT_EQ(ReadReport(run)["rays_per_texel"], 9);
}

}  // namespace
}  // namespace prt
