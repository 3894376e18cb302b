#pragma once
// The refiner nodelet's launch-time ~parameters, read once into one value and checked in one place; the node
// then only reads them. What may change while it runs (mode, refiner and track options) starts from here and
// lives in RuntimeSettings. Names and defaults: docs/ros.md.
#include <cstdint>
#include <map>
#include <string>

#include <dynamic_reconfigure/Config.h>

#include "diffdope/object_track.hpp"
#include "diffdope_ros/stream_mode.hpp"

namespace ros {
class NodeHandle;
}

namespace diffdope_ros {

class ErrorReporter;

/// ~mask_source: what tells the refiner which pixels are the object's. kNone: nothing, as beside DOPE (with depth
/// the refiner derives them); kTopic: the `mask` topic; kBox: the detector's box, the object's box projected at
/// the detected pose (DOPE's projected cuboid), which bounds where its pixels are sought.
enum class MaskSource { kNone, kTopic, kBox };
/// "none", "topic", "box"; std::invalid_argument naming the value otherwise.
MaskSource parse_mask_source(const std::string& name);

struct RefinerSettings {
  StreamMode mode = StreamMode::kTracking;  // ~mode
  bool use_depth = true;                    // ~use_depth
  MaskSource mask_source = MaskSource::kNone;  // ~mask_source (or the older ~use_mask: true = topic)
  bool use_mask = false;                    // mask_source == kTopic: subscribe to and synchronise `mask`
  bool publish_tf = true;                   // ~publish_tf
  bool publish_implausible = false;         // ~publish_implausible
  int queue_size = 10;                      // ~queue_size (messages)
  double max_interval = 0.1;                // ~max_interval (s): stamps of one synchronized set
  double sync_timeout = 3.0;                // ~sync_timeout (s): no synchronized set for this long is an error
  double tf_timeout = 0.1;                  // ~tf_timeout (s, wall time)
  /// ~max_request_time (s): a ~refine call estimated to take longer is refused (it would stop streaming that long).
  double max_request_time = 10.0;
  double error_throttle = 5.0;              // ~error_throttle (s): one log line per error category and period
  std::string frame_prefix = "diffdope_";   // ~frame_prefix: TF child frame = prefix + instance name
  std::string fixed_frame;                  // ~fixed_frame: detections stamped at another time go through it
  std::string detection_prefix = "/dope/pose_";  // ~detection_topic_prefix
  std::string detections_topic;             // ~detections_topic: DOPE's Detection3DArray ("" = off)
  std::map<std::string, int64_t> class_ids;  // ~class_ids: object name -> DOPE class id
  /// ~max_detection_age, ~track_timeout, ~max_track_failures, ~predict_motion, ~max_extrapolation,
  /// ~track_batch_size, ~track_iterations (TrackOptions' defaults); tracking follows the mode.
  diffdope::TrackOptions track;
  /// The ~parameters of cfg/Refiner.cfg that are set (mode, publish_implausible and the track options above are
  /// taken from them here; the refiner options override the YAMLs' when the objects are loaded).
  dynamic_reconfigure::Config runtime_parameters;
  std::string objects_config;               // ~objects_config (required)
  std::string refiner_config;               // ~refiner_config: overrides the objects file's refiner section
  std::string device;                       // ~device ("" = the YAML's choice)
  /// The first value out of its range (check_refiner_settings): a configuration error, nothing is refined.
  std::string error;
};

/// Range checks. On a value outside its range `error` names it, and the input settings go back to their
/// defaults, so that the inputs still come up and their counts and diagnostics keep working.
void check_refiner_settings(RefinerSettings& settings);

/// Reads every ~parameter of `pnh` once and checks them (check_refiner_settings). An unknown ~mode is logged
/// (as `node_name`) and read as tracking; a malformed ~class_ids goes to `errors`. A parameter of
/// cfg/Refiner.cfg of the wrong type (iterations: "many") is a configuration error naming it.
RefinerSettings load_refiner_settings(const ros::NodeHandle& pnh, const std::string& node_name,
                                      ErrorReporter& errors);

}  // namespace diffdope_ros
