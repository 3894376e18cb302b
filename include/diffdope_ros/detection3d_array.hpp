#pragma once
// DOPE's detection output, vision_msgs/Detection3DArray (ROS 1, integer class ids), read without the vision_msgs
// package (Debian does not ship it): the node subscribes with topic_tools::ShapeShifter and decodes the ROS 1
// serialization here. Every count and length is checked against the bytes that are there, so a truncated or
// hostile message is an error naming where it broke, never an overread or a huge allocation.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "diffdope/pose.hpp"

namespace diffdope_ros {

/// The ROS 1 vision_msgs/Detection3DArray that DOPE publishes (ObjectHypothesisWithPose: int64 id, float64 score,
/// geometry_msgs/PoseWithCovariance pose; Detection3D: header, results, bbox, source_cloud). MD5 computed with
/// genmsg from those definitions.
constexpr const char* kDetection3DArrayType = "vision_msgs/Detection3DArray";
constexpr const char* kDetection3DArrayMd5 = "05c51d9aea1fb4cfdc8effb94f197b6f";

struct DecodedHypothesis {
  int64_t class_id = 0;
  double score = 0;
  diffdope::Pose pose;                 // metres, in the detection's header frame
  std::array<double, 36> covariance{};
  /// Why this hypothesis cannot be used (a non-finite pose or score, a zero quaternion); empty when it can. One
  /// bad hypothesis does not spoil the array: the others are used, and the caller names this one.
  std::string problem;
};

struct DecodedDetection {
  std::string frame_id;
  uint32_t stamp_sec = 0, stamp_nsec = 0;
  std::vector<DecodedHypothesis> results;
};

struct DecodedDetectionArray {
  std::string frame_id;
  uint32_t stamp_sec = 0, stamp_nsec = 0;
  std::vector<DecodedDetection> detections;
};

/// Decodes one serialized message. Throws std::invalid_argument naming the field and byte offset: truncated
/// data, a count or length larger than the bytes left, trailing bytes. A hypothesis with a non-finite pose or
/// score, or a zero quaternion, is decoded with its `problem` set.
DecodedDetectionArray decode_detection3d_array(const uint8_t* data, size_t size);

/// The ROS 1 serialization of `array` as DOPE publishes it (what decode_detection3d_array reads back): each
/// detection with its hypotheses, a bounding box of size `box_size` (metres) at its first hypothesis' pose, and
/// an empty source cloud. For tools that write DOPE's output into a bag (topic_tools::ShapeShifter).
std::vector<uint8_t> encode_detection3d_array(const DecodedDetectionArray& array, double box_size = 0.1);

}  // namespace diffdope_ros
