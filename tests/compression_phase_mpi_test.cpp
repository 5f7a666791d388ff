// prt-farm's compression phase end to end under mpirun (farm/compression_phase.h,
// docs/farm-compression.md): on the tiny scene of tests/data, run/transport.prtc is byte-identical
// to the in-process compressor (CompressTransport on the rows of transport.prtt, the scene's
// [compression] settings, the domain of geometry.prtg) for 1, 2 and 3 ranks, with a budget that
// forces every rank to spill and with the default budget; the scheme override is honoured; the
// raw matrix is removed unless --keep-raw; an interrupted compression is redone by --resume
// without redoing any job, and --resume on a finished, compressed run does nothing.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "tests/run_prt_farm.h"
#include "formats/compressed_transport.h"
#include "vocabulary/scene.h"
#include "formats/transport_file.h"
#include "formats/geometry_file.h"
#include "vocabulary/durable_file.h"
#include "worker/column_order.h"
#include "worker/transport_compressor.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

const std::string kScene = std::string(PRT_TESTS_DATA_DIR) + "/tiny.toml";
const std::string kArgs = " --rows-per-block 16 --max-job-rows 9 --quiet --force";

using testing::RunResult;

RunResult Farm(int ranks, const std::string& args) {
  testing::ApplyMpiTestEnvironment();
  // Small eager limit: the column blocks sent to rank 0 (a few KB here) take MPI's rendezvous
  // path, as on real scenes, so that a send/collective ordering deadlock would show.
  ::setenv("OMPI_MCA_btl_vader_eager_limit", "1024", 0);
  return testing::RunPrtFarm(ranks, args);
}

std::string WorkDir(const std::string& name) {
  const fs::path dir = fs::path(PRT_TEST_WORK_DIR) / ("compression_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

nlohmann::json Report(const std::string& run) {
  return nlohmann::json::parse(ReadWholeFile(run + "/report.json"));
}

// The in-process compressor on the farmed rows (the reference the farm must equal).
std::string InProcess(const std::string& run, const std::string& scheme = "",
                      const std::string& scene_file = kScene) {
  TransportFileReader reader(run + "/transport.prtt");
  std::vector<float> T(reader.info().rows * reader.info().cols());
  reader.ReadRows(0, reader.info().rows, T.data());
  const SceneDescription scene = LoadSceneFile(scene_file);
  CompressionOptions o = CompressionOptionsFrom(scene.compression, scene_file);
  if (!scheme.empty()) o.scheme = ParseCompressionScheme(scheme, "test");
  const SpatialDomain domain = SpatialDomainOf(ReadSceneGeometryFile(run + "/geometry.prtg"));
  const std::vector<uint8_t> bytes = EncodeCompressedTransport(
      CompressTransport(T.data(), static_cast<int>(reader.info().cubemap_n), domain, o));
  return std::string(bytes.begin(), bytes.end());
}

// 1, 2 and 3 ranks, with a 4 KiB budget (every rank spills) and the default (none does): the
// same bytes, equal to the in-process compressor; the report carries the phase's figures.
TEST(CompressionPhase, ByteIdenticalToInProcessForAnyRanksAndBudget) {
  const std::string first = WorkDir("np2_spill");
  const RunResult r =
      Farm(2, kScene + " --out " + first + kArgs + " --keep-raw --memory-budget 4k");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string expected = InProcess(first);
  const std::string got = ReadWholeFile(first + "/transport.prtc");
  ASSERT_EQ(got.size(), expected.size());
  EXPECT_TRUE(got == expected) << "transport.prtc differs from the in-process compressor";
  const nlohmann::json c = Report(first)["compression"];
  EXPECT_EQ(c["ranks"], 2);
  EXPECT_EQ(c["raw_bytes"], 72u * 384u * 4u);
  EXPECT_EQ(c["compressed_bytes"], got.size());
  EXPECT_GT(c["spill_bytes"].get<uint64_t>(), 0u);
  EXPECT_GT(c["spill_runs"].get<uint64_t>(), 2u);
  // 2 ranks: rank 0 scatters half the rows, then each rank sends the other half its slab.
  EXPECT_EQ(c["bytes_moved"], 72u * 384u * 4u);
  EXPECT_EQ(c["terms"],
            DecodeCompressedTransport(
                std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(got.data()), got.size()),
                "prtc")
                .term_count());
  EXPECT_NEAR(c["ratio_to_raw"].get<double>(), static_cast<double>(got.size()) / (72 * 384 * 4),
              1e-12);
  EXPECT_GT(c["transpose_mb_per_second"].get<double>(), 0);
  EXPECT_EQ(Report(first)["phases"].back()["name"], "compress");

  for (const auto& [ranks, budget] :
       std::vector<std::pair<int, std::string>>{{1, "2k"}, {1, "1G"}, {2, "1G"}, {3, "3k"}}) {
    const std::string run = WorkDir("np" + std::to_string(ranks) + "_" + budget);
    const RunResult q =
        Farm(ranks, kScene + " --out " + run + kArgs + " --memory-budget " + budget);
    ASSERT_EQ(q.exit_code, 0) << q.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected)
        << ranks << " rank(s), budget " << budget;
    EXPECT_EQ(Report(run)["compression"]["spill_bytes"] == 0, budget.back() == 'G') << budget;
    // Without --keep-raw the raw matrix is gone once the compressed one is durable.
    EXPECT_FALSE(fs::exists(run + "/transport.prtt"));
    EXPECT_FALSE(Report(run)["compression"]["raw_kept"].get<bool>());
  }
}

