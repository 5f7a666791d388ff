// prt-farm's compression phase end to end under mpirun (farm/compression_phase.h,
// docs/farm-compression.md): on the tiny scene of tests/data, run/transport.prtc is byte-identical
// to the in-process compressor (CompressTransport on the rows of transport.prtt, the scene's
// [compression] settings, the domain of geometry.prtg) for 1, 2 and 3 ranks, with a budget that
// forces every rank to spill and with the default budget; the scheme override is honoured; the
// rows stay unless --discard-raw; an interrupted compression is redone by --resume without
// tracing, --resume on a finished run does nothing, and every edit of a finished run re-runs
// only the stages it touches.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "formats/column_coding.h"
#include "formats/compressed_transport.h"
#include "formats/geometry_file.h"
#include "formats/transport_file.h"
#include "tests/run_prt_farm.h"
#include "vocabulary/durable_file.h"
#include "vocabulary/scene.h"
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
// report.json's compression error is exact: ‖T − T̃‖_F / ‖T‖_F with T the rows of
// transport.prtt and T̃ what transport.prtc decodes to.
void ExpectExactFrobeniusError(const std::string& run) {
  const std::string bytes = ReadWholeFile(run + "/transport.prtc");
  const CompressedTransport t = DecodeCompressedTransport(
      std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
      "prtc");
  const std::vector<float> decoded = DecompressTransport(t);
  const TransportFileReader raw(run + "/transport.prtt");
  std::vector<float> rows(raw.info().rows * raw.info().cols());
  raw.ReadRows(0, raw.info().rows, rows.data());
  ASSERT_EQ(rows.size(), decoded.size());
  double err = 0, total = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    err += (double(rows[i]) - decoded[i]) * (double(rows[i]) - decoded[i]);
    total += double(rows[i]) * rows[i];
  }
  const double reported = Report(run)["compression"]["relative_frobenius_error"].get<double>();
  EXPECT_GT(reported, 0.0) << run;
  EXPECT_NEAR(reported, std::sqrt(err / total), 1e-5 * std::sqrt(err / total) + 1e-7) << run;
}

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
  // 2 ranks sharing the run folder: each reads its own share of the rows in whole file blocks
  // and sends the other rank its share's slab of the other's 192 columns; no row passes through
  // rank 0. With a 4 KiB budget a chunk is one 16-row block per rank: rank 0 reads rows 0–15
  // and 32–47, rank 1 rows 16–31, 48–63 and the last chunk's 8 rows.
  EXPECT_TRUE(c["every_rank_reads"].get<bool>());
  EXPECT_EQ(c["bytes_moved"], 72u * 192u * 4u);
  EXPECT_EQ(c["rank0_bytes_read"], 32u * 384u * 4u);
  EXPECT_EQ(c["rank0_bytes_sent"], 32u * 192u * 4u);
  EXPECT_EQ(c["terms"],
            DecodeCompressedTransport(
                std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(got.data()), got.size()),
                "prtc")
                .term_count());
  EXPECT_NEAR(c["ratio_to_raw"].get<double>(), static_cast<double>(got.size()) / (72 * 384 * 4),
              1e-12);
  EXPECT_GT(c["transpose_mb_per_second"].get<double>(), 0);
  ExpectExactFrobeniusError(first);
  const nlohmann::json phases = Report(first)["phases"];
  EXPECT_EQ(phases[phases.size() - 2]["name"], "compress");
  EXPECT_EQ(phases.back()["name"], "estimate");

  for (const auto& [ranks, budget] :
       std::vector<std::pair<int, std::string>>{{1, "2k"}, {1, "1G"}, {2, "1G"}, {3, "3k"}}) {
    const std::string run = WorkDir("np" + std::to_string(ranks) + "_" + budget);
    const RunResult q =
        Farm(ranks, kScene + " --out " + run + kArgs + " --memory-budget " + budget);
    ASSERT_EQ(q.exit_code, 0) << q.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected)
        << ranks << " rank(s), budget " << budget;
    EXPECT_EQ(Report(run)["compression"]["spill_bytes"] == 0, budget.back() == 'G') << budget;
    // The rows stay (packed) by default; --discard-raw removes them once the compressed
    // transport and the report are durable.
    EXPECT_TRUE(fs::exists(run + "/transport.prtt"));
    EXPECT_TRUE(Report(run)["compression"]["raw_kept"].get<bool>());
  }
  // --rows-via-rank0 (a run folder only rank 0 reaches): rank 0 reads every row and scatters
  // half of each chunk to rank 1, then each rank sends the other its slab: the same bytes.
  const std::string funnel = WorkDir("np2_via_rank0");
  ASSERT_EQ(Farm(2, kScene + " --out " + funnel + kArgs + " --memory-budget 4k --rows-via-rank0")
                .exit_code,
            0);
  EXPECT_TRUE(ReadWholeFile(funnel + "/transport.prtc") == expected);
  EXPECT_TRUE(ReadWholeFile(funnel + "/transport.prtt") ==
              ReadWholeFile(first + "/transport.prtt"));
  const nlohmann::json cf = Report(funnel)["compression"];
  EXPECT_FALSE(cf["every_rank_reads"].get<bool>());
  EXPECT_EQ(cf["bytes_moved"], 36u * 384u * 4u + 72u * 192u * 4u);
  EXPECT_EQ(cf["rank0_bytes_read"], 72u * 384u * 4u);
  const std::string discard = WorkDir("discard");
  ASSERT_EQ(Farm(2, kScene + " --out " + discard + kArgs + " --discard-raw").exit_code, 0);
  EXPECT_TRUE(ReadWholeFile(discard + "/transport.prtc") == expected);
  EXPECT_FALSE(fs::exists(discard + "/transport.prtt"));
  EXPECT_FALSE(Report(discard)["compression"]["raw_kept"].get<bool>());
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
  ExpectExactFrobeniusError(run);
  // The per-column budget (2D: the rows truncated before the column stage; 4D: per column).
  const std::string column_scene = WorkDir("column-budget") + "/tiny_column.toml";
  fs::copy_file(std::string(PRT_TESTS_DATA_DIR) + "/box.off",
                fs::path(column_scene).parent_path() / "box.off", fs::copy_options::skip_existing);
  WriteFileDurably(column_scene, ReadWholeFile(kScene) + "\n[compression]\nbudget = \"column\"\n");
  for (const std::string scheme : {"2d", "adaptive4d"}) {
    const std::string col = WorkDir("column-" + scheme);
    ASSERT_EQ(Farm(2, column_scene + " --out " + col + kArgs + " --compression-scheme " + scheme)
                  .exit_code,
              0);
    ExpectExactFrobeniusError(col);
  }
  const std::string none = WorkDir("none");
  ASSERT_EQ(Farm(1, kScene + " --out " + none + kArgs + " --no-compress").exit_code, 0);
  EXPECT_TRUE(fs::exists(none + "/transport.prtt"));
  EXPECT_FALSE(fs::exists(none + "/transport.prtc"));
  EXPECT_FALSE(Report(none).contains("compression"));
  EXPECT_EQ(Farm(1, kScene + " --out " + none + " --compression-scheme 3d").exit_code, 1);
}

