// The farm's determinism guarantee (docs/farm.md, "Determinism"): every file a run writes, other
// than the few listed in kNotCompared, is byte-identical for any rank count (1, 2, 3 and 8
// oversubscribed), any job split, rows written by the ranks or sent through rank 0, and after a
// kill and a resume (with another rank count). The whole run folder is listed recursively and
// compared file by file, so a file a future phase adds is compared too, or fails the test when
// one run has it and another has not.
//
// Scenes: tests/data/tiny.toml with a 24×24 ground (584 rows: enough that the variance sums of the
// old order-dependent reduction differed) farmed by brute force with one bounce (gathering), and
// tests/data/sparse_tiny.toml (the sparse method) with one bounce (gathering at the dense
// vertices, combinations elsewhere); without a kill, the glossy visibility job and an image
// (samples = "camera") by the sparse method with a path-traced bounce.
#include <fnmatch.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

// The files not compared (fnmatch patterns, relative to the run folder), and why each may differ.
// Nothing else is excluded: keep this list short and every entry justified.
struct NotCompared {
  const char* pattern;
  const char* why;
};
const NotCompared kNotCompared[] = {
    {"report.json", "this run's wall times, rank count and per-rank figures"},
    {"checkpoints/journal.txt", "a line per job in the order jobs finished, with their timings"},
    {"checkpoints/indirect-journal.txt", "the same for the bounce jobs"},
    {"checkpoints/variance.log",
     "a record per job in the order jobs finished (their exact sum, transport.variance, is "
     "compared)"},
    {"checkpoints/variance.rank-*.log", "a computing rank's own records (rows in place)"},
    {"visibility.chunks",
     "the visibility job's results in the order jobs finished, a checkpoint (visibility.prtv, "
     "compared, is assembled from it in sample order)"},
};

bool Compared(const std::string& relative) {
  for (const NotCompared& n : kNotCompared)
    if (::fnmatch(n.pattern, relative.c_str(), FNM_PATHNAME) == 0) return false;
  return true;
}

// Every regular file under `run` (recursively) that is compared, by its path relative to `run`.
std::map<std::string, std::string> CompareableFiles(const std::string& run) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(run)) {
    if (e.is_directory()) continue;
    const std::string relative = fs::relative(e.path(), run).generic_string();
    if (!e.is_regular_file()) {
      files[relative] = "(not a regular file)";
      continue;
    }
    if (Compared(relative)) files[relative] = ReadWholeFile(e.path().string());
  }
  return files;
}

// The differences between two run folders, one line per file: a file only one of them has, or
// the number of bytes that differ (and where the first is). Empty when they are the same.
std::vector<std::string> Differences(const std::string& a, const std::string& b) {
  const std::map<std::string, std::string> fa = CompareableFiles(a), fb = CompareableFiles(b);
  std::vector<std::string> out;
  for (const auto& [name, bytes] : fa) {
    const auto it = fb.find(name);
    if (it == fb.end()) {
      out.push_back(name + ": only in " + a);
      continue;
    }
    const std::string& other = it->second;
    if (bytes == other) continue;
    std::size_t differing =
        std::max(bytes.size(), other.size()) - std::min(bytes.size(), other.size());
    std::size_t first = std::string::npos;
    for (std::size_t i = 0; i < std::min(bytes.size(), other.size()); ++i) {
      if (bytes[i] != other[i]) {
        ++differing;
        if (first == std::string::npos) first = i;
      }
    }
    if (first == std::string::npos) first = std::min(bytes.size(), other.size());
    out.push_back(name + ": " + std::to_string(differing) + " of " +
                  std::to_string(std::max(bytes.size(), other.size())) +
                  " bytes differ (the first at byte " + std::to_string(first) + ")");
  }
  for (const auto& [name, bytes] : fb)
    if (!fa.count(name)) out.push_back(name + ": only in " + b);
  return out;
}