// The global budget (one threshold from a histogram summed over the ranks, transformed columns
// kept until it is known, spilled beyond the budget): the same bytes as in process for 1, 2 and 3
// ranks, spilling or not.
TEST(CompressionPhase, GlobalBudgetIsByteIdenticalForAnyRanksAndBudget) {
  const std::string scene = std::string(PRT_TESTS_DATA_DIR) + "/tiny_global.toml";
  const std::string first = WorkDir("global_np2_spill");
  const RunResult r = Farm(2, scene + " --out " + first + kArgs + " --keep-raw --memory-budget 4k");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::string expected = InProcess(first, "", scene);
  const std::string got = ReadWholeFile(first + "/transport.prtc");
  EXPECT_TRUE(got == expected) << "transport.prtc differs from the in-process compressor";
  const CompressedTransport t = DecodeCompressedTransport(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(got.data()), got.size()), "prtc");
  EXPECT_EQ(t.header.budget, CompressionBudget::kGlobal);
  EXPECT_GT(Report(first)["compression"]["spill_bytes"].get<uint64_t>(), 0u);
  for (const auto& [ranks, budget] :
       std::vector<std::pair<int, std::string>>{{1, "2k"}, {1, "1G"}, {3, "3k"}}) {
    const std::string run = WorkDir("global_np" + std::to_string(ranks) + "_" + budget);
    const RunResult q = Farm(ranks, scene + " --out " + run + kArgs + " --memory-budget " + budget);
    ASSERT_EQ(q.exit_code, 0) << q.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected)
        << ranks << " rank(s), budget " << budget;
  }
}

TEST(CompressionPhase, SchemeOverrideAndNoCompress) {
  const std::string run = WorkDir("scheme2d");
  const RunResult r =
      Farm(2, kScene + " --out " + run + kArgs + " --keep-raw --compression-scheme 2d");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == InProcess(run, "2d"));
  EXPECT_EQ(Report(run)["compression"]["scheme"], "2d");
  const std::string none = WorkDir("none");
  ASSERT_EQ(Farm(1, kScene + " --out " + none + kArgs + " --no-compress").exit_code, 0);
  EXPECT_TRUE(fs::exists(none + "/transport.prtt"));
  EXPECT_FALSE(fs::exists(none + "/transport.prtc"));
  EXPECT_FALSE(Report(none).contains("compression"));
  EXPECT_EQ(Farm(1, kScene + " --out " + none + " --compression-scheme 3d").exit_code, 1);
}

// A rank killed after sampling, at each point where finished work could be lost: rank 0 before
// renaming the finalized transport.prtt, either rank inside the transpose (4 KiB budget: spill
// files on disk), rank 0 halfway through writing transport.prtc. --resume re-uses every journaled
// job (none redone) and writes the bytes of an uninterrupted run; nothing temporary is left.
TEST(CompressionPhase, KilledAfterSamplingThenResumeGivesTheUninterruptedBytes) {
  const std::string reference = WorkDir("kill_reference");
  ASSERT_EQ(Farm(2, kScene + " --out " + reference + kArgs + " --memory-budget 4k").exit_code, 0);
  const std::string expected = ReadWholeFile(reference + "/transport.prtc");
  const std::vector<std::pair<std::string, int>> points = {
      {"finalize", 0}, {"transpose", 0}, {"transpose", 1}, {"write", 0}};
  for (const auto& [point, rank] : points) {
    SCOPED_TRACE(point + " on rank " + std::to_string(rank));
    const std::string run = WorkDir("kill_" + point + std::to_string(rank));
    const RunResult killed =
        Farm(2, kScene + " --out " + run + kArgs + " --memory-budget 4k --fail-in " + point +
                    " --fail-rank " + std::to_string(rank));
    EXPECT_EQ(killed.exit_code, 4) << killed.output;
    EXPECT_NE(killed.output.find("exits abruptly"), std::string::npos) << killed.output;
    EXPECT_FALSE(fs::exists(run + "/transport.prtc"));
    const int journaled = static_cast<int>(Report(reference)["jobs"]["total"].get<int>());
    const RunResult resumed = Farm(2, kScene + " --out " + run +
                                          " --rows-per-block 16 --max-job-rows 9 --quiet "
                                          "--memory-budget 4k --resume");
    ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
    const nlohmann::json rep = Report(run);
    EXPECT_EQ(rep["jobs"]["done"], 0) << rep.dump();
    EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], journaled) << rep.dump();
    EXPECT_EQ(rep["rays_traced"], 0) << rep.dump();
    for (const fs::directory_entry& e : fs::directory_iterator(run)) {
      const std::string name = e.path().filename().string();
      EXPECT_TRUE(name != "transport.prtt" && name.find(".tmp") == std::string::npos &&
                  name.find("spill") == std::string::npos &&
                  name.find(".partial") == std::string::npos)
          << "left behind: " << name;
    }
  }
}