// A rank killed after sampling, at each point where finished work could be lost: rank 0 before
// renaming the packed transport.prtt into place, either rank inside the transpose (4 KiB budget:
// spill files on disk), rank 0 halfway through writing transport.prtc. --resume traces nothing
// (the journaled jobs, or the finished rows stage, are re-used) and writes the bytes of an
// uninterrupted run; nothing temporary is left.
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
    EXPECT_EQ(rep["rays_traced"], 0) << rep.dump();
    if (point == "finalize") {
      EXPECT_EQ(rep["stages"][0]["status"], "resumed") << rep.dump();
      EXPECT_EQ(rep["jobs"]["reused_from_checkpoints"], journaled) << rep.dump();
    } else {
      EXPECT_EQ(rep["stages"][0]["status"], "reused") << rep.dump();
    }
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtt") ==
                ReadWholeFile(reference + "/transport.prtt"));
    for (const fs::directory_entry& e : fs::directory_iterator(run)) {
      const std::string name = e.path().filename().string();
      EXPECT_TRUE(name.find(".tmp") == std::string::npos &&
                  name.find("spill") == std::string::npos &&
                  name.find(".partial") == std::string::npos)
          << "left behind: " << name;
    }
  }
}

// The compression was interrupted (no transport.prtc, the rows there): --resume traces nothing
// and redoes only the compression. A finished run resumed has nothing to do.
TEST(CompressionPhase, ResumeRedoesOnlyTheCompression) {
  const std::string run = WorkDir("resume");
  ASSERT_EQ(Farm(2, kScene + " --out " + run + kArgs).exit_code, 0);
  const std::string expected = ReadWholeFile(run + "/transport.prtc");
  fs::remove(run + "/transport.prtc");
  const std::string args = " --rows-per-block 16 --max-job-rows 9 --quiet --resume";
  const RunResult r = Farm(2, kScene + " --out " + run + args);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json rep = Report(run);
  EXPECT_EQ(rep["rays_traced"], 0) << rep.dump();
  EXPECT_EQ(rep["stages"][0]["status"], "reused") << rep.dump();
  EXPECT_EQ(rep["stages"][1]["status"], "ran") << rep.dump();
  EXPECT_EQ(rep["stages"][1]["reason"], "transport.prtc missing") << rep.dump();
  EXPECT_EQ(rep["stages"][2]["status"], "reused") << rep.dump();
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
  const std::string report = ReadWholeFile(run + "/report.json");
  const RunResult again = Farm(1, kScene + " --out " + run + " --rows-per-block 16 --resume");
  EXPECT_EQ(again.exit_code, 0) << again.output;
  EXPECT_NE(again.output.find("nothing to do"), std::string::npos) << again.output;
  EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
  EXPECT_TRUE(ReadWholeFile(run + "/report.json") == report);
}

