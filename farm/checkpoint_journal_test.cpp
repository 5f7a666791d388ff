#include "farm/checkpoint_journal.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "formats/run_folder.h"
#include "vocabulary/errors.h"

namespace prt {
namespace {

namespace fs = std::filesystem;

JournalEntry Entry(uint64_t first, uint64_t count) {
  JournalEntry e;
  e.rows = {first, count};
  e.rows_checksum = 0x0123456789abcdefULL ^ first;
  e.rank = static_cast<int>(first % 3);
  e.rays_traced = 1000 * count;
  e.texels_traced = 10 * count;
  e.texels_below_horizon = 7 * count;
  e.rays_below_horizon = 3;
  e.busy_seconds = 0.125;
  return e;
}

void ExpectSame(const JournalEntry& a, const JournalEntry& b) {
  EXPECT_EQ(a.rows, b.rows);
  EXPECT_EQ(a.rows_checksum, b.rows_checksum);
  EXPECT_EQ(a.rank, b.rank);
  EXPECT_EQ(a.rays_traced, b.rays_traced);
  EXPECT_EQ(a.texels_traced, b.texels_traced);
  EXPECT_EQ(a.texels_below_horizon, b.texels_below_horizon);
  EXPECT_EQ(a.rays_below_horizon, b.rays_below_horizon);
  EXPECT_DOUBLE_EQ(a.busy_seconds, b.busy_seconds);
}

class CheckpointJournalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("prt_journal_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    path_ = (dir_ / "journal.txt").string();
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
  std::string path_;
};

TEST_F(CheckpointJournalTest, LinesRoundTripAndDetectDamage) {
  const JournalEntry e = Entry(42, 17);
  const std::string line = FormatJournalLine(e);
  JournalEntry back;
  ASSERT_TRUE(ParseJournalLine(line, back));
  ExpectSame(back, e);
  std::string damaged = line;
  damaged[5] = damaged[5] == '1' ? '2' : '1';  // a digit of `first`
  EXPECT_FALSE(ParseJournalLine(damaged, back));
  EXPECT_FALSE(ParseJournalLine(line.substr(0, line.size() - 3), back));  // torn
  EXPECT_FALSE(ParseJournalLine("", back));
}

TEST_F(CheckpointJournalTest, AppendedJobsSurviveATornLastLine) {
  {
    CheckpointJournal j(path_, 0xfeedULL, {Entry(0, 5)});
    j.Append({Entry(5, 5), Entry(10, 3)});
  }
  // A kill in the middle of appending the next line.
  const std::string torn = FormatJournalLine(Entry(13, 4));
  std::ofstream(path_, std::ios::app) << torn.substr(0, torn.size() / 2);
  JournalContents c = ReadJournal(path_);
  EXPECT_TRUE(c.has_header);
  EXPECT_EQ(c.run_key, 0xfeedULL);
  ASSERT_EQ(c.entries.size(), 3u);
  ExpectSame(c.entries[2], Entry(10, 3));
  EXPECT_EQ(c.damaged_lines, 1);
  // Resume rewrites the journal with the good entries only; appending then stays parseable.
  {
    CheckpointJournal j(path_, 0xfeedULL, c.entries);
    j.Append({Entry(13, 4)});
  }
  c = ReadJournal(path_);
  ASSERT_EQ(c.entries.size(), 4u);
  EXPECT_EQ(c.damaged_lines, 0);
  ExpectSame(c.entries[3], Entry(13, 4));
}

TEST_F(CheckpointJournalTest, MissingJournalIsEmptyAndForeignFileIsRejected) {
  const JournalContents c = ReadJournal(path_);
  EXPECT_FALSE(c.has_header);
  EXPECT_TRUE(c.entries.empty());
  std::ofstream(path_) << "something else\n";
  EXPECT_THROW(ReadJournal(path_), InputError);
}

TEST(RunFolderTest, LayoutNames) {
  const RunFolder f("run");
  EXPECT_EQ(f.transport, "run/transport.prtt");
  EXPECT_EQ(f.partial, "run/transport.prtt.partial");
  EXPECT_EQ(f.geometry, "run/geometry.prtg");
  EXPECT_EQ(f.scene_copy, "run/scene.toml");
  EXPECT_EQ(f.report, "run/report.json");
  EXPECT_EQ(f.journal, "run/checkpoints/journal.txt");
  EXPECT_EQ(f.manifest, "run/checkpoints/manifest.json");
}

}  // namespace
}  // namespace prt
