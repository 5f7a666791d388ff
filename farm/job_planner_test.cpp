#include "farm/job_planner.h"

#include <gtest/gtest.h>

#include <vector>

namespace prt {
namespace {

// Hands out every job to workers in turn and returns them in order of handing out.
std::vector<RowRange> Drain(JobPlanner& p, int workers, double rows_per_second) {
  std::vector<RowRange> jobs;
  for (int w = 0;; w = (w + 1) % workers) {
    const auto job = p.Next(w);
    if (!job) break;
    jobs.push_back(*job);
    p.Measured(w, job->count, static_cast<double>(job->count) / rows_per_second);
  }
  return jobs;
}

TEST(JobPlannerTest, CoversEveryUnfinishedRowExactlyOnce) {
  // Checkpointed ranges, overlapping and out of order, some past the end.
  const std::vector<RowRange> done = {{100, 50}, {0, 10}, {120, 40}, {990, 100}};
  JobSizing sizing;
  sizing.workers = 3;
  JobPlanner p(1000, done, sizing);
  EXPECT_EQ(p.done_before_rows(), 10u + 60u + 10u);
  EXPECT_EQ(p.gaps(), (std::vector<RowRange>{{10, 90}, {160, 830}}));
  std::vector<int> covered(1000, 0);
  for (const RowRange& r : done) {
    for (uint64_t i = r.first; i < std::min<uint64_t>(r.end(), 1000); ++i) covered[i] = 1;
  }
  for (const RowRange& j : Drain(p, 3, 1000.0)) {
    for (uint64_t i = j.first; i < j.end(); ++i) ++covered[i];
  }
  for (int c : covered) ASSERT_EQ(c, 1);
  EXPECT_EQ(p.unassigned_rows(), 0u);
}

TEST(JobPlannerTest, JobsStartSmallAndGrowTowardsTheTargetDuration) {
  JobSizing sizing;
  sizing.job_seconds = 2.0;
  sizing.initial_rows = 8;
  sizing.growth = 2.0;
  sizing.workers = 1;
  JobPlanner p(1000000, {}, sizing);
  // A worker doing 1000 rows/s: 8, 16, 32, ... doubling until 2000 rows (2 s) is reached.
  std::vector<uint64_t> sizes;
  for (int i = 0; i < 10; ++i) {
    const auto job = p.Next(0);
    ASSERT_TRUE(job);
    sizes.push_back(job->count);
    p.Measured(0, job->count, static_cast<double>(job->count) / 1000.0);
  }
  EXPECT_EQ(sizes, (std::vector<uint64_t>{8, 16, 32, 64, 128, 256, 512, 1024, 2000, 2000}));
}

TEST(JobPlannerTest, FasterWorkersGetLargerJobsAndTheTailShrinks) {
  JobSizing sizing;
  sizing.job_seconds = 1.0;
  sizing.initial_rows = 100;
  sizing.workers = 2;
  JobPlanner p(100000, {}, sizing);
  p.Measured(0, 100, 1.0);   // 100 rows/s
  p.Measured(1, 100, 0.25);  // 400 rows/s
  EXPECT_EQ(p.NextSize(0), 100u);
  EXPECT_EQ(p.NextSize(1), 200u);  // limited by growth 2× of its last job
  p.Measured(1, 200, 0.5);
  EXPECT_EQ(p.NextSize(1), 400u);
  // Near the end no job exceeds remaining / (2 · workers).
  JobPlanner tail(1000, {{0, 900}}, sizing);
  tail.Measured(0, 100, 0.01);  // fast: 10k rows/s
  const auto job = tail.Next(0);
  ASSERT_TRUE(job);
  EXPECT_EQ(job->count, 25u);  // 100 left / (2 · 2)
}

TEST(JobPlannerTest, ReturnedJobsAreHandedOutAgainAndSizesRespectBounds) {
  JobSizing sizing;
  sizing.initial_rows = 1000;  // clamped to max_rows
  sizing.max_rows = 7;
  JobPlanner p(20, {}, sizing);
  const auto a = p.Next(0);
  ASSERT_TRUE(a);
  EXPECT_EQ(*a, (RowRange{0, 7}));
  p.Return(*a);  // its rank failed
  EXPECT_EQ(p.unassigned_rows(), 20u);
  EXPECT_EQ(p.Next(1), (RowRange{0, 7}));
  EXPECT_EQ(p.Next(1), (RowRange{7, 7}));   // tail bound 13 / 2 = 6.5 rounds to 7
  EXPECT_EQ(p.Next(1), (RowRange{14, 3}));  // 6 left / 2 = 3
}

}  // namespace
}  // namespace prt