// The edits of a finished run (issue 27's table, docs/farm.md "Stages and re-runs"): each
// re-runs only the stages that depend on it, traces no ray unless the rows change, and leaves
// the asset a fresh run of the edited scene writes (no stale transport.prtc, ever).
TEST(CompressionPhase, EveryEditReRunsOnlyWhatItTouchesAndNeverLeavesAStaleAsset) {
  const std::string dir = WorkDir("edits");
  const std::string base_text = ReadWholeFile(kScene) +
                                "\n[compression]\nkeep_fraction = 0.05\nbits = 9\n"
                                "\n[camera]\nfov = 35.0\n"
                                "\n[environments]\npaths = [\"" PRT_DATA_DIR
                                "/envmaps/sunrise.exr\"]\n";
  auto write_scene = [&](const std::string& name, const std::string& text) {
    const std::string path = dir + "/" + name + ".toml";
    fs::copy_file(std::string(PRT_TESTS_DATA_DIR) + "/box.off", dir + "/box.off",
                  fs::copy_options::skip_existing);
    WriteFileDurably(path, text);
    return path;
  };
  auto edit = [&](std::string text, const std::string& from, const std::string& to) {
    const std::size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
    return text;
  };
  struct Edit {
    std::string name, from, to;
    std::vector<std::string> statuses;  // rows, compression, estimate, assets
    std::string extra = "";
  };
  const std::vector<Edit> edits = {
      {"comment",
       "# A tiny scene",
       "# An edited tiny scene",
       {"reused", "reused", "reused", "updated"}},
      {"camera", "fov = 35.0", "fov = 50.0", {"reused", "reused", "reused", "updated"}},
      // A glossy material is baked into a vertex run's rows ([glossy] terms per vertex,
      // docs/glossy-transport.md): the rows and everything after them run again.
      {"material",
       "albedo = [0.5, 0.5, 0.5]",
       "albedo = [0.5, 0.5, 0.5]\nbrdf = \"phong\"\nspecular = [0.2, 0.2, 0.2]\nexponent = 20",
       {"ran", "ran", "ran", "updated"}},
      {"environments",
       "/envmaps/sunrise.exr\"]",
       "/envmaps/studio.exr\"]",
       {"reused", "reused", "ran", "updated"}},
      {"albedo",
       "albedo = [0.5, 0.5, 0.5]",
       "albedo = [0.9, 0.3, 0.3]",
       {"reused", "reused", "ran", "updated"}},
      {"keep",
       "keep_fraction = 0.05",
       "keep_fraction = 0.1",
       {"reused", "ran", "reused", "updated"}},
      {"bits", "bits = 9", "bits = 12", {"reused", "ran", "reused", "updated"}},
      {"scheme", "", "", {"reused", "ran", "reused", "unchanged"}, " --compression-scheme 2d"},
      {"rays", "rays_per_texel = 4", "rays_per_texel = 6", {"ran", "ran", "ran", "updated"}},
      {"moved",
       "albedo = [0.5, 0.5, 0.5]",
       "albedo = [0.5, 0.5, 0.5]\ntranslate = [0.2, 0, 0]",
       {"ran", "ran", "ran", "updated"}},
  };
  const std::string args = " --rows-per-block 16 --max-job-rows 9 --quiet";
  for (const Edit& e : edits) {
    SCOPED_TRACE(e.name);
    const std::string run = dir + "/" + e.name;
    ASSERT_EQ(Farm(2, write_scene("base", base_text) + " --out " + run + args).exit_code, 0);
    const std::string text = e.from.empty() ? base_text : edit(base_text, e.from, e.to);
    const std::string scene = write_scene(e.name, text);
    const RunResult r = Farm(2, scene + " --out " + run + args + " --resume" + e.extra);
    ASSERT_EQ(r.exit_code, 0) << r.output;
    const nlohmann::json rep = Report(run);
    ASSERT_EQ(rep["stages"].size(), 4u) << rep.dump();
    for (std::size_t k = 0; k < 4; ++k)
      EXPECT_EQ(rep["stages"][k]["status"], e.statuses[k]) << rep["stages"].dump();
    EXPECT_EQ(rep["rays_traced"].get<uint64_t>() == 0, e.statuses[0] == "reused") << rep.dump();
    // The same files as a fresh run of the edited scene.
    const std::string fresh = dir + "/" + e.name + "-fresh";
    ASSERT_EQ(Farm(1, scene + " --out " + fresh + args + e.extra).exit_code, 0);
    // accuracy.json too, to the byte: its sums are exact (docs/farm.md, "Determinism"), so a
    // resumed 2-rank run and a fresh 1-rank run write the same text.
    for (const char* file :
         {"transport.prtt", "transport.prtc", "geometry.prtg", "scene.toml", "accuracy.json"})
      EXPECT_TRUE(ReadWholeFile(run + "/" + file) == ReadWholeFile(fresh + "/" + file)) << file;
  }
}

