// The refiner nodelet's launch-time settings (refiner_settings.hpp): the defaults pass their checks, a value out
// of range is named and the input settings fall back to their defaults.
#include <gtest/gtest.h>

#include "diffdope_ros/refiner_settings.hpp"

using diffdope_ros::RefinerSettings;

TEST(RefinerSettings, DefaultsPass) {
  RefinerSettings s;
  diffdope_ros::check_refiner_settings(s);
  EXPECT_EQ(s.error, "");
  EXPECT_EQ(s.queue_size, 10);
}

TEST(RefinerSettings, OutOfRangeIsNamedAndInputsFallBack) {
  RefinerSettings s;
  s.queue_size = 0;
  s.sync_timeout = 7.0;
  diffdope_ros::check_refiner_settings(s);
  EXPECT_NE(s.error.find("~queue_size"), std::string::npos) << s.error;
  EXPECT_EQ(s.queue_size, 10);
  EXPECT_DOUBLE_EQ(s.sync_timeout, 3.0);
}

TEST(RefinerSettings, EachRangeIsChecked) {
  const auto error_of = [](auto set) {
    RefinerSettings s;
    set(s);
    diffdope_ros::check_refiner_settings(s);
    return s.error;
  };
  EXPECT_NE(error_of([](RefinerSettings& s) { s.max_interval = 0; }).find("~max_interval"), std::string::npos);
  EXPECT_NE(error_of([](RefinerSettings& s) { s.tf_timeout = 61; }).find("~tf_timeout"), std::string::npos);
  EXPECT_NE(error_of([](RefinerSettings& s) { s.max_request_time = 0; }).find("~max_request_time"), std::string::npos);
  EXPECT_NE(error_of([](RefinerSettings& s) { s.error_throttle = -1; }).find("~error_throttle"), std::string::npos);
  EXPECT_NE(error_of([](RefinerSettings& s) { s.track.max_failures = 0; }), "");
}

TEST(RefinerSettings, MaskSourcesByName) {
  using diffdope_ros::MaskSource;
  EXPECT_EQ(diffdope_ros::parse_mask_source("none"), MaskSource::kNone);
  EXPECT_EQ(diffdope_ros::parse_mask_source("topic"), MaskSource::kTopic);
  EXPECT_EQ(diffdope_ros::parse_mask_source("box"), MaskSource::kBox);
  try {
    diffdope_ros::parse_mask_source("Topic");
    ADD_FAILURE() << "an unknown mask source was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("~mask_source: unknown 'Topic'"), std::string::npos) << e.what();
  }
  EXPECT_EQ(RefinerSettings().mask_source, MaskSource::kNone);  // DOPE gives no mask
}
