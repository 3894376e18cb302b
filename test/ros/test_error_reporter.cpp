// ErrorReporter: every error counted and kept for diagnostics; the log is throttled per category, so one noisy
// input cannot hide another kind of error.
#include <gtest/gtest.h>

#include <stdexcept>

#include "diffdope_ros/error_reporter.hpp"
#include "ros/refiner/input_sync.hpp"

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

TEST(ErrorReporter, CategoriesAreBounded) {
  // 400 errors, each its own category (a caller that put a value in it): the diagnostics keep at most
  // kMaxCategories entries and count the rest together, so nothing grows without bound and the log stays
  // throttled.
  diffdope_ros::ErrorReporter r(60.0);
  for (int i = 0; i < 400; ++i) r.error("size " + std::to_string(i), "image of size " + std::to_string(i));
  r.warn("lost_box", "lost track of 'box'");
  const auto s = r.summary();
  ASSERT_EQ(s.error_counts.size(), diffdope_ros::ErrorReporter::kMaxCategories);
  long total = 0;
  for (const auto& [category, count] : s.error_counts) total += count;
  EXPECT_EQ(total, 400);
  EXPECT_EQ(s.error_counts.at("other"), 400 - long(diffdope_ros::ErrorReporter::kMaxCategories - 1));
  EXPECT_EQ(s.error_counts.at("size 0"), 1);  // the first ones keep their own
  EXPECT_EQ(s.last_error, "image of size 399");
  EXPECT_EQ(s.warn_counts.at("lost_box"), 1);  // warnings have their own bound
}

TEST(ErrorReporter, AnInputErrorIsCategorisedByItsInputNotItsText) {
  // 400 depth images of 400 sizes: one category, "input/depth"; a message that names no input is "input/other".
  diffdope_ros::ErrorReporter r(60.0);
  for (int i = 0; i < 400; ++i)
    diffdope_ros::report_input_error(
        r, std::invalid_argument("depth image is " + std::to_string(i) + "x480 but rgb is 640x480"));
  diffdope_ros::report_input_error(r, std::invalid_argument("camera_info: P has a non-finite value"));
  diffdope_ros::report_input_error(r, std::invalid_argument("something else"));
  const auto s = r.summary();
  ASSERT_EQ(s.error_counts.size(), 3u);
  EXPECT_EQ(s.error_counts.at("input/depth"), 400);
  EXPECT_EQ(s.error_counts.at("input/camera_info"), 1);
  EXPECT_EQ(s.error_counts.at("input/other"), 1);
}

TEST(ErrorReporter, AnUnthrottledErrorIsCountedAndKeptAsEver) {
  diffdope_ros::ErrorReporter r(60.0);
  r.error("reconfigure", "reconfigure refused: iterations", diffdope_ros::ErrorReporter::Logging::kEveryTime);
  r.error("reconfigure", "reconfigure refused: batch_size", diffdope_ros::ErrorReporter::Logging::kEveryTime);
  const auto s = r.summary();
  EXPECT_EQ(s.error_counts.at("reconfigure"), 2);
  EXPECT_EQ(s.last_error, "reconfigure refused: batch_size");
}
