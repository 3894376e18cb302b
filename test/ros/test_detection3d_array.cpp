// Decoding DOPE's vision_msgs/Detection3DArray from its ROS 1 bytes (detection3d_array.hpp), written here by a
// writer that follows the .msg definitions, including every kind of broken message.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "detection3d_writer.hpp"
#include "diffdope_ros/detection_selection.hpp"

using diffdope_ros::decode_detection3d_array;

using diffdope_ros::test::Writer;

namespace {

/// Two detections: class 1 (one hypothesis, with a point cloud) and class 3 (two hypotheses).
std::vector<uint8_t> two_detections() {
  Writer w;
  w.header(7, 1000, 500, "camera_color_optical_frame");
  w.put<uint32_t>(2);
  w.header(7, 1000, 500, "camera_color_optical_frame");
  w.put<uint32_t>(1);
  w.hypothesis(1, 0.9, 0.1, 0, 1);
  w.pose(0.1, 0.02, 0.6, 0, 0, 0, 1), w.put<double>(0.1), w.put<double>(0.05), w.put<double>(0.2);  // bbox
  w.cloud(true);
  w.header(7, 1000, 500, "camera_color_optical_frame");
  w.put<uint32_t>(2);
  w.hypothesis(3, 0.4, -0.1, std::sin(0.25), std::cos(0.25));
  w.hypothesis(3, 0.7, -0.12, 0, 1);
  w.pose(-0.1, 0.02, 0.6, 0, 0, 0, 1), w.put<double>(0.1), w.put<double>(0.1), w.put<double>(0.1);
  w.cloud(false);
  return w.bytes;
}

}  // namespace

TEST(Detection3DArray, DecodesDopesLayout) {
  const std::vector<uint8_t> b = two_detections();
  const auto m = decode_detection3d_array(b.data(), b.size());
  EXPECT_EQ(m.frame_id, "camera_color_optical_frame");
  EXPECT_EQ(m.stamp_sec, 1000u);
  EXPECT_EQ(m.stamp_nsec, 500u);
  ASSERT_EQ(m.detections.size(), 2u);
  ASSERT_EQ(m.detections[0].results.size(), 1u);
  EXPECT_EQ(m.detections[0].results[0].class_id, 1);
  EXPECT_DOUBLE_EQ(m.detections[0].results[0].score, 0.9);
  EXPECT_DOUBLE_EQ(m.detections[0].results[0].pose.t.x(), 0.1);
  EXPECT_DOUBLE_EQ(m.detections[0].results[0].covariance[0], 1e-4);
  ASSERT_EQ(m.detections[1].results.size(), 2u);
  EXPECT_EQ(m.detections[1].results[1].class_id, 3);
  EXPECT_DOUBLE_EQ(m.detections[1].results[1].score, 0.7);
  EXPECT_NEAR(diffdope::rotation_angle(m.detections[1].results[0].pose.R, Eigen::Matrix3d::Identity()), 0.5, 1e-12);
  EXPECT_EQ(m.detections[1].frame_id, "camera_color_optical_frame");
}

// What a tool writes (encode_detection3d_array) reads back the same, and has the layout the writer above follows.
TEST(Detection3DArray, EncodingReadsBackTheSame) {
  const std::vector<uint8_t> written = two_detections();
  const auto once = decode_detection3d_array(written.data(), written.size());
  diffdope_ros::DecodedDetectionArray array = once;
  array.detections[1].stamp_sec = 1001;
  array.detections[1].results[0].covariance[35] = 0.5;
  std::vector<uint8_t> bytes = diffdope_ros::encode_detection3d_array(array);
  const auto back = decode_detection3d_array(bytes.data(), bytes.size());
  EXPECT_EQ(back.frame_id, array.frame_id);
  EXPECT_EQ(back.stamp_sec, array.stamp_sec);
  EXPECT_EQ(back.stamp_nsec, array.stamp_nsec);
  ASSERT_EQ(back.detections.size(), array.detections.size());
  for (size_t d = 0; d < array.detections.size(); ++d) {
    EXPECT_EQ(back.detections[d].frame_id, array.detections[d].frame_id);
    EXPECT_EQ(back.detections[d].stamp_sec, array.detections[d].stamp_sec);
    ASSERT_EQ(back.detections[d].results.size(), array.detections[d].results.size());
    for (size_t h = 0; h < array.detections[d].results.size(); ++h) {
      const auto &a = array.detections[d].results[h], &b = back.detections[d].results[h];
      EXPECT_EQ(b.class_id, a.class_id);
      EXPECT_EQ(b.score, a.score);
      EXPECT_LT((b.pose.t - a.pose.t).norm(), 1e-15);
      EXPECT_LT(diffdope::rotation_angle(b.pose.R, a.pose.R), 1e-7);
      EXPECT_EQ(b.covariance, a.covariance);
      EXPECT_EQ(b.problem, "");
    }
  }
  bytes.pop_back();  // and a cut one is refused, as DOPE's own
  EXPECT_THROW(decode_detection3d_array(bytes.data(), bytes.size()), std::invalid_argument);
}

