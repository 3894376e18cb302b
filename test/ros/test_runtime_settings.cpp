// Runtime settings <-> dynamic_reconfigure values (runtime_settings.hpp): a round trip keeps every value, the
// library's own checks refuse what the YAML would refuse, and what the config does not hold stays as it was.
#include <gtest/gtest.h>

#include "diffdope_ros/runtime_settings.hpp"

using diffdope_ros::RuntimeSettings;
using diffdope_ros::StreamMode;

namespace {

RuntimeSettings someSettings() {
  RuntimeSettings s;
  s.mode = StreamMode::kContinuous;
  s.refiner.iterations = 37;
  s.refiner.batch_size = 9;
  s.refiner.image_scale = 0.4;
  s.refiner.coarse_fraction = 0.25;
  s.refiner.lr_low = 0.002;
  s.refiner.lr_high = 0.02;
  s.refiner.early_stop_patience = 5;
  s.refiner.shape_tolerance = 0.03;
  s.refiner.shape_scan = false;
  s.refiner.print_search = 0.3;
  s.refiner.retry_turn = 0.4;
  s.refiner.loss.weight_rgb = 0.7;
  s.refiner.loss.weight_depth = 2.0;
  s.refiner.loss.weight_mask = 0.3;
  s.refiner.loss.weight_edges = 0.1;
  s.refiner.loss.weight_texture = 0.2;
  s.refiner.min_mask_iou = 0.6;
  s.refiner.min_depth_inliers = 0.7;
  s.refiner.min_print_significance = 2.5;
  s.refiner.render.lod_pixel_error = 0.5;  // not in the config: must survive
  s.publish_implausible = true;
  s.track.tracking = false;
  s.track.max_detection_age = 0.4;
  s.track.track_timeout = 2.0;
  s.track.max_failures = 4;
  s.track.predict = false;
  s.track.batch_size = 5;
  s.track.iterations = 17;
  return s;
}

}  // namespace

TEST(RuntimeSettings, RoundTripKeepsEveryValue) {
  const RuntimeSettings s = someSettings();
  const RuntimeSettings back = diffdope_ros::from_config(diffdope_ros::to_config(s), RuntimeSettings());
  EXPECT_EQ(back.mode, s.mode);
  EXPECT_EQ(back.refiner.iterations, 37);
  EXPECT_EQ(back.track.batch_size, 5);
  EXPECT_EQ(back.track.iterations, 17);
  EXPECT_EQ(back.refiner.batch_size, 9);
  EXPECT_DOUBLE_EQ(back.refiner.image_scale, 0.4);
  EXPECT_DOUBLE_EQ(back.refiner.coarse_fraction, 0.25);
  EXPECT_DOUBLE_EQ(back.refiner.lr_low, 0.002);
  EXPECT_DOUBLE_EQ(back.refiner.lr_high, 0.02);
  EXPECT_EQ(back.refiner.early_stop_patience, 5);
  EXPECT_DOUBLE_EQ(back.refiner.shape_tolerance, 0.03);
  EXPECT_FALSE(back.refiner.shape_scan);
  EXPECT_DOUBLE_EQ(back.refiner.print_search, 0.3);
  EXPECT_DOUBLE_EQ(back.refiner.retry_turn, 0.4);
  EXPECT_DOUBLE_EQ(back.refiner.loss.weight_rgb, 0.7);
  EXPECT_DOUBLE_EQ(back.refiner.loss.weight_depth, 2.0);
  EXPECT_DOUBLE_EQ(back.refiner.loss.weight_mask, 0.3);
  EXPECT_DOUBLE_EQ(back.refiner.loss.weight_edges, 0.1);
  EXPECT_DOUBLE_EQ(back.refiner.loss.weight_texture, 0.2);
  EXPECT_DOUBLE_EQ(back.refiner.min_mask_iou, 0.6);
  EXPECT_DOUBLE_EQ(back.refiner.min_depth_inliers, 0.7);
  EXPECT_DOUBLE_EQ(back.refiner.min_print_significance, 2.5);
  EXPECT_TRUE(back.publish_implausible);
  EXPECT_FALSE(back.track.tracking);  // continuous
  EXPECT_DOUBLE_EQ(back.track.max_detection_age, 0.4);
  EXPECT_DOUBLE_EQ(back.track.track_timeout, 2.0);
  EXPECT_EQ(back.track.max_failures, 4);
  EXPECT_FALSE(back.track.predict);
  // What the config does not hold comes from the base.
  EXPECT_DOUBLE_EQ(diffdope_ros::from_config(diffdope_ros::to_config(s), s).refiner.render.lod_pixel_error, 0.5);
  EXPECT_DOUBLE_EQ(back.refiner.render.lod_pixel_error, RuntimeSettings().refiner.render.lod_pixel_error);
}

