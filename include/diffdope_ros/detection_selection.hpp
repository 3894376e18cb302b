#pragma once
// Which detection of DOPE's Detection3DArray seeds which object (the ROS side of detection3d_array.hpp).
#include <geometry_msgs/PoseStamped.h>

#include <map>
#include <string>
#include <vector>

#include "diffdope_ros/detection3d_array.hpp"

namespace diffdope_ros {

/// What a decoded array gives each object: every detection's best-scoring hypothesis, named through `class_ids`
/// (object name -> DOPE class id, DOPE's own `class_ids` parameter); an object's detections (one per instance
/// seen) highest score first; stamped and framed by the detection's header (the array's when the detection's
/// frame is empty). Which instance each one is, the node's InstanceTracks decide.
struct DetectionSelection {
  std::map<std::string, std::vector<geometry_msgs::PoseStamped>> by_object;
  std::vector<int64_t> unknown_class_ids;  // detections whose class id no object has
  /// Detections left out because no hypothesis of theirs could be used: "detection 3: results.pose is not
  /// finite" (index in the array, from 0).
  std::vector<std::string> unusable;
};
DetectionSelection select_detections(const DecodedDetectionArray& array, const std::map<std::string, int64_t>& class_ids);

}  // namespace diffdope_ros