// The stale-asset trap (issue 27): --resume of a finished run with other compression settings
// used to print "nothing to do" and keep the old asset (at 647dc18). Now the compression runs
// again from the kept rows without tracing; with the rows discarded (--discard-raw) it traces
// them again. Either way the asset is what a fresh run with the new settings writes.
TEST(CompressionPhase, ResumeWithOtherCompressionSettingsIsNeverReportedDone) {
  const std::string fresh = WorkDir("stale-fresh");
  ASSERT_EQ(Farm(1, kScene + " --out " + fresh + kArgs + " --compression-scheme 2d").exit_code, 0);
  const std::string expected = ReadWholeFile(fresh + "/transport.prtc");
  const std::string resume = " --rows-per-block 16 --max-job-rows 9 --resume";
  for (const std::string raw : {"", " --discard-raw"}) {
    SCOPED_TRACE(raw.empty() ? "rows kept" : "rows discarded");
    const std::string run = WorkDir(raw.empty() ? "stale-kept" : "stale-discarded");
    ASSERT_EQ(Farm(2, kScene + " --out " + run + kArgs + raw).exit_code, 0);
    const RunResult other = Farm(2, kScene + " --out " + run + resume + " --compression-scheme 2d");
    ASSERT_EQ(other.exit_code, 0) << other.output;
    EXPECT_EQ(other.output.find("nothing to do"), std::string::npos) << other.output;
    EXPECT_NE(other.output.find("scheme \"adaptive4d\" -> \"2d\""), std::string::npos)
        << other.output;
    EXPECT_TRUE(ReadWholeFile(run + "/transport.prtc") == expected);
    const nlohmann::json rep = Report(run);
    EXPECT_EQ(rep["compression"]["scheme"], "2d");
    EXPECT_EQ(rep["stages"][0]["status"], raw.empty() ? "reused" : "ran") << rep.dump();
    EXPECT_EQ(rep["rays_traced"].get<uint64_t>() == 0, raw.empty()) << rep.dump();
    const RunResult same = Farm(1, kScene + " --out " + run + resume + " --compression-scheme 2d");
    EXPECT_EQ(same.exit_code, 0) << same.output;
    EXPECT_NE(same.output.find("nothing to do"), std::string::npos) << same.output;
  }
}

}  // namespace
}  // namespace prt