void ExpectSameFiles(const std::string& reference, const std::string& run,
                     const std::string& what) {
  const std::vector<std::string> diff = Differences(reference, run);
  std::string text;
  for (const std::string& d : diff) text += "\n  " + d;
  EXPECT_TRUE(diff.empty()) << what << " differs from the reference run:" << text;
}

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("determinism_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

int ReusedJobs(const std::string& run) {
  const nlohmann::json r = nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
  return r["jobs"]["reused_from_checkpoints"].get<int>();
}

struct Variant {
  std::string name;
  int ranks;
  std::string args;  // job split and the like
};

// Farms `scene` (with `common` arguments) as each variant and compares every run folder with the
// first's; then (kill_ranks > 0) a run killed by `kill` on `kill_ranks` ranks, resumed on
// `resume_ranks`.
void ExpectTheSameFilesForEveryVariant(const std::string& dir, const std::string& scene,
                                       const std::string& common,
                                       const std::vector<Variant>& variants, int kill_ranks,
                                       const std::string& kill, int resume_ranks) {
  const std::string reference = dir + "/" + variants.front().name;
  for (const Variant& v : variants) {
    const std::string run = dir + "/" + v.name;
    const testing::RunResult r =
        testing::RunPrtFarm(v.ranks, scene + " --out " + run + common + v.args);
    ASSERT_EQ(r.exit_code, 0) << v.name << ":\n" << r.output;
    if (run != reference) ExpectSameFiles(reference, run, v.name);
  }
  if (kill_ranks == 0) return;
  const std::string run = dir + "/killed";
  const testing::RunResult killed =
      testing::RunPrtFarm(kill_ranks, scene + " --out " + run + common + kill);
  ASSERT_NE(killed.exit_code, 0) << killed.output;
  EXPECT_TRUE(fs::exists(run + "/transport.prtt.partial")) << "killed too late";
  const testing::RunResult resumed =
      testing::RunPrtFarm(resume_ranks, scene + " --out " + run + common + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_GT(ReusedJobs(run), 0);
  ExpectSameFiles(reference, run, "killed, then resumed");
}

TEST(RunFolderDeterminismMpiTest, BruteWithABounceGivesTheSameFilesForAnyRanksSplitOrResume) {
  const std::string dir = WorkDir("brute");
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/tiny.toml");
  testing::ReplaceOnce(text, "resolution = 8", "resolution = 24");
  const std::string scene = testing::WriteTestScene(text, dir + "/tiny24.toml");
  ExpectTheSameFilesForEveryVariant(dir, scene, " --quiet --bounces 1 --rows-per-block 64",
                                    {{"np1", 1, " --max-job-rows 5"},
                                     {"np2", 2, " --initial-job-rows 3 --max-job-rows 11"},
                                     {"np2_via_rank0", 2, " --max-job-rows 9 --rows-via-rank0"},
                                     {"np3", 3, ""},  // the planner's own job sizes
                                     {"np8", 8, " --max-job-rows 7"}},
                                    3, " --max-job-rows 6 --fail-after-jobs 5 --fail-rank 1", 2);
}

TEST(RunFolderDeterminismMpiTest, SparseWithABounceGivesTheSameFilesForAnyRanksSplitOrResume) {
  const std::string dir = WorkDir("sparse");
  const std::string scene = std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml";
  ExpectTheSameFilesForEveryVariant(dir, scene, " --quiet --bounces 1 --rows-per-block 64",
                                    {{"np1", 1, " --max-job-rows 5"},
                                     {"np2", 2, " --initial-job-rows 2 --max-job-rows 9"},
                                     {"np3", 3, ""},
                                     {"np8", 8, " --max-job-rows 7"}},
                                    2, " --max-job-rows 6 --fail-after-jobs 8 --fail-rank 0", 3);
}

// The other kinds of run, without a kill (their resumes have tests of their own): the glossy
// visibility job, and an image (samples = "camera") by the sparse method with a path-traced
// bounce.
TEST(RunFolderDeterminismMpiTest, VisibilityJobAndPathTracedImageGiveTheSameFilesForAnyRanks) {
  const std::string dir = WorkDir("other");
  ExpectTheSameFilesForEveryVariant(
      dir + "/vis", std::string(PRT_TESTS_DATA_DIR) + "/glossy_tiny.toml", " --quiet",
      {{"np1", 1, " --max-job-rows 5"}, {"np3", 3, " --max-job-rows 9"}, {"np8", 8, ""}}, 0, "", 0);
  std::string text = ReadWholeFile(std::string(PRT_TESTS_DATA_DIR) + "/sparse_tiny.toml");
  testing::ReplaceOnce(text, "[scene]\n", "[scene]\nsamples = \"camera\"\n");
  testing::ReplaceOnce(text, "[sampling]\n",
                       "[camera]\neye = [0.4, 1.6, 3.2]\ntarget = [0.0, 0.2, 0.0]\nfov = 30.0\n"
                       "width = 24\nheight = 16\n\n[sampling]\nbounces = 1\nestimator = \"path\"\n"
                       "gather_paths = 4\n");
  const std::string scene = testing::WriteTestScene(text, dir + "/image.toml");
  ExpectTheSameFilesForEveryVariant(
      dir + "/image", scene, " --quiet",
      {{"np1", 1, " --max-job-rows 5"}, {"np3", 3, " --max-job-rows 9"}, {"np8", 8, ""}}, 0, "", 0);
}

// The comparison itself: a changed byte, a file only one run has and a file in a sub-folder are
// each found; the excluded files are not compared.
TEST(RunFolderDeterminismMpiTest, TheComparisonFindsEveryDifferenceOutsideTheExcludedFiles) {
  const std::string dir = WorkDir("compare");
  for (const char* run : {"/a", "/b"}) {
    fs::create_directories(dir + run + "/checkpoints");
    fs::create_directories(dir + run + "/deep/er");
    WriteFileDurably(dir + run + "/transport.variance", std::string(100, 'x'));
    WriteFileDurably(dir + run + "/deep/er/new.bin", "same");
    WriteFileDurably(dir + run + "/report.json", std::string(run));
    WriteFileDurably(dir + run + "/checkpoints/variance.rank-" + std::string(run + 1) + ".log",
                     "records");
  }
  EXPECT_TRUE(Differences(dir + "/a", dir + "/b").empty());
  std::string changed(100, 'x');
  changed[42] = 'y';
  changed[43] = 'y';
  WriteFileDurably(dir + "/b/transport.variance", changed);
  WriteFileDurably(dir + "/b/deep/er/new.bin", "sam3");
  WriteFileDurably(dir + "/b/checkpoints/journal.bin", "a file not in the list");
  const std::vector<std::string> d = Differences(dir + "/a", dir + "/b");
  ASSERT_EQ(d.size(), 3u);
  EXPECT_EQ(d[0], "deep/er/new.bin: 1 of 4 bytes differ (the first at byte 3)");
  EXPECT_EQ(d[1], "transport.variance: 2 of 100 bytes differ (the first at byte 42)");
  EXPECT_EQ(d[2], "checkpoints/journal.bin: only in " + dir + "/b");
}

}  // namespace
}  // namespace prt
