// Reading and checking the refiner nodelet's ~parameters (refiner_settings.hpp).
#include "diffdope_ros/refiner_settings.hpp"

#include <ros/console.h>
#include <ros/node_handle.h>

#include <stdexcept>

#include "base/option_range.hpp"
#include "diffdope/option_table.hpp"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/runtime_settings.hpp"

namespace diffdope_ros {

MaskSource parse_mask_source(const std::string& name) {
  if (name == "none") return MaskSource::kNone;
  if (name == "topic") return MaskSource::kTopic;
  if (name == "box") return MaskSource::kBox;
  throw std::invalid_argument("~mask_source: unknown '" + name + "' (none, topic or box)");
}

void check_refiner_settings(RefinerSettings& s) {
  try {
    const diffdope::OptionRange check{"parameters"};
    check("~queue_size", s.queue_size, 1, 1000, " messages");
    check.above("~max_interval", s.max_interval, 0, 10, " seconds");
    check("~sync_timeout", s.sync_timeout, 0, 3600, " seconds");
    check("~tf_timeout", s.tf_timeout, 0, 60, " seconds");
    check.above("~max_request_time", s.max_request_time, 0, 3600, " seconds");
    check("~error_throttle", s.error_throttle, 0, 3600, " seconds");
    s.track.validate();
  } catch (const std::invalid_argument& e) {
    s.error = e.what();
    const RefinerSettings defaults;
    s.queue_size = defaults.queue_size;
    s.max_interval = defaults.max_interval;
    s.sync_timeout = defaults.sync_timeout;
    s.tf_timeout = defaults.tf_timeout;
    s.max_request_time = defaults.max_request_time;
  }
}

namespace {

/// The ~parameters among `names` that are set, each read as a `Value`; the first of the wrong type is `error`.
template <typename Value, typename Param>
void read_typed(const ros::NodeHandle& pnh, const std::vector<Param>& names, const char* type,
                std::vector<Param>& out, std::string& error) {
  for (Param p : names) {
    if (!pnh.hasParam(p.name)) continue;
    Value value{};
    if (pnh.getParam(p.name, value)) p.value = value, out.push_back(p);
    else if (error.empty()) error = "~" + p.name + ": expected " + type;
  }
}

/// The ~parameters named in cfg/Refiner.cfg that are set, each read once with its type; the first of the wrong
/// type goes to `error` (unless it holds one already).
dynamic_reconfigure::Config read_runtime_parameters(const ros::NodeHandle& pnh, std::string& error) {
  dynamic_reconfigure::Config names, out;
  RefinerConfig::__getDefault__().__toMessage__(names);
  read_typed<int>(pnh, names.ints, "an integer", out.ints, error);
  read_typed<double>(pnh, names.doubles, "a number", out.doubles, error);
  read_typed<bool>(pnh, names.bools, "true or false", out.bools, error);
  read_typed<std::string>(pnh, names.strs, "a string", out.strs, error);
  // A deprecated name is read as its current one when that is a parameter here. When both are set, the current
  // one holds: the reconfigure server writes it to the parameter server, where a respawned node finds it beside
  // the launch file's deprecated one.
  for (const diffdope::RenamedOption& r : diffdope::renamed_refiner_options()) {
    for (dynamic_reconfigure::DoubleParameter p : names.doubles) {
      if (p.name != r.current || !pnh.hasParam(r.deprecated)) continue;
      if (pnh.hasParam(r.current)) {
        ROS_WARN_STREAM("~" << r.deprecated << " is deprecated and ignored: ~" << r.current << " is set");
      } else if (pnh.getParam(r.deprecated, p.value)) {
        ROS_WARN_STREAM("~" << r.deprecated << " is deprecated: read as ~" << r.current);
        out.doubles.push_back(p);
      } else if (error.empty()) {
        error = std::string("~") + r.deprecated + ": expected a number";
      }
    }
  }
  return out;
}

}  // namespace

RefinerSettings load_refiner_settings(const ros::NodeHandle& pnh, const std::string& node_name,
                                      ErrorReporter& errors) {
  RefinerSettings s;
  s.runtime_parameters = read_runtime_parameters(pnh, s.error);
  // mode, publish_implausible and the track options: TrackOptions' defaults, then the ~parameters.
  RefinerConfig runtime = to_config(RuntimeSettings{s.mode, {}, s.track, s.publish_implausible});
  runtime.__fromMessage__(s.runtime_parameters);
  try {
    parse_stream_mode(runtime.mode);
  } catch (const std::invalid_argument& e) {
    ROS_ERROR_STREAM_NAMED(node_name, "~" << e.what() << "; using tracking");
    runtime.mode = to_string(StreamMode::kTracking);
  }
  const RuntimeSettings taken = with_config(runtime, RuntimeSettings());
  s.mode = taken.mode;
  s.track = taken.track;  // (track.tracking follows the mode)
  s.publish_implausible = taken.publish_implausible;
  s.use_depth = pnh.param("use_depth", s.use_depth);
  // ~mask_source, or the older ~use_mask (true: the topic); both, disagreeing, is a configuration error.
  const bool use_mask = pnh.param("use_mask", false);
  const std::string source = pnh.param<std::string>("mask_source", "");
  try {
    s.mask_source = source.empty() ? (use_mask ? MaskSource::kTopic : MaskSource::kNone) : parse_mask_source(source);
    if (use_mask && s.mask_source != MaskSource::kTopic)
      throw std::invalid_argument("~use_mask is true but ~mask_source is '" + source + "' (use ~mask_source alone)");
  } catch (const std::invalid_argument& e) {
    s.error = e.what();
  }
  s.use_mask = s.mask_source == MaskSource::kTopic;
  s.queue_size = pnh.param("queue_size", s.queue_size);
  s.max_interval = pnh.param("max_interval", s.max_interval);
  s.sync_timeout = pnh.param("sync_timeout", s.sync_timeout);
  s.tf_timeout = pnh.param("tf_timeout", s.tf_timeout);
  s.max_request_time = pnh.param("max_request_time", s.max_request_time);
  s.frame_prefix = pnh.param("frame_prefix", s.frame_prefix);
  s.fixed_frame = pnh.param("fixed_frame", s.fixed_frame);
  s.detection_prefix = pnh.param("detection_topic_prefix", s.detection_prefix);
  s.detections_topic = pnh.param("detections_topic", s.detections_topic);
  XmlRpc::XmlRpcValue ids;
  if (pnh.getParam("class_ids", ids)) {
    // DOPE's own layout: {object name: class id}.
    if (ids.getType() != XmlRpc::XmlRpcValue::TypeStruct) {
      errors.error("config", "~class_ids: expected a mapping of object names to DOPE class ids, e.g. {cracker: 1}");
    } else {
      for (auto& kv : ids) {
        if (kv.second.getType() == XmlRpc::XmlRpcValue::TypeInt) s.class_ids[kv.first] = static_cast<int>(kv.second);
        else errors.error("config", "~class_ids: the id of '" + kv.first + "' is not an integer: ignored");
      }
    }
  }
  s.publish_tf = pnh.param("publish_tf", s.publish_tf);
  s.error_throttle = pnh.param("error_throttle", s.error_throttle);
  s.objects_config = pnh.param<std::string>("objects_config", "");
  s.refiner_config = pnh.param<std::string>("refiner_config", "");
  s.device = pnh.param<std::string>("device", "");
  check_refiner_settings(s);
  return s;
}

}  // namespace diffdope_ros