// The compression was interrupted (no transport.prtc, raw still there): --resume re-uses every
// journaled job and redoes only the compression. On a compressed run without the raw matrix,
// --resume has nothing to do.
TEST(CompressionPhase, ResumeRedoesOnlyTheCompression) {
  const std::string run = WorkDir("resume");
  ASSERT_EQ(Farm(2, kScene + " --out " + run + kArgs + " --keep-raw").exit_code, 0);
  const std::string expected = ReadWholeFile(run + "/transport.prtc");
  fs::remove(run + "/transport.prtc");
  const std::string args = " --rows-per-block 16 --max-job-rows 9 --quiet --resume";
  const RunResult r = Farm(2, kScene + " --out " + run + args);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json rep = Report(run);
  EXPECT_EQ(rep["jobs"]["done"], 0) << rep.dump();
  EXPECT_GT(rep["jobs"]["reused_from_checkpoints"].get<int>(), 0);
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
  EXPECT_FALSE(fs::exists(run + "/transport.prtt"));
  const std::string report = ReadWholeFile(run + "/report.json");
  const RunResult again = Farm(1, kScene + " --out " + run + " --rows-per-block 16 --resume");
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("nothing to do"), std::string::npos) << again.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
  EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);

  // The finished run's inputs are checked before "nothing to do": another scene (here another
  // seed) or other settings are refused, naming the manifest, and the finished asset stays.
  const std::string changed = WorkDir("resume-changed") + "/changed.toml";
  std::string text = ReadWholeFile(kScene);
  std::string box_path = PRT_TESTS_DATA_DIR;
  box_path.append("/box.off").insert(0, 1, '"').push_back('"');
  for (const auto& [from, to] :
       {std::pair<std::string, std::string>{"seed = 3", "seed = 4"}, {"\"box.off\"", box_path}}) {
    const std::size_t at = text.find(from);
    ASSERT_NE(at, std::string::npos) << text;
    text.replace(at, from.size(), to);
  }
  WriteFileDurably(changed, text);
  const RunResult other = Farm(1, changed + " --out " + run + " --rows-per-block 16 --resume");
  EXPECT_EQ(other.exit_code, 2) << other.output;
  EXPECT_NE(other.output.find("manifest.json"), std::string::npos) << other.output;
  EXPECT_NE(other.output.find("different run"), std::string::npos) << other.output;
  const RunResult rpb = Farm(1, kScene + " --out " + run + " --resume");
  EXPECT_EQ(rpb.exit_code, 2) << rpb.output;
  EXPECT_NE(rpb.output.find("rows_per_block"), std::string::npos) << rpb.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
  EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);
}

// The stale-asset trap (issue 27): --resume of a finished run (transport.prtc written, the raw
// matrix removed) with other compression settings used to print "nothing to do" and keep the old
// asset. Now it is refused, naming the asset and what changed, and nothing is touched; the same
// settings still have nothing to do; with the raw matrix kept, the new settings are applied.
TEST(CompressionPhase, ResumeWithOtherCompressionSettingsIsNeverReportedDone) {
  const std::string run = WorkDir("stale");
  ASSERT_EQ(Farm(2, kScene + " --out " + run + kArgs).exit_code, 0);
  const std::string asset = ReadWholeFile(run + "/transport.prtc");
  const std::string report = ReadWholeFile(run + "/report.json");
  const std::string resume = " --rows-per-block 16 --max-job-rows 9 --resume";
  const RunResult other = Farm(1, kScene + " --out " + run + resume + " --compression-scheme 2d");
  EXPECT_EQ(other.exit_code, 2) << other.output;
  EXPECT_EQ(other.output.find("nothing to do"), std::string::npos) << other.output;
  EXPECT_NE(other.output.find("transport.prtc"), std::string::npos) << other.output;
  EXPECT_NE(other.output.find("scheme adaptive4d -> 2d"), std::string::npos) << other.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == asset);
  EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);
  const RunResult same = Farm(1, kScene + " --out " + run + resume);
  EXPECT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("nothing to do"), std::string::npos) << same.output;

  const std::string kept = WorkDir("stale-kept");
  ASSERT_EQ(Farm(2, kScene + " --out " + kept + kArgs + " --keep-raw").exit_code, 0);
  const RunResult again =
      Farm(2, kScene + " --out " + kept + resume + " --keep-raw --compression-scheme 2d --quiet");
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(Report(kept)["compression"]["scheme"], "2d");
  EXPECT_EQ(Report(kept)["jobs"]["done"], 0);
}

}  // namespace
}  // namespace prt
