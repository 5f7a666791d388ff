// The whole run's ETA (farm/run_eta.h) on an injected clock.
#include "farm/run_eta.h"

#include <gtest/gtest.h>

namespace prt {
namespace {

TEST(RunEtaTest, PriorsThenMeasuredCostsThenTheMachinesSpeed) {
  double now = 100;
  RunEta eta([&now] { return now; });
  EXPECT_EQ(eta.RemainingSeconds(-1), -1);
  EXPECT_EQ(eta.Suffix(-1), "");
  // Two dense steps, a rank step and a packing step; priors sum to 10 + 2 + 20 + 4 = 36 s.
  eta.SetSteps({{"dense-initial", "dense", 100, 0.1},
                {"rank-1", "rank", 200, 0.01},
                {"dense-rank-1", "dense", 200, 0.1},
                {"pack", "pack", 4e9, 1e-9}});
  EXPECT_DOUBLE_EQ(eta.RemainingSeconds(-1), 36.0);
  eta.StepStarted("dense-initial");
  now += 5;
  // The running step's own ETA replaces its prediction.
  EXPECT_DOUBLE_EQ(eta.RemainingSeconds(7.0), 7.0 + 2 + 20 + 4);
  EXPECT_DOUBLE_EQ(eta.RemainingSeconds(-1), 5.0 + 2 + 20 + 4);
  now += 15;  // it took 20 s: 0.2 s per dense row, twice the prior
  eta.StepFinished("dense-initial");
  // The dense kind is measured (0.2 s/row: 40 s); the other priors run at the measured speed (2×).
  EXPECT_DOUBLE_EQ(eta.RemainingSeconds(-1), 2 * 2.0 + 40.0 + 2 * 4.0);
  EXPECT_EQ(eta.Suffix(-1), " | run 28% ETA 52.0s");
  eta.StepStarted("rank-1");
  now += 2;
  eta.StepFinished("rank-1");  // 2 s for a 2 s prior: the speed over both steps is 22/12
  EXPECT_NEAR(eta.RemainingSeconds(-1), 40.0 + 4.0 * 22.0 / 12.0, 1e-12);
  const std::vector<RunEtaSample> h = eta.History();
  ASSERT_EQ(h.size(), 2u);
  EXPECT_EQ(h[0].step, "dense-initial");
  EXPECT_DOUBLE_EQ(h[0].elapsed_s, 0.0);
  EXPECT_DOUBLE_EQ(h[0].predicted_total_s, 36.0);
  EXPECT_DOUBLE_EQ(h[1].elapsed_s, 20.0);
  EXPECT_DOUBLE_EQ(h[1].predicted_total_s, 20.0 + 52.0);
  // Unknown steps are ignored.
  eta.StepStarted("no-such-step");
  EXPECT_NEAR(eta.RemainingSeconds(-1), 40.0 + 4.0 * 22.0 / 12.0, 1e-12);
}

}  // namespace
}  // namespace prt
