#pragma once
// Where the refiner's initial poses arrive: per-object PoseStamped topics (DOPE's /dope/pose_<name>), the node's
// ~initial_poses (InitialPoseArray) and DOPE's Detection3DArray (~detections_topic). Each message is checked and
// kept, the newest per object, until the worker takes them for its next frame.
#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <topic_tools/shape_shifter.h>

#include <atomic>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "diffdope_ros/InitialPoseArray.h"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/refiner_settings.hpp"

namespace diffdope_ros {

class DetectionInbox {
 public:
  struct Object {
    std::string name;
    int max_instances = 1;
    std::string pose_topic;  // "" = ~detection_topic_prefix + name
  };
  using Poses = std::vector<geometry_msgs::PoseStamped>;

  DetectionInbox(std::vector<Object> objects, const RefinerSettings& settings, ErrorReporter& errors);
  void subscribe(ros::NodeHandle& nh, ros::NodeHandle& pnh);
  /// The poses received since the last call, per object index (raw, any frame; several = several instances).
  std::vector<std::pair<size_t, Poses>> take();
  /// From the watchdog: subscribes the Detection3DArray topic afresh once a publisher of another type has gone.
  void resubscribeIfNeeded();
  void addDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat);
  void shutdown();

 private:
  void onDetection(const geometry_msgs::PoseStampedConstPtr& msg, size_t object);
  void onInitialPoses(const diffdope_ros::InitialPoseArrayConstPtr& msg);
  /// DOPE's vision_msgs/Detection3DArray, read as a ShapeShifter (detection3d_array.hpp).
  void onDetectionArray(const topic_tools::ShapeShifter::ConstPtr& msg);
  void subscribeDetectionArray();
  /// Checks and keeps one detector message's poses of an object (one per instance it saw).
  void store(const Poses& poses, size_t object, const std::string& origin);

  const std::vector<Object> objects_;
  const RefinerSettings& settings_;
  ErrorReporter& errors_;
  ros::NodeHandle nh_;

  std::mutex mutex_;
  std::vector<std::optional<Poses>> pending_;  // per object (mutex_)
  struct ArrayCounts {
    long received = 0, malformed = 0;  // arrays
    long known_class = 0, unknown_class = 0, malformed_detections = 0;  // detections in the arrays
  } array_counts_;  // (mutex_)

  std::vector<ros::Subscriber> pose_subs_;
  ros::Subscriber initial_poses_sub_, array_sub_;
  std::atomic<bool> resubscribe_{false};  // a Detection3DArray publisher of another type was seen
};

}  // namespace diffdope_ros