TEST(Detection3DArray, EveryTruncationIsAnErrorNeverACrash) {
  const std::vector<uint8_t> b = two_detections();
  for (size_t n = 0; n < b.size(); ++n) {
    try {
      decode_detection3d_array(b.data(), n);
      ADD_FAILURE() << "a message cut at " << n << " of " << b.size() << " bytes was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("Detection3DArray: "), std::string::npos) << e.what();
    }
  }
  std::vector<uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_THROW(decode_detection3d_array(longer.data(), longer.size()), std::invalid_argument);
}

TEST(Detection3DArray, HostileCountsAndValuesAreRefusedByName) {
  Writer w;
  w.header(0, 1, 2, "cam");
  w.put<uint32_t>(std::numeric_limits<uint32_t>::max());  // 4 billion detections in a few bytes
  try {
    decode_detection3d_array(w.bytes.data(), w.bytes.size());
    ADD_FAILURE();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("detections says 4294967295 elements"), std::string::npos) << e.what();
  }
  std::vector<uint8_t> b = two_detections();
  // The first hypothesis's x: after the array header (4+4+4+4+26), the count (4), the detection header (42),
  // the results count (4), id and score (16).
  const size_t x_at = 42 + 4 + 42 + 4 + 16;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(b.data() + x_at, &nan, sizeof nan);
  // A NaN pose spoils its detection only: it is decoded with its problem, and the others are used.
  const auto m = decode_detection3d_array(b.data(), b.size());
  ASSERT_EQ(m.detections.size(), 2u);
  EXPECT_EQ(m.detections[0].results[0].problem, "results.pose is not finite");
  EXPECT_TRUE(m.detections[1].results[0].problem.empty());
  const auto chosen = diffdope_ros::select_detections(m, {{"box", 1}, {"mug", 3}});
  EXPECT_EQ(chosen.by_object.count("box"), 0u);
  ASSERT_EQ(chosen.by_object.at("mug").size(), 1u);
  EXPECT_EQ(chosen.unusable, std::vector<std::string>{"detection 0: results.pose is not finite"});
  // A zero quaternion and a NaN score, likewise.
  std::vector<uint8_t> z = two_detections();
  for (size_t k = 3; k < 7; ++k) std::memset(z.data() + x_at + 8 * k, 0, 8);
  EXPECT_EQ(decode_detection3d_array(z.data(), z.size()).detections[0].results[0].problem,
            "results.pose has a zero quaternion");
  std::vector<uint8_t> s = two_detections();
  std::memcpy(s.data() + x_at - 8, &nan, sizeof nan);
  EXPECT_EQ(decode_detection3d_array(s.data(), s.size()).detections[0].results[0].problem,
            "results.score is not finite");
}

TEST(Detection3DArray, EachObjectGetsItsDetectionsByClassIdBestFirst) {
  const std::vector<uint8_t> b = two_detections();
  const auto m = decode_detection3d_array(b.data(), b.size());
  // Class 1 is the box; class 3 is nobody's here.
  auto chosen = diffdope_ros::select_detections(m, {{"box", 1}, {"mug", 2}});
  ASSERT_EQ(chosen.by_object.size(), 1u);
  ASSERT_EQ(chosen.by_object.at("box").size(), 1u);
  EXPECT_DOUBLE_EQ(chosen.by_object.at("box")[0].pose.position.x, 0.1);
  EXPECT_EQ(chosen.by_object.at("box")[0].header.frame_id, "camera_color_optical_frame");
  EXPECT_EQ(chosen.by_object.at("box")[0].header.stamp, ros::Time(1000, 500));
  EXPECT_EQ(chosen.unknown_class_ids, std::vector<int64_t>{3});
  // Class 3 as the mug: of its two hypotheses the better one (score 0.7, x = -0.12).
  chosen = diffdope_ros::select_detections(m, {{"box", 1}, {"mug", 3}});
  ASSERT_EQ(chosen.by_object.size(), 2u);
  ASSERT_EQ(chosen.by_object.at("mug").size(), 1u);  // one detection, its best hypothesis
  EXPECT_DOUBLE_EQ(chosen.by_object.at("mug")[0].pose.position.x, -0.12);
  EXPECT_TRUE(chosen.unknown_class_ids.empty());
  // Two detections of one object (two instances): both, the higher score first.
  diffdope_ros::DecodedDetectionArray twice = m;
  twice.detections[1].results = {m.detections[0].results[0]};
  twice.detections[1].results[0].score = 0.95;
  twice.detections[1].results[0].pose.t.x() = 0.3;
  chosen = diffdope_ros::select_detections(twice, {{"box", 1}});
  ASSERT_EQ(chosen.by_object.at("box").size(), 2u);
  EXPECT_DOUBLE_EQ(chosen.by_object.at("box")[0].pose.position.x, 0.3);
  EXPECT_DOUBLE_EQ(chosen.by_object.at("box")[1].pose.position.x, 0.1);
}