TEST(RuntimeSettings, ModesAndTracking) {
  for (StreamMode m : {StreamMode::kContinuous, StreamMode::kTracking, StreamMode::kOnRequest})
    EXPECT_EQ(diffdope_ros::parse_stream_mode(diffdope_ros::to_string(m)), m);
  EXPECT_THROW(diffdope_ros::parse_stream_mode("sometimes"), std::invalid_argument);
  diffdope_ros::RefinerConfig c = diffdope_ros::to_config(RuntimeSettings());
  c.mode = "on_request";
  EXPECT_TRUE(diffdope_ros::from_config(c, RuntimeSettings()).track.tracking);  // seeds from its own results
  c.mode = "continuous";
  EXPECT_FALSE(diffdope_ros::from_config(c, RuntimeSettings()).track.tracking);
}

TEST(RuntimeSettings, RefusesWhatTheYamlRefuses) {
  const RuntimeSettings base;
  auto refused = [&](auto change) {
    diffdope_ros::RefinerConfig c = diffdope_ros::to_config(base);
    change(c);
    EXPECT_THROW(diffdope_ros::from_config(c, base), std::invalid_argument);
  };
  refused([](diffdope_ros::RefinerConfig& c) { c.lr_low = 0.5, c.lr_high = 0.1; });
  refused([](diffdope_ros::RefinerConfig& c) {
    c.weight_rgb = c.weight_depth = c.weight_mask = c.weight_edges = c.weight_texture = 0;
  });
  refused([](diffdope_ros::RefinerConfig& c) { c.mode = "sometimes"; });
  refused([](diffdope_ros::RefinerConfig& c) { c.batch_size = 0; });
  refused([](diffdope_ros::RefinerConfig& c) { c.max_track_failures = 0; });
  refused([](diffdope_ros::RefinerConfig& c) { c.image_scale = std::nan(""); });
}

// A change is named with both values; one at a bound of its range is flagged, since dynamic_reconfigure clamps a
// request outside the range (iterations -5, batch_size 100000, weight_depth inf) to that bound without a word.
TEST(RuntimeSettings, ChangesAreNamedAndValuesAtABoundAreFlagged) {
  const diffdope_ros::RefinerConfig before = diffdope_ros::to_config(RuntimeSettings());
  diffdope_ros::RefinerConfig after = before;
  after.iterations = 12;
  after.mode = "on_request";
  after.publish_implausible = true;
  auto changes = diffdope_ros::config_changes(before, after);
  ASSERT_EQ(changes.size(), 3u);
  EXPECT_EQ(diffdope_ros::describe(changes),
            "mode tracking -> on_request, iterations 48 -> 12, publish_implausible false -> true");
  EXPECT_EQ(diffdope_ros::bound_warning(changes), "");
  EXPECT_TRUE(diffdope_ros::config_changes(before, before).empty());

  after = before;
  after.__clamp__();  // (the defaults are inside every range)
  EXPECT_TRUE(diffdope_ros::config_changes(before, after).empty());
  after.iterations = -5;
  after.batch_size = 100000;
  after.weight_depth = std::numeric_limits<double>::infinity();
  after.__clamp__();  // what the server does to a request before the node's callback sees it
  changes = diffdope_ros::config_changes(before, after);
  ASSERT_EQ(changes.size(), 3u);
  for (const auto& c : changes) EXPECT_TRUE(c.at_bound) << c.name;
  const std::string warning = diffdope_ros::bound_warning(changes);
  EXPECT_NE(warning.find("iterations 0 (range 0 to 10000)"), std::string::npos) << warning;
  EXPECT_NE(warning.find("batch_size 1024 (range 1 to 1024)"), std::string::npos) << warning;
  EXPECT_NE(warning.find("weight_depth 1000 (range 0 to 1000)"), std::string::npos) << warning;
  EXPECT_NE(warning.find("clamps"), std::string::npos) << warning;
}
