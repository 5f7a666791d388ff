#include "farm/progress.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <memory>
#include <sstream>
#include <string>

namespace prt {
namespace {

TEST(ProgressTest, PercentageRateAndEtaFollowAnInjectedClock) {
  double now = 100.0;
  ProgressOptions options;
  options.unit = "samples";
  options.rate_unit = "rays";
  options.log = false;
  options.clock = [&] { return now; };
  Progress p("brute", 1000, options);
  EXPECT_EQ(p.Snapshot().eta_s, -1);  // unknown before anything is done
  now = 102.0;
  p.Advance(250, 5000000);
  const ProgressSnapshot s = p.Snapshot();
  EXPECT_EQ(s.done, 250u);
  EXPECT_DOUBLE_EQ(s.fraction, 0.25);
  EXPECT_DOUBLE_EQ(s.elapsed_s, 2.0);
  EXPECT_DOUBLE_EQ(s.units_per_s, 125.0);
  EXPECT_DOUBLE_EQ(s.rate_units_per_s, 2.5e6);
  EXPECT_DOUBLE_EQ(s.eta_s, 6.0);  // 750 remaining at 125/s
  const std::string line = p.Line();
  EXPECT_NE(line.find("25.0%"), std::string::npos) << line;
  EXPECT_NE(line.find("2.50M rays/s"), std::string::npos) << line;
  EXPECT_NE(line.find("ETA 6.0s"), std::string::npos) << line;
  p.Advance(10000);  // clamps at total
  EXPECT_EQ(p.Snapshot().done, 1000u);
  EXPECT_EQ(p.Snapshot().eta_s, 0.0);
}

TEST(ProgressTest, WorkDoneBeforeCountsTowardsPercentageNotRate) {
  double now = 0.0;
  ProgressOptions options;
  options.log = false;
  options.already_done = 600;
  options.clock = [&] { return now; };
  Progress p("resume", 1000, options);
  EXPECT_DOUBLE_EQ(p.Snapshot().fraction, 0.6);
  now = 4.0;
  p.Advance(100);
  const ProgressSnapshot s = p.Snapshot();
  EXPECT_DOUBLE_EQ(s.units_per_s, 25.0);  // 100 in 4 s, not 700 in 4 s
  EXPECT_DOUBLE_EQ(s.eta_s, 12.0);        // 300 remaining at 25/s
}

// The job loop calls Advance(0) on every pass (farm/job_loop.cpp): a line comes every interval
// while no unit finishes (a long job out), with the elapsed time and the ETA moving on.
TEST(ProgressTest, AdvanceWithoutUnitsLogsEveryInterval) {
  std::ostringstream log;
  auto previous = spdlog::default_logger();
  auto logger = std::make_shared<spdlog::logger>(
      "progress-test", std::make_shared<spdlog::sinks::ostream_sink_st>(log));
  logger->set_pattern("%v");
  logger->set_level(spdlog::level::info);
  spdlog::set_default_logger(logger);
  double now = 0.0;
  ProgressOptions options;
  options.log_interval_s = 5.0;
  options.clock = [&] { return now; };
  options.suffix = [](double eta_s) { return " | step ETA " + Progress::FormatDuration(eta_s); };
  Progress p("path-trace", 100, options);
  now = 2.0;
  p.Advance(10);  // within the interval: no line
  for (now = 2.0; now <= 20.0; now += 0.5) p.Advance(0);
  spdlog::set_default_logger(previous);
  const std::string text = log.str();
  int lines = 0;
  for (char c : text) lines += c == '\n' ? 1 : 0;
  EXPECT_EQ(lines, 4) << text;  // at 5, 10, 15 and 20 s
  EXPECT_NE(text.find("10.0% (10/100 items)"), std::string::npos) << text;
  EXPECT_NE(text.find("elapsed 20.0s, ETA 3m00s | step ETA 3m00s"), std::string::npos) << text;
}

TEST(ProgressTest, FormatsDurationsAndCounts) {
  EXPECT_EQ(Progress::FormatDuration(0.25), "250ms");
  EXPECT_EQ(Progress::FormatDuration(12.34), "12.3s");
  EXPECT_EQ(Progress::FormatDuration(245), "4m05s");
  EXPECT_EQ(Progress::FormatDuration(7380), "2h03m");
  EXPECT_EQ(Progress::FormatDuration(-1), "unknown");
  EXPECT_EQ(Progress::FormatCount(950), "950");
  EXPECT_EQ(Progress::FormatCount(12345), "12.3k");
  EXPECT_EQ(Progress::FormatCount(4.56e6), "4.56M");
  EXPECT_EQ(Progress::FormatCount(7.891e9), "7.89G");
}

}  // namespace
}  // namespace prt
