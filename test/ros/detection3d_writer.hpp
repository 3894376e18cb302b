#pragma once
// Writes vision_msgs/Detection3DArray (ROS 1, DOPE's layout) byte by byte from the .msg definitions, for the tests
// of the decoder and of the node (which receives it as a topic_tools::ShapeShifter).
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace diffdope_ros::test {

/// ROS 1 serialization, little-endian, as the .msg files define the fields.
struct Writer {
  std::vector<uint8_t> bytes;
  template <class T>
  void put(T v) {
    const size_t at = bytes.size();
    bytes.resize(at + sizeof(T));
    std::memcpy(bytes.data() + at, &v, sizeof(T));
  }
  void str(const std::string& s) {
    put<uint32_t>(uint32_t(s.size()));
    bytes.insert(bytes.end(), s.begin(), s.end());
  }
  void header(uint32_t seq, uint32_t sec, uint32_t nsec, const std::string& frame) {
    put<uint32_t>(seq), put<uint32_t>(sec), put<uint32_t>(nsec), str(frame);
  }
  void pose(double x, double y, double z, double qx, double qy, double qz, double qw) {
    for (double v : {x, y, z, qx, qy, qz, qw}) put<double>(v);
  }
  /// One ObjectHypothesisWithPose: class id, score, pose (position, quaternion x y z w) and a small covariance.
  void hypothesis_at(int64_t id, double score, double x, double y, double z, double qx, double qy, double qz,
                     double qw) {
    put<int64_t>(id), put<double>(score);
    pose(x, y, z, qx, qy, qz, qw);
    for (int i = 0; i < 36; ++i) put<double>(i % 7 == 0 ? 1e-4 : 0.0);  // PoseWithCovariance.covariance
  }
  void hypothesis(int64_t id, double score, double x, double qz, double qw) {
    hypothesis_at(id, score, x, 0.02, 0.6, 0, 0, qz, qw);
  }
  /// The rest of a Detection3D after its results: a bounding box and an empty source cloud.
  void box_and_empty_cloud() {
    pose(0, 0, 0.5, 0, 0, 0, 1), put<double>(0.1), put<double>(0.1), put<double>(0.1);
    cloud(false);
  }
  void cloud(bool with_points) {
    header(0, 0, 0, "");
    put<uint32_t>(1), put<uint32_t>(with_points ? 1 : 0);  // height, width
    put<uint32_t>(with_points ? 1 : 0);                     // fields
    if (with_points) str("x"), put<uint32_t>(0), put<uint8_t>(7), put<uint32_t>(1);
    put<uint8_t>(0), put<uint32_t>(4), put<uint32_t>(4);  // is_bigendian, point_step, row_step
    put<uint32_t>(with_points ? 4 : 0);                     // data
    for (int i = 0; i < (with_points ? 4 : 0); ++i) put<uint8_t>(uint8_t(i));
    put<uint8_t>(1);  // is_dense
  }
};

}  // namespace diffdope_ros::test
