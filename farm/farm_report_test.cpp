#include "farm/farm_report.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

namespace prt {
namespace {

TEST(FarmReportTest, LoadImbalanceIsMaxOverMeanBusyTimeOfComputingRanks) {
  FarmReport r;
  EXPECT_EQ(r.LoadImbalance(), 0.0);                   // nobody computed
  r.rank_reports = {{0, "a", 4, false, 0, 0, 0, 0.0},  // coordinator only: not counted
                    {1, "b", 4, true, 3, 30, 3000, 2.0},
                    {2, "c", 4, true, 5, 50, 5000, 4.0}};
  EXPECT_DOUBLE_EQ(r.LoadImbalance(), 4.0 / 3.0);
  r.rank_reports[0].computes = true;  // counted as idle: mean (0 + 2 + 4) / 3 = 2
  EXPECT_DOUBLE_EQ(r.LoadImbalance(), 2.0);
}

TEST(FarmReportTest, JsonHasTheDocumentedKeys) {
  FarmReport r;
  r.status = "ok";
  r.phases = {{"setup", 0.5}, {"brute", 10.0}};
  r.sampling_seconds = 10.0;
  r.rays_traced = 1000000;
  r.texels_below_horizon = 77;
  r.jobs_done = 8;
  r.jobs_reused = 2;
  r.jobs_total = 10;
  r.rank_reports = {{0, "a", 2, true, 8, 80, 1000000, 4.0}};
  const nlohmann::json j = nlohmann::json::parse(r.ToJsonText());
  EXPECT_EQ(j["status"], "ok");
  EXPECT_EQ(j["phases"][1]["name"], "brute");
  EXPECT_DOUBLE_EQ(j["rays_per_second"].get<double>(), 1e5);
  EXPECT_EQ(j["texels_skipped_below_horizon"], 77);
  EXPECT_EQ(j["jobs"]["total"], 10);
  EXPECT_EQ(j["jobs"]["reused_from_checkpoints"], 2);
  EXPECT_DOUBLE_EQ(j["rank_details"][0]["rays_per_second"].get<double>(), 2.5e5);
  EXPECT_DOUBLE_EQ(j["rank_details"][0]["busy_seconds"].get<double>(), 4.0);
  EXPECT_DOUBLE_EQ(j["load_imbalance"].get<double>(), 1.0);
}

}  // namespace
}  // namespace prt
