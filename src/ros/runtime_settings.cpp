// Runtime settings <-> dynamic_reconfigure values (runtime_settings.hpp).
#include "diffdope_ros/runtime_settings.hpp"

#include <stdexcept>

namespace diffdope_ros {

const char* to_string(StreamMode mode) {
  switch (mode) {
    case StreamMode::kContinuous: return "continuous";
    case StreamMode::kTracking: return "tracking";
    case StreamMode::kOnRequest: return "on_request";
  }
  return "?";
}

StreamMode parse_stream_mode(const std::string& name) {
  for (StreamMode m : {StreamMode::kContinuous, StreamMode::kTracking, StreamMode::kOnRequest})
    if (name == to_string(m)) return m;
  throw std::invalid_argument("mode: unknown value '" + name + "' (continuous, tracking, on_request)");
}

RefinerConfig to_config(const RuntimeSettings& s) {
  RefinerConfig c = RefinerConfig::__getDefault__();
  c.mode = to_string(s.mode);
  const diffdope::RefinerOptions& o = s.refiner;
  c.iterations = o.iterations;
  c.batch_size = o.batch_size;
  c.image_scale = o.image_scale;
  c.coarse_fraction = o.coarse_fraction;
  c.lr_low = o.lr_low;
  c.lr_high = o.lr_high;
  c.early_stop_patience = o.early_stop_patience;
  c.explore_tolerance = o.explore_tolerance;
  c.print_search = o.print_search;
  c.retry_turn = o.retry_turn;
  c.weight_rgb = o.loss.weight_rgb;
  c.weight_depth = o.loss.weight_depth;
  c.weight_mask = o.loss.weight_mask;
  c.weight_edges = o.loss.weight_edges;
  c.weight_texture = o.loss.weight_texture;
  c.min_mask_iou = o.min_mask_iou;
  c.min_depth_inliers = o.min_depth_inliers;
  c.min_print_significance = o.min_print_significance;
  c.publish_implausible = s.publish_implausible;
  c.max_detection_age = s.track.max_detection_age;
  c.track_timeout = s.track.track_timeout;
  c.max_track_failures = s.track.max_failures;
  c.predict_motion = s.track.predict;
  c.track_batch_size = s.track.batch_size;
  c.track_iterations = s.track.iterations;
  return c;
}

RuntimeSettings from_config(const RefinerConfig& c, const RuntimeSettings& base) {
  RuntimeSettings s = base;
  s.mode = parse_stream_mode(c.mode);
  diffdope::RefinerOptions& o = s.refiner;
  o.iterations = c.iterations;
  o.batch_size = c.batch_size;
  o.image_scale = c.image_scale;
  o.coarse_fraction = c.coarse_fraction;
  o.lr_low = c.lr_low;
  o.lr_high = c.lr_high;
  o.early_stop_patience = c.early_stop_patience;
  o.explore_tolerance = c.explore_tolerance;
  o.print_search = c.print_search;
  o.retry_turn = c.retry_turn;
  o.loss.weight_rgb = c.weight_rgb;
  o.loss.weight_depth = c.weight_depth;
  o.loss.weight_mask = c.weight_mask;
  o.loss.weight_edges = c.weight_edges;
  o.loss.weight_texture = c.weight_texture;
  o.min_mask_iou = c.min_mask_iou;
  o.min_depth_inliers = c.min_depth_inliers;
  o.min_print_significance = c.min_print_significance;
  s.publish_implausible = c.publish_implausible;
  s.track.tracking = s.mode != StreamMode::kContinuous;  // on_request seeds from its own previous results too
  s.track.max_detection_age = c.max_detection_age;
  s.track.track_timeout = c.track_timeout;
  s.track.max_failures = c.max_track_failures;
  s.track.predict = c.predict_motion;
  s.track.batch_size = c.track_batch_size;
  s.track.iterations = c.track_iterations;
  o.validate();  // the same checks as the YAML's
  s.track.validate();
  return s;
}

}  // namespace diffdope_ros
