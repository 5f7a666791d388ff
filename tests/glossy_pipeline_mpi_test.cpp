// The glossy pipeline end to end (docs/farm.md "Visibility job", docs/prtpack-format.md VISB,
// docs/viewer.md "Glossy assets"): tests/data/glossy_tiny.toml farmed as visibility cubemaps
// with `mpirun -np 1` and `-np 2` gives byte-identical visibility.prtv equal to the worker
// kernel's encoding; a worker killed mid-way and --resume give the same bytes without redoing
// the journaled jobs; prt-pack packs the run, inspect shows the visibility, and prt-view renders
// the pack as a glossy asset into a PNG.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "formats/visibility_blocks.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/environment_io.h"
#include "vocabulary/envmap.h"
#include "vocabulary/scene.h"
#include "vocabulary/sky.h"
#include "worker/embree_scene.h"
#include "worker/visibility_sampler.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(PRT_TESTS_DATA_DIR) + "/glossy_tiny.toml";
const std::string kSmallJobs = " --max-job-rows 5 --log-interval 0.2";

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// Runs a command, returning its exit code and output.
int RunCommand(const std::string& command, std::string* output) {
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  char buf[4096];
  std::size_t n;
  output->clear();
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) output->append(buf, n);
  const int status = ::pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// The maps as the worker kernel computes them in one process.
const std::string& KernelVisibility() {
  static const std::string bytes = [] {
    const SceneDescription scene = LoadSceneFile(kScene);
    const SceneGeometry geometry = BuildSceneGeometry(scene);
    const EmbreeScene embree(geometry);
    const VisibilitySampler sampler(embree, VisibilitySamplerOptions{scene.visibility.n, 1, 1});
    const std::vector<uint8_t> b =
        EncodeVisibilityBlocks(sampler.ComputeBlocks(SpatialSamplesOf(geometry)));
    return std::string(b.begin(), b.end());
  }();
  return bytes;
}

int JournalJobs(const std::string& run) {
  std::ifstream in(run + "/checkpoints/journal.txt");
  std::string line;
  int jobs = 0;
  while (std::getline(in, line)) jobs += line.rfind("sjob visibility ", 0) == 0 ? 1 : 0;
  return jobs;
}

TEST(GlossyPipeline, OneAndTwoRanksGiveTheKernelsVisibilityBytes) {
  for (int ranks : {1, 2}) {
    const std::string run = WorkDir("glossy_np" + std::to_string(ranks));
    const testing::RunResult r = testing::RunPrtFarm(ranks, kScene + " --out " + run + kSmallJobs);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    ASSERT_TRUE(fs::exists(run + "/visibility.prtv")) << r.output;
    EXPECT_EQ(ReadWholeFile(run + "/visibility.prtv"), KernelVisibility()) << ranks << " ranks";
    EXPECT_FALSE(fs::exists(run + "/transport.prtc"));  // no transport, no compression phase
    const nlohmann::json rep = nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
    EXPECT_EQ(rep["status"], "ok");
    EXPECT_EQ(rep["method"], "visibility");
    EXPECT_EQ(rep["cubemap_n"], 16);
    EXPECT_EQ(rep["visibility"]["vertices"], 72);
    EXPECT_EQ(rep["visibility"]["raw_bytes"], 72 * 6 * 16 * 16 / 8);
    EXPECT_EQ(rep["visibility"]["encoded_bytes"], KernelVisibility().size());
    EXPECT_GT(rep["rays_traced"].get<uint64_t>(), 0u);
    EXPECT_GE(JournalJobs(run), 72 / 5);
  }
}

TEST(GlossyPipeline, KilledMidwayThenResumeGivesTheSameBytes) {
  // Rank 0 exits abruptly right after its 3rd journaled job: the whole run dies.
  const std::string run = WorkDir("glossy_kill");
  const testing::RunResult killed = testing::RunPrtFarm(
      2, kScene + " --out " + run + kSmallJobs + " --fail-after-jobs 3 --fail-rank 0");
  EXPECT_EQ(killed.exit_code, 4) << killed.output;
  EXPECT_FALSE(fs::exists(run + "/visibility.prtv"));
  EXPECT_EQ(JournalJobs(run), 3);
  const testing::RunResult refused = testing::RunPrtFarm(2, kScene + " --out " + run + kSmallJobs);
  EXPECT_EQ(refused.exit_code, 1) << refused.output;  // needs --resume or --force
  const testing::RunResult resumed =
      testing::RunPrtFarm(2, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_EQ(ReadWholeFile(run + "/visibility.prtv"), KernelVisibility());
  const nlohmann::json rep = nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
  EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], 3);
  EXPECT_EQ(rep["jobs"]["checkpoints_rejected"], 0);
  EXPECT_LT(rep["jobs"]["rows_done"].get<int>(), 72);
  EXPECT_EQ(rep["jobs"]["rows_done"].get<int>() + rep["jobs"]["rows_reused"].get<int>(), 72);
  // A finished run resumed has nothing to do: the maps and the report stay as they are.
  const std::string report = ReadWholeFile(run + "/report.json");
  const testing::RunResult again =
      testing::RunPrtFarm(1, kScene + " --out " + run + kSmallJobs + " --resume");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("nothing to do"), std::string::npos) << again.output;
  EXPECT_EQ(ReadWholeFile(run + "/visibility.prtv"), KernelVisibility());
  EXPECT_EQ(ReadWholeFile(run + "/report.json"), report);
}

TEST(GlossyPipeline, FarmPackAndViewAGlossyImage) {
  const std::string dir = WorkDir("glossy_pipeline");
  const std::string run = dir + "/run";
  const testing::RunResult r = testing::RunPrtFarm(2, kScene + " --out " + run + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::string out;
  const std::string pack = dir + "/glossy.prtpack";
  ASSERT_EQ(RunCommand(std::string(PRT_PACK_EXE) + " pack " + run + " --out " + pack, &out), 0)
      << out;
  ASSERT_EQ(RunCommand(std::string(PRT_PACK_EXE) + " inspect " + pack, &out), 0) << out;
  EXPECT_NE(out.find("visibility: 2 VISB sections"), std::string::npos) << out;
  EXPECT_NE(out.find("materials: box phong"), std::string::npos) << out;
  ASSERT_EQ(RunCommand(std::string(PRT_PACK_EXE) + " verify " + pack, &out), 0) << out;
  EXPECT_NE(out.find("72 visibility maps decoded"), std::string::npos) << out;

  SkySunParams sky;
  sky.sun_direction = {0.3, 0.7, -0.6};
  sky.sun_angular_radius = 0.1;
  const std::string env = dir + "/sky.exr";
  WriteEnvironmentExr(MakeSkyWithSun(EnvmapLayout::kLatLong, 64, 32, sky), env);
  const std::string png = dir + "/glossy.png", npy = dir + "/glossy.npy";
  ASSERT_EQ(RunCommand(std::string(PRT_VIEW_EXE) + " " + pack + " --env " + env + " --out " + png +
                           " --radiance-out " + npy,
                       &out),
            0)
      << out;
  EXPECT_NE(out.find("triple products"), std::string::npos) << out;
  ASSERT_TRUE(fs::exists(png));
  EXPECT_GT(fs::file_size(png), 200u);
  // 72 vertices × 3 float32 after the .npy header.
  EXPECT_EQ(fs::file_size(npy) % 4, 0u);
  EXPECT_GT(fs::file_size(npy), 72u * 3 * 4);
}

}  // namespace
}  // namespace prt
