// The refiner's initial poses as they arrive (detection_inbox.hpp).
#include "ros/refiner/detection_inbox.hpp"

#include <boost/bind/bind.hpp>

#include <map>

#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/detection3d_array.hpp"
#include "diffdope_ros/detection_selection.hpp"

namespace diffdope_ros {

DetectionInbox::DetectionInbox(std::vector<Object> objects, const RefinerSettings& settings, ErrorReporter& errors)
    : objects_(std::move(objects)), settings_(settings), errors_(errors), pending_(objects_.size()) {}

void DetectionInbox::subscribe(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
  nh_ = nh;
  for (size_t i = 0; i < objects_.size(); ++i) {
    const Object& o = objects_[i];
    const std::string topic = o.pose_topic.empty() ? settings_.detection_prefix + o.name : o.pose_topic;
    pose_subs_.push_back(nh.subscribe<geometry_msgs::PoseStamped>(
        topic, 5, boost::bind(&DetectionInbox::onDetection, this, boost::placeholders::_1, i)));
  }
  initial_poses_sub_ = pnh.subscribe("initial_poses", 5, &DetectionInbox::onInitialPoses, this);
  if (settings_.detections_topic.empty()) return;
  subscribeDetectionArray();
  for (const Object& o : objects_)
    if (!settings_.class_ids.count(o.name))
      errors_.warn("class_ids", "object '" + o.name + "' has no id in ~class_ids: " + settings_.detections_topic +
                                    " cannot seed it");
}

void DetectionInbox::shutdown() {
  initial_poses_sub_.shutdown();
  for (auto& s : pose_subs_) s.shutdown();
  array_sub_.shutdown();
}

std::vector<std::pair<size_t, DetectionInbox::Poses>> DetectionInbox::take() {
  std::vector<std::pair<size_t, Poses>> out;
  std::lock_guard<std::mutex> lock(mutex_);
  for (size_t i = 0; i < pending_.size(); ++i)
    if (pending_[i]) {
      out.emplace_back(i, std::move(*pending_[i]));
      pending_[i].reset();
    }
  return out;
}

void DetectionInbox::onDetection(const geometry_msgs::PoseStampedConstPtr& msg, size_t object) {
  store({*msg}, object, "detection for '" + objects_[object].name + "'");
}

void DetectionInbox::onInitialPoses(const diffdope_ros::InitialPoseArrayConstPtr& msg) {
  std::map<size_t, Poses> by_object;  // entries of one name: its instances
  for (const auto& p : msg->poses) {
    size_t i = 0;
    while (i < objects_.size() && objects_[i].name != p.name) ++i;
    if (i == objects_.size()) {
      errors_.error("unknown_object", "~initial_poses: unknown object name '" + p.name + "' (not in the objects config)");
      continue;
    }
    by_object[i].push_back(p.pose);
  }
  for (const auto& [i, poses] : by_object) store(poses, i, "~initial_poses entry for '" + objects_[i].name + "'");
}

void DetectionInbox::store(const Poses& poses, size_t object, const std::string& origin) {
  Poses usable;
  for (const auto& pose : poses) {
    try {
      pose_from_msg(pose.pose, origin);  // reject NaN / zero quaternions at once
      if (pose.header.frame_id.empty()) throw std::invalid_argument(origin + ": empty header.frame_id");
      usable.push_back(pose);
    } catch (const std::exception& e) {
      errors_.error("pose/" + objects_[object].name, std::string("initial pose ignored: ") + e.what());
    }
  }
  if (usable.empty()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  auto& pending = pending_[object];
  // The newest message wins; but with several instances, messages of the same stamp are one detection round
  // (a detector that publishes a PoseStamped per instance, one after the other).
  if (pending && !pending->empty() && objects_[object].max_instances > 1 &&
      pending->front().header.stamp == usable.front().header.stamp)
    pending->insert(pending->end(), usable.begin(), usable.end());
  else
    pending = std::move(usable);
}

void DetectionInbox::subscribeDetectionArray() {
  array_sub_.shutdown();
  array_sub_ = nh_.subscribe<topic_tools::ShapeShifter>(settings_.detections_topic, 5,
                                                        &DetectionInbox::onDetectionArray, this);
}

void DetectionInbox::resubscribeIfNeeded() {
  // Once the publisher of the other type has gone (while it is connected a new subscription would take its type
  // again, and a publisher of the right one still could not connect).
  if (resubscribe_ && array_sub_.getNumPublishers() == 0) {
    resubscribe_ = false;
    subscribeDetectionArray();
  }
}

void DetectionInbox::onDetectionArray(const topic_tools::ShapeShifter::ConstPtr& msg) {
  const auto count = [this](long ArrayCounts::*field, long n) {
    std::lock_guard<std::mutex> lock(mutex_);
    array_counts_.*field += n;
  };
  count(&ArrayCounts::received, 1);
  const std::string where = "~detections_topic " + settings_.detections_topic + ": ";
  if (msg->getDataType() != kDetection3DArrayType || msg->getMD5Sum() != kDetection3DArrayMd5) {
    count(&ArrayCounts::malformed, 1);
    errors_.error("detections", where + "a " + msg->getDataType() + " (MD5 " + msg->getMD5Sum() + "), expected " +
                                    kDetection3DArrayType + " with MD5 " + kDetection3DArrayMd5 +
                                    " (DOPE's, integer class ids): ignored");
    // A ROS 1 subscription keeps the type of the first publisher it connects to: subscribe afresh (from the
    // watchdog, outside this callback) so that a publisher of the right type can still connect.
    resubscribe_ = true;
    return;
  }
  DecodedDetectionArray decoded;
  try {
    std::vector<uint8_t> bytes(msg->size());
    ros::serialization::OStream out(bytes.data(), uint32_t(bytes.size()));
    msg->write(out);
    decoded = decode_detection3d_array(bytes.data(), bytes.size());
  } catch (const std::exception& e) {
    count(&ArrayCounts::malformed, 1);
    errors_.error("detections", where + e.what() + ": ignored");
    return;
  }
  const DetectionSelection chosen = select_detections(decoded, settings_.class_ids);
  count(&ArrayCounts::malformed_detections, long(chosen.unusable.size()));
  if (!chosen.unusable.empty())
    errors_.error("detections/unusable", where + std::to_string(chosen.unusable.size()) + " of " +
                                    std::to_string(decoded.detections.size()) + " detection(s) ignored (first: " +
                                    chosen.unusable.front() + "); the others are used");
  count(&ArrayCounts::unknown_class, long(chosen.unknown_class_ids.size()));
  if (!chosen.unknown_class_ids.empty())
    errors_.warn("class_ids", where + std::to_string(chosen.unknown_class_ids.size()) +
                                  " detection(s) with a class id no object has in ~class_ids (first: " +
                                  std::to_string(chosen.unknown_class_ids.front()) + ")");
  for (const auto& [name, poses] : chosen.by_object) {
    for (size_t i = 0; i < objects_.size(); ++i) {
      if (objects_[i].name != name) continue;
      count(&ArrayCounts::known_class, long(poses.size()));
      store(poses, i, where + "class id " + std::to_string(settings_.class_ids.at(name)) + " ('" + name + "')");
    }
  }
}

void DetectionInbox::addDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  if (settings_.detections_topic.empty()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  const ArrayCounts& c = array_counts_;
  // Of the detections of a known class, those beyond an object's max_instances are counted by the refiner.
  stat.add("input detections (Detection3DArray)",
           "received " + std::to_string(c.received) + " arrays (malformed " + std::to_string(c.malformed) +
               "); detections of a known class " + std::to_string(c.known_class) + ", of an unknown class id " +
               std::to_string(c.unknown_class) + ", unusable " + std::to_string(c.malformed_detections));
}

}  // namespace diffdope_ros
