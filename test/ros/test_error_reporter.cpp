// ErrorReporter: every error counted and kept for diagnostics; the log is throttled per category, so one noisy
// input cannot hide another kind of error.
#include <gtest/gtest.h>

#include "diffdope_ros/error_reporter.hpp"

TEST(ErrorReporter, CountsEveryErrorKeepsTheLastAndSeparatesWarnings) {
  diffdope_ros::ErrorReporter r(60.0);
  r.error("input/rgb image", "rgb image: unsupported encoding '32FC1'");
  r.error("input/rgb image", "rgb image: unsupported encoding '16UC3'");
  r.error("pose/box", "initial pose of 'box': NaN");
  r.warn("lost_box", "lost track of 'box'");
  const auto s = r.summary();
  EXPECT_EQ(s.error_counts.at("input/rgb image"), 2);
  EXPECT_EQ(s.error_counts.at("pose/box"), 1);
  EXPECT_EQ(s.warn_counts.at("lost_box"), 1);
  EXPECT_EQ(s.last_error, "initial pose of 'box': NaN");  // warnings do not replace the last error
  EXPECT_GT(s.last_error_time, 0.0);
}

TEST(ErrorReporter, NoErrorYet) {
  diffdope_ros::ErrorReporter r;
  const auto s = r.summary();
  EXPECT_TRUE(s.last_error.empty());
  EXPECT_EQ(s.last_error_time, 0.0);
  EXPECT_TRUE(s.error_counts.empty());
}
