// The service's time budget: planned evaluations times a cost learned from timed refinements, and the refusal
// a caller gets when a request would not fit.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "diffdope/pose_curvature.hpp"
#include "diffdope/print_alignment.hpp"
#include "diffdope/refine_time.hpp"

using namespace diffdope;

TEST(PlannedEvaluations, RunsTimesIterationsLessWhatHalvingDrops) {
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 100;
  o.shape_tolerance = 0;  // no shape scan, print alignment nor shape turns
  o.successive_halving = false;
  o.probe_distance = 0;  // no curvature probe
  o.polish_iterations = 0;
  o.newton_rounds = 0;
  o.derive_mask = false;  // (below)
  EXPECT_EQ(planned_evaluations(o), 16 * 101 + 2);
  o.successive_halving = true;  // 25 iterations each at 16, 8, 4, 2 runs, then the last evaluation at 2
  EXPECT_EQ(planned_evaluations(o), 16 * 25 + 8 * 25 + 4 * 25 + 2 * 25 + 2 + 2);
  o.iterations = 0;
  EXPECT_EQ(planned_evaluations(o), 16 + 2);
  o.probe_distance = 0.01;
  EXPECT_EQ(planned_evaluations(o), 16 + 2 + kCurvatureProbeEvaluations);
  // Newton steps: none when scoring the start; otherwise a render for the pixel count, then per round a probe
  // and three tries (at most: the rounds end at a step that is not clearly better).
  o.newton_rounds = 2;
  EXPECT_EQ(planned_evaluations(o), 16 + 2 + kCurvatureProbeEvaluations);
  o.iterations = 100;
  o.probe_distance = 0;
  EXPECT_EQ(planned_evaluations(o), 16 * 25 + 8 * 25 + 4 * 25 + 2 * 25 + 2 + 2 + 1 + 2 * (kSecantProbePoses + 3));
  // With the shape scan, and so the print alignment: when the steps move far, the alignment and the steps run
  // once more; and all that again from the shape turn the print prefers at the result.
  o.shape_tolerance = 0.01;
  o.newton_rounds = 0;
  const long without = planned_evaluations(o);
  o.newton_rounds = 2;
  const long newton = 1 + 2 * (kSecantProbePoses + 3), print = print_alignment_evaluations(o.print_search) + 3;
  EXPECT_EQ(planned_evaluations(o) - without, 2 * (2 * newton + print));
  // Without a mask: the renders the pixels are derived about (the starts, at most one per run; the better half;
  // the result), and the result's and the starts' losses under the last pixels.
  const long masked = planned_evaluations(o);
  o.derive_mask = true;
  EXPECT_EQ(planned_evaluations(o) - masked, 16 + 8 + 2 + 16);
}

TEST(RefineTimeEstimator, UsesThePriorUntilARefinementWasTimed) {
  RefineTimeEstimator e(2e-3);
  RefinerOptions o;
  EXPECT_EQ(e.observations(), 0);
  EXPECT_DOUBLE_EQ(e.estimate(o, 3), 3 * planned_evaluations(o) * 2e-3);
  e.observe(1000, 0.5);
  EXPECT_EQ(e.observations(), 1);
  EXPECT_DOUBLE_EQ(e.seconds_per_evaluation(), 0.5e-3);
  EXPECT_DOUBLE_EQ(e.estimate(o, 2), 2 * planned_evaluations(o) * 0.5e-3);
  EXPECT_DOUBLE_EQ(e.estimate(o, 0), 0.0);
  EXPECT_THROW(RefineTimeEstimator(0), std::invalid_argument);
  EXPECT_THROW(RefineTimeEstimator(std::nan("")), std::invalid_argument);
}

TEST(RefineTimeEstimator, RecentRefinementsWeighedByTheirWorkUntilForgotten) {
  RefineTimeEstimator e;
  e.observe(1000, 3.0);  // a big object, or a busy machine
  for (int i = 0; i < RefineTimeEstimator::kWindow - 1; ++i) e.observe(1000, 1.0);
  EXPECT_DOUBLE_EQ(e.seconds_per_evaluation(), (3.0 + 15.0) / 16000);
  e.observe(1000, 1.0);  // the slow one leaves the window
  EXPECT_DOUBLE_EQ(e.seconds_per_evaluation(), 1e-3);
  // A tiny call whose fixed costs dominate (20 evaluations in 50 ms) hardly moves the estimate.
  e.observe(20, 0.05);
  EXPECT_NEAR(e.seconds_per_evaluation(), 1e-3, 0.05e-3);
}

TEST(RefineTimeEstimator, IgnoresTimingsThatMeanNothing) {
  RefineTimeEstimator e(1e-3);
  const double inf = std::numeric_limits<double>::infinity();
  e.observe(0, 1.0);
  e.observe(1000, 0);
  e.observe(1000, -1);
  e.observe(std::nan(""), 1.0);
  e.observe(1000, inf);
  EXPECT_EQ(e.observations(), 0);
  EXPECT_DOUBLE_EQ(e.seconds_per_evaluation(), 1e-3);
}

TEST(CheckRequestTime, PassesWhatFitsAndRefusesWithTheIterationsThatWouldFit) {
  RefineTimeEstimator e;
  e.observe(1000, 1.0);  // 1 ms per evaluation
  RefinerOptions o;      // 32 runs x 100 iterations with halving: ~1.5 k evaluations
  EXPECT_EQ(check_request_time(o, 2, e, 10.0), "");
  o.iterations = 1000;
  o.batch_size = 256;
  const std::string why = check_request_time(o, 3, e, 10.0);
  ASSERT_FALSE(why.empty());
  EXPECT_NE(why.find("~max_request_time = 10.0 s"), std::string::npos) << why;
  EXPECT_NE(why.find("as measured here"), std::string::npos) << why;
  // The iteration count it names fits; one more does not.
  const auto at = why.find("at most ");
  ASSERT_NE(at, std::string::npos) << why;
  const int fit = std::stoi(why.substr(at + 8));
  o.iterations = fit;
  EXPECT_EQ(check_request_time(o, 3, e, 10.0), "");
  o.iterations = fit + 1;
  EXPECT_NE(check_request_time(o, 3, e, 10.0), "");
  // Too many runs for even one iteration.
  o.batch_size = 1024;
  EXPECT_NE(check_request_time(o, 3, e, 1.0).find("not even one iteration"), std::string::npos);
}
