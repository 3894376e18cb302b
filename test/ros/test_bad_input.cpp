// rostest (bad_input.test): every kind of bad input gets a clear error on /rosout (and diagnostics), nothing
// wrong is published, and the node still refines a good frame afterwards.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <ros/network.h>
#include <xmlrpcpp/XmlRpcClient.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <rosgraph_msgs/Log.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <topic_tools/shape_shifter.h>

#include <fstream>
#include <functional>
#include <mutex>
#include <tuple>

#include "diffdope_ros/InitialPoseArray.h"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/RefinedPoseArray.h"
#include "detection3d_writer.hpp"
#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/detection3d_array.hpp"
#include "diffdope_ros/pose_checker.hpp"

namespace {

struct Node {
  ros::NodeHandle nh;
  ros::Publisher rgb, info, depth, mask, det_box, initial_poses;
  ros::Subscriber rosout, diag, refined_box, refined_all;
  std::mutex mutex;
  std::vector<std::string> errors;
  std::string diagnostics_text;
  int refined_box_count = 0, refined_arrays = 0;
  geometry_msgs::PoseStamped last_refined_box;

  // One good frame from the bag.
  sensor_msgs::Image good_rgb, good_depth, good_mask;
  sensor_msgs::CameraInfo good_info;
  diffdope::Pose truth_box;

  void onLog(const rosgraph_msgs::LogConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    if (m->level >= rosgraph_msgs::Log::ERROR) errors.push_back(m->msg);
    else if (m->level == rosgraph_msgs::Log::WARN) warnings.push_back(m->msg);
  }
  std::vector<std::string> warnings;
  bool waitForWarning(const std::string& needle, double timeout = 8.0) {
    const ros::WallTime start = ros::WallTime::now();
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      {
        std::lock_guard<std::mutex> l(mutex);
        for (const auto& e : warnings)
          if (e.find(needle) != std::string::npos) return true;
      }
      ros::WallDuration(0.05).sleep();
    }
    ADD_FAILURE() << "no warning containing '" << needle << "'";
    return false;
  }
  void onDiag(const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
    std::string text;
    for (const auto& s : m->status) {
      if (s.name.find("refiner") == std::string::npos) continue;
      text += s.message + "\n";
      for (const auto& kv : s.values) text += kv.key + ": " + kv.value + "\n";
    }
    std::lock_guard<std::mutex> l(mutex);
    if (!text.empty()) diagnostics_text = text;
  }
  /// The latest diagnostics text once it contains `needle` (or after `timeout` seconds, whatever it is).
  std::string waitForDiagnostics(const std::string& needle, double timeout = 15.0) {
    const ros::WallTime start = ros::WallTime::now();
    std::string text;
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      {
        std::lock_guard<std::mutex> l(mutex);
        text = diagnostics_text;
      }
      if (text.find(needle) != std::string::npos) break;
      ros::WallDuration(0.2).sleep();
    }
    return text;
  }
  void onRefinedBox(const geometry_msgs::PoseStampedConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    ++refined_box_count;
    last_refined_box = *m;
  }
  void onRefinedAll(const diffdope_ros::RefinedPoseArrayConstPtr&) {
    std::lock_guard<std::mutex> l(mutex);
    ++refined_arrays;
  }

  /// Whether an error containing `needle` was logged.
  bool sawError(const std::string& needle) {
    std::lock_guard<std::mutex> l(mutex);
    for (const auto& e : errors)
      if (e.find(needle) != std::string::npos) return true;
    return false;
  }
  /// Waits until an error containing `needle` was logged.
  bool waitForError(const std::string& needle, double timeout = 8.0) {
    const ros::WallTime start = ros::WallTime::now();
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      if (sawError(needle)) return true;
      ros::WallDuration(0.05).sleep();
    }
    std::lock_guard<std::mutex> l(mutex);
    std::string all;
    for (const auto& e : errors) all += "\n  " + e;
    ADD_FAILURE() << "no error containing '" << needle << "'; errors so far:" << all;
    return false;
  }

  void publishSet(sensor_msgs::Image r, sensor_msgs::CameraInfo i, sensor_msgs::Image d, sensor_msgs::Image m,
                  bool with_depth_and_mask = true) {
    const ros::Time now = ros::Time::now();
    r.header.stamp = i.header.stamp = d.header.stamp = m.header.stamp = now;
    rgb.publish(r);
    info.publish(i);
    if (with_depth_and_mask) {
      depth.publish(d);
      mask.publish(m);
    }
  }
  void publishGood() { publishSet(good_rgb, good_info, good_depth, good_mask); }
  /// Publishes good frames until an error containing `needle` was logged: the one a detection sent just before
  /// causes (on a loaded machine the first frame may be taken before the detection is in).
  bool publishGoodUntilError(const std::string& needle, double timeout = 8.0) {
    const ros::WallTime start = ros::WallTime::now();
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      publishGood();
      for (int i = 0; i < 10; ++i) {
        ros::WallDuration(0.1).sleep();
        if (sawError(needle)) return true;
      }
    }
    return waitForError(needle, 0.5);  // (a last look; fails listing the errors seen)
  }
  /// Publishes the set (fresh stamps each time) until an error containing `needle` was logged: for errors found
  /// only once the synchronizer has matched the set, which an approximate-time policy may first pair with an
  /// earlier message of another topic (the earlier sets of a test had one of their messages dropped).
  bool publishSetUntilError(const sensor_msgs::Image& r, const sensor_msgs::CameraInfo& i, const sensor_msgs::Image& d,
                            const sensor_msgs::Image& m, const std::string& needle, double timeout = 8.0) {
    const ros::WallTime start = ros::WallTime::now();
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      publishSet(r, i, d, m);
      for (int k = 0; k < 5; ++k) {
        ros::WallDuration(0.1).sleep();
        if (sawError(needle)) return true;
      }
    }
    return waitForError(needle, 0.5);  // (a last look; fails listing the errors seen)
  }
  /// Publishes a seed (`seed()`) and then a good frame until more than `before` refined boxes have arrived (up
  /// to `timeout` seconds); then the last one must be within 5 mm / 2 degrees of the truth.
  void refineBoxFrom(int before, const std::function<void()>& seed, const std::string& what, double timeout = 40) {
    const ros::WallTime start = ros::WallTime::now();
    while ((ros::WallTime::now() - start).toSec() < timeout) {
      seed();
      ros::WallDuration(0.2).sleep();
      publishGood();
      ros::WallDuration(1.0).sleep();
      std::lock_guard<std::mutex> l(mutex);
      if (refined_box_count > before) break;
    }
    std::lock_guard<std::mutex> l(mutex);
    ASSERT_GT(refined_box_count, before) << what;
    const auto err = diffdope_ros::pose_error(diffdope_ros::pose_from_msg(last_refined_box.pose, "refined"),
                                              truth_box, false);
    EXPECT_LT(err.translation_m, 0.005);
    EXPECT_LT(err.rotation_rad, 2.0 * M_PI / 180);
  }
  geometry_msgs::PoseStamped detection(const diffdope::Pose& p, const std::string& frame) {
    geometry_msgs::PoseStamped d;
    d.header.stamp = ros::Time::now();
    d.header.frame_id = frame;
    d.pose = diffdope_ros::pose_to_msg(p);
    return d;
  }
};
Node* node = nullptr;

// transport.test only (the node there asks for a depth transport that is not installed).
TEST(BadInput, UnknownTransportIsAnErrorAtStart) {
  const std::string text = node->waitForDiagnostics("inputs: ");
  EXPECT_NE(text.find("no input subscribed: ~depth_image_transport: 'nosuch' is not an installed image transport"),
            std::string::npos) << text;
  EXPECT_NE(text.find("installed: "), std::string::npos) << text;
  EXPECT_NE(text.find("raw"), std::string::npos) << text;
  // The node is up (its service answers) but refines nothing.
  diffdope_ros::Refine srv;
  srv.request.object_names = {"box"};
  EXPECT_TRUE(ros::service::call("/diffdope_refiner/refine", srv));
}

TEST(BadInput, BrokenMeshesDisableOnlyTheirObjects) {
  // Start-up errors may predate this test's /rosout subscription: diagnostics keep them.
  const std::string text = node->waitForDiagnostics("object ghost");
  EXPECT_NE(text.find("objects enabled: 1 of 3"), std::string::npos) << text;
  EXPECT_NE(text.find("object ghost: disabled"), std::string::npos) << text;
  EXPECT_NE(text.find("does_not_exist.ply"), std::string::npos) << text;
  EXPECT_NE(text.find("object broken: disabled"), std::string::npos) << text;
  diffdope_ros::Refine srv;
  srv.request.object_names = {"ghost"};
  ASSERT_TRUE(ros::service::call("/diffdope_refiner/refine", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("disabled"), std::string::npos) << srv.response.message;
}

TEST(BadInput, EachBadMessageIsReported) {
  Node& n = *node;
  auto rgb = n.good_rgb;
  rgb.encoding = "32FC1";
  n.publishSet(rgb, n.good_info, n.good_depth, n.good_mask);
  n.waitForError("rgb image: unsupported encoding '32FC1'");

  auto depth = n.good_depth;
  depth.encoding = "rgb8";
  n.publishSet(n.good_rgb, n.good_info, depth, n.good_mask);
  n.waitForError("depth image: unsupported encoding 'rgb8'");

  auto mask = n.good_mask;
  mask.encoding = "bgr8";
  n.publishSet(n.good_rgb, n.good_info, n.good_depth, mask);
  n.waitForError("mask image: unsupported encoding 'bgr8'");

  depth = n.good_depth;  // half size: not registered to the rgb camera
  depth.width /= 2;
  depth.height /= 2;
  depth.step /= 2;
  depth.data.resize(size_t(depth.step) * depth.height);
  n.publishSetUntilError(n.good_rgb, n.good_info, depth, n.good_mask, "register it to the rgb camera");

  auto info = n.good_info;
  info.K.fill(0.0);
  info.P.fill(0.0);
  n.publishSet(n.good_rgb, info, n.good_depth, n.good_mask);
  n.waitForError("camera_info: focal length is zero");

  rgb = n.good_rgb;
  rgb.data.resize(rgb.data.size() / 2);
  n.publishSet(rgb, n.good_info, n.good_depth, n.good_mask);
  n.waitForError("does not match step");

  auto nan_pose = n.detection(n.truth_box, "camera_color_optical_frame");
  nan_pose.pose.orientation.w = std::numeric_limits<double>::quiet_NaN();
  n.det_box.publish(nan_pose);
  n.waitForError("NaN");

  diffdope::Pose behind = n.truth_box;
  behind.t.z() = -0.5;
  n.det_box.publish(n.detection(behind, "camera_color_optical_frame"));
  ros::WallDuration(0.3).sleep();
  n.publishGoodUntilError("behind the camera");

  n.det_box.publish(n.detection(n.truth_box, "nowhere"));
  ros::WallDuration(0.3).sleep();
  n.publishGoodUntilError("no transform from 'nowhere'");

  // A detection stamped far after the images (a detector on another clock) waits for a later image, said so.
  auto ahead = n.detection(n.truth_box, "camera_color_optical_frame");
  ahead.header.stamp += ros::Duration(100.0);
  n.det_box.publish(ahead);
  ros::WallDuration(0.3).sleep();
  n.publishGoodUntilError("s after the image at");
  EXPECT_NE(n.waitForDiagnostics("kept for a later image").find("kept for a later image"), std::string::npos);

  diffdope_ros::InitialPoseArray unknown;
  diffdope_ros::InitialPose ip;
  ip.name = "teapot";
  ip.pose = n.detection(n.truth_box, "camera_color_optical_frame");
  unknown.poses.push_back(ip);
  n.initial_poses.publish(unknown);
  n.waitForError("unknown object name 'teapot'");

  // Every input pauses for 4 s, then depth and mask stay away: rgb + camera_info alone never form a synchronized
  // set. The time given counts from when rgb came back, not from the last set before the pause.
  ros::WallDuration(4.0).sleep();
  for (int i = 0; i < 15; ++i) {
    n.publishSet(n.good_rgb, n.good_info, n.good_depth, n.good_mask, false);
    ros::WallDuration(0.2).sleep();
  }
  const std::string no_sync = "no synchronized input for ";
  n.waitForError(no_sync);
  {
    std::lock_guard<std::mutex> l(n.mutex);
    for (const auto& e : n.errors)
      if (e.find(no_sync) != std::string::npos)
        EXPECT_LT(std::atof(e.c_str() + e.find(no_sync) + no_sync.size()), 3.5) << e;
  }

  diffdope_ros::Refine srv;
  srv.request.object_names = {"teapot"};
  ASSERT_TRUE(ros::service::call("/diffdope_refiner/refine", srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("teapot"), std::string::npos);

  // Nothing was refined from any of that.
  std::lock_guard<std::mutex> l(n.mutex);
  EXPECT_EQ(n.refined_box_count, 0);
  EXPECT_EQ(n.refined_arrays, 0);
}

/// The count after `what` in the diagnostics line "input NAME: received R, synchronized S, malformed M, ..."
/// (-1 when absent).
long input_count(const std::string& diagnostics, const std::string& name, const std::string& what) {
  const size_t line = diagnostics.find("input " + name + ": ");
  if (line == std::string::npos) return -1;
  const size_t at = diagnostics.find(what + " ", line);
  if (at == std::string::npos || at > diagnostics.find('\n', line)) return -1;
  return std::stol(diagnostics.substr(at + what.size() + 1));
}

// A malformed message whose partners never arrive does not reach the synchronizer's callback: it must
// still be counted and reported with its reason.
TEST(BadInput, MalformedMessagesThatNeverSynchronizeAreCountedAndReported) {
  Node& n = *node;
  long before = -1;
  for (int i = 0; i < 50 && before < 0; ++i) {
    ros::WallDuration(0.1).sleep();
    std::lock_guard<std::mutex> l(n.mutex);
    before = input_count(n.diagnostics_text, "depth", "malformed");
  }
  ASSERT_GE(before, 0) << "no 'input depth' line in the diagnostics:\n" << n.diagnostics_text;
  auto depth = n.good_depth;
  depth.encoding = "mono8";
  for (int i = 0; i < 5; ++i) {
    depth.header.stamp = ros::Time::now() - ros::Duration(100.0 + i);  // no rgb near it: never synchronized
    n.depth.publish(depth);
    ros::WallDuration(0.05).sleep();
  }
  n.waitForError("depth message dropped: depth image: unsupported encoding 'mono8'");
  long after = before;
  for (int i = 0; i < 60 && after < before + 5; ++i) {
    ros::WallDuration(0.1).sleep();
    std::lock_guard<std::mutex> l(n.mutex);
    after = input_count(n.diagnostics_text, "depth", "malformed");
  }
  EXPECT_EQ(after, before + 5) << n.diagnostics_text;
  std::lock_guard<std::mutex> l(n.mutex);
  EXPECT_GE(input_count(n.diagnostics_text, "rgb", "received"), input_count(n.diagnostics_text, "rgb", "synchronized"));
  EXPECT_GE(input_count(n.diagnostics_text, "camera_info", "unmatched"), 0) << n.diagnostics_text;
}

// Every depth message malformed for three sync timeouts: its own error explains why no set forms, and stays
// the cause the log and the diagnostics give (not "no synchronized input").
TEST(BadInput, AMalformedInputStaysTheReportedCause) {
  Node& n = *node;
  const auto sync_errors = [&] {
    std::lock_guard<std::mutex> l(n.mutex);
    return std::count_if(n.errors.begin(), n.errors.end(),
                         [](const std::string& e) { return e.find("no synchronized input") != std::string::npos; });
  };
  auto depth = n.good_depth;
  depth.encoding = "mono8";
  const long before = sync_errors();
  for (int i = 0; i < 15; ++i) {
    n.publishSet(n.good_rgb, n.good_info, depth, n.good_mask);
    ros::WallDuration(0.2).sleep();
  }
  n.waitForError("depth image: unsupported encoding 'mono8'");
  EXPECT_EQ(sync_errors(), before);
  const std::string text = n.waitForDiagnostics("last error: depth message dropped");
  EXPECT_NE(text.find("last error: depth message dropped: depth image: unsupported encoding 'mono8'"),
            std::string::npos) << text;
  // A depth image without any valid reading is dropped and said so, not refined as if the object had no depth.
  auto blank = n.good_depth;
  std::fill(blank.data.begin(), blank.data.end(), 0);
  n.publishSetUntilError(n.good_rgb, n.good_info, blank, n.good_mask, "depth image has no valid reading");
}

TEST(BadInput, StillRefinesAGoodFrameAfterwards) {
  Node& n = *node;
  const diffdope::Pose init =
      diffdope::Pose(Eigen::AngleAxisd(3.0 * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                     Eigen::Vector3d(0.006, 0, 0)) * n.truth_box;
  n.refineBoxFrom(0, [&] { n.det_box.publish(n.detection(init, "camera_color_optical_frame")); },
                  "no refined pose for a good frame after the bad input");
}

TEST(BadInput, QualityCheckDropsALostTrack) {
  // The box is tracked now. Frames whose mask no longer shows it fail the quality check; after
  // ~max_track_failures (2) of them the track is dropped, and later good frames without a detection are not
  // refined from the stale pose.
  Node& n = *node;
  auto empty_mask = n.good_mask;
  std::fill(empty_mask.data.begin(), empty_mask.data.end(), 0);
  for (int i = 0; i < 3; ++i) {
    n.publishSet(n.good_rgb, n.good_info, n.good_depth, empty_mask);
    ros::WallDuration(0.6).sleep();
  }
  n.waitForWarning("lost track of 'box'");
  int before;
  {
    std::lock_guard<std::mutex> l(n.mutex);
    before = n.refined_box_count;
  }
  for (int i = 0; i < 3; ++i) {
    n.publishGood();
    ros::WallDuration(0.5).sleep();
  }
  {
    std::lock_guard<std::mutex> l(n.mutex);
    EXPECT_EQ(n.refined_box_count, before) << "refined from a lost track";
  }
  // A pose on ~initial_poses (the array topic for other detectors) re-acquires it.
  diffdope_ros::InitialPoseArray a;
  diffdope_ros::InitialPose ip;
  ip.name = "box";
  ip.pose = n.detection(n.truth_box, "camera_color_optical_frame");
  a.poses.push_back(ip);
  n.refineBoxFrom(before, [&] {
    ip.pose.header.stamp = ros::Time::now();
    a.poses[0] = ip;
    n.initial_poses.publish(a);
  }, "~initial_poses did not re-acquire the object", 30);
}

TEST(BadInput, DopesDetectionArrayIsReadAndBadOnesAreReported) {
  // DOPE's vision_msgs/Detection3DArray on ~detections_topic, as a ShapeShifter: the newer layout (another MD5),
  // then broken bytes of the right one, each reported; then good arrays seed the box (class id 1), with a weaker
  // second box (beyond the box's one instance) and an unknown class id counted.
  Node& n = *node;
  const std::string topic = "/dope/detected_objects";
  const auto connected = [](const ros::Publisher& p) {
    const ros::WallTime start = ros::WallTime::now();
    while (p.getNumSubscribers() == 0 && (ros::WallTime::now() - start).toSec() < 10) ros::WallDuration(0.05).sleep();
    return p.getNumSubscribers() > 0;
  };
  {
    // The newer vision_msgs layout (string class ids): same type name, another MD5.
    topic_tools::ShapeShifter newer;
    newer.morph("ce4a6fa9e38b86b8d286a82799ca586d", diffdope_ros::kDetection3DArrayType, "", "");
    ros::Publisher wrong = newer.advertise(n.nh, topic, 5);
    ASSERT_TRUE(connected(wrong));
    std::vector<uint8_t> some(64, 0);
    ros::serialization::IStream in(some.data(), uint32_t(some.size()));
    newer.read(in);
    wrong.publish(newer);
    n.waitForError("a vision_msgs/Detection3DArray (MD5 ce4a6fa9e38b86b8d286a82799ca586d)");
    wrong.shutdown();  // the node then subscribes afresh (its subscription had taken the other MD5)
  }
  topic_tools::ShapeShifter shape;
  shape.morph(diffdope_ros::kDetection3DArrayMd5, diffdope_ros::kDetection3DArrayType, "", "");
  ros::Publisher pub = shape.advertise(n.nh, topic, 5);
  ASSERT_TRUE(connected(pub));
  const auto publish = [&](const std::vector<uint8_t>& bytes) {
    topic_tools::ShapeShifter m;
    m.morph(diffdope_ros::kDetection3DArrayMd5, diffdope_ros::kDetection3DArrayType, "", "");
    std::vector<uint8_t> copy = bytes;
    ros::serialization::IStream in(copy.data(), uint32_t(copy.size()));
    m.read(in);
    pub.publish(m);
  };
  const diffdope::Pose init =
      diffdope::Pose(Eigen::AngleAxisd(3.0 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                     Eigen::Vector3d(0.0, 0.005, 0)) * n.truth_box;
  const auto array = [&](const ros::Time& stamp) {
    diffdope_ros::test::Writer w;
    w.header(0, stamp.sec, stamp.nsec, "camera_color_optical_frame");
    w.put<uint32_t>(4);
    const auto q = init.quaternion_xyzw();
    // The last one, the box's best score, has a NaN position: it alone is left out (and named).
    const double nan = std::numeric_limits<double>::quiet_NaN();
    for (const auto& [id, score, dx] : {std::tuple<int64_t, double, double>{1, 0.8, 0.0}, {1, 0.3, 0.2}, {9, 0.9, 0.0},
                                        {1, 0.95, nan}}) {
      w.header(0, stamp.sec, stamp.nsec, "camera_color_optical_frame");
      w.put<uint32_t>(1);
      w.hypothesis_at(id, score, init.t.x() + dx, init.t.y(), init.t.z(), q[0], q[1], q[2], q[3]);
      w.box_and_empty_cloud();
    }
    return w.bytes;
  };
  std::vector<uint8_t> cut = array(ros::Time::now());
  cut.resize(cut.size() - 10);
  publish(cut);
  n.waitForError("Detection3DArray: truncated");
  int before;
  {
    std::lock_guard<std::mutex> l(n.mutex);
    before = n.refined_box_count;
  }
  n.refineBoxFrom(before, [&] { publish(array(ros::Time::now())); }, "no refined pose with detections from the array");
  const std::string unusable = "1 of 4 detection(s) ignored (first: detection 3: results.pose is not finite)";
  for (int i = 0; i < 40 && !n.sawError(unusable); ++i) {  // (the log is throttled)
    publish(array(ros::Time::now()));
    ros::WallDuration(0.25).sleep();
  }
  n.waitForError(unusable);
  // The weaker second box is one more than the box's max_instances (1): counted, not used.
  const std::string key = "detections beyond max_instances (ignored): ";
  std::string text;
  long extra = 0;
  for (int i = 0; i < 75 && extra == 0; ++i) {
    text = n.waitForDiagnostics(key);
    const size_t at = text.find(key);
    if (at != std::string::npos) extra = std::atol(text.c_str() + at + key.size());
    if (extra == 0) ros::WallDuration(0.2).sleep();
  }
  EXPECT_GE(extra, 1) << text;
  const size_t line = text.find("input detections (Detection3DArray): ");
  ASSERT_NE(line, std::string::npos) << text;
  const std::string counts = text.substr(line, text.find('\n', line) - line);
  EXPECT_EQ(counts.find("of a known class 0,"), std::string::npos) << counts;
  EXPECT_NE(counts.find("(malformed 2)"), std::string::npos) << counts;  // the other layout and the cut array
  EXPECT_EQ(counts.find("of an unknown class id 0,"), std::string::npos) << counts;
  EXPECT_EQ(counts.find("unusable 0"), std::string::npos) << counts;
}

/// The process id of ROS node `name` (its XML-RPC getPid), -1 when it cannot be asked.
int nodePid(const std::string& name) {
  XmlRpc::XmlRpcValue args, result, uri;
  args[0] = ros::this_node::getName();
  args[1] = name;
  if (!ros::master::execute("lookupNode", args, result, uri, true)) return -1;
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(std::string(uri), host, port)) return -1;
  XmlRpc::XmlRpcClient client(host.c_str(), int(port), "/");
  XmlRpc::XmlRpcValue pid_args, pid;
  pid_args[0] = ros::this_node::getName();
  if (!client.execute("getPid", pid_args, pid) || pid.getType() != XmlRpc::XmlRpcValue::TypeArray) return -1;
  return int(pid[2]);
}
/// Resident memory of process `pid` in MB (-1 when unknown).
double residentMb(int pid) {
  std::ifstream status("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return -1;
}

// Floods of hostile messages: depth images of 300 different sizes, and Detection3DArrays of 10,000 detections.
// The log stays throttled (one category per input), the diagnostics message stays small, the node's memory does
// not grow with the flood, and it still refines a good frame afterwards.
TEST(BadInput, FloodsKeepTheLogTheDiagnosticsAndTheMemoryBounded) {
  Node& n = *node;
  const int pid = nodePid("/diffdope_manager");
  ASSERT_GT(pid, 0) << "cannot ask /diffdope_manager for its pid";
  const double before_mb = residentMb(pid);
  const auto count_errors = [&](const std::string& needle) {
    std::lock_guard<std::mutex> l(n.mutex);
    return std::count_if(n.errors.begin(), n.errors.end(),
                         [&](const std::string& e) { return e.find(needle) != std::string::npos; });
  };
  const std::string unregistered = "register it to the rgb camera";
  const long logged_before = count_errors(unregistered);
  const ros::WallTime start = ros::WallTime::now();
  for (int i = 0; i < 300; ++i) {
    auto depth = n.good_depth;  // each a size of its own, none the rgb's
    depth.width = 40 + uint32_t(i);
    depth.height = 30 + uint32_t(i % 97);
    depth.step = depth.width * 4;
    depth.data.assign(size_t(depth.step) * depth.height, 0x3f);
    n.publishSet(n.good_rgb, n.good_info, depth, n.good_mask);
    ros::WallDuration(0.01).sleep();
  }
  {
    diffdope_ros::test::Writer w;
    const ros::Time stamp = ros::Time::now();
    w.header(0, stamp.sec, stamp.nsec, "camera_color_optical_frame");
    const uint32_t count = 10000;
    w.put<uint32_t>(count);
    const auto q = n.truth_box.quaternion_xyzw();
    for (uint32_t k = 0; k < count; ++k) {
      w.header(0, stamp.sec, stamp.nsec, "camera_color_optical_frame");
      w.put<uint32_t>(1);
      w.hypothesis_at(k % 3 == 0 ? 1 : 1000 + k, 0.5, n.truth_box.t.x(), n.truth_box.t.y(), n.truth_box.t.z(), q[0], q[1],
                      q[2], q[3]);
      w.box_and_empty_cloud();
    }
    topic_tools::ShapeShifter shape;
    shape.morph(diffdope_ros::kDetection3DArrayMd5, diffdope_ros::kDetection3DArrayType, "", "");
    ros::Publisher pub = shape.advertise(n.nh, "/dope/detected_objects", 5);
    for (int i = 0; i < 100 && pub.getNumSubscribers() == 0; ++i) ros::WallDuration(0.05).sleep();
    for (int i = 0; i < 20; ++i) {
      topic_tools::ShapeShifter m;
      m.morph(diffdope_ros::kDetection3DArrayMd5, diffdope_ros::kDetection3DArrayType, "", "");
      ros::serialization::IStream in(w.bytes.data(), uint32_t(w.bytes.size()));
      m.read(in);
      pub.publish(m);
      n.publishGood();
      ros::WallDuration(0.1).sleep();
    }
  }
  const double seconds = (ros::WallTime::now() - start).toSec() + 1.0;
  ros::WallDuration(1.5).sleep();  // (the last log lines and a diagnostics message)
  // ~error_throttle is 0.2 s here: one line per input per period at most, not one per message.
  EXPECT_GT(count_errors(unregistered), logged_before);
  EXPECT_LE(count_errors(unregistered) - logged_before, long(seconds / 0.2) + 2);
  const std::string text = n.waitForDiagnostics("refiner", 3.0);
  EXPECT_LT(text.size(), 8000u) << text;
  const double after_mb = residentMb(pid);
  std::printf("diffdope_manager: %.0f MB before the flood, %.0f MB after; diagnostics %zu bytes\n", before_mb,
              after_mb, text.size());
  EXPECT_LT(after_mb - before_mb, 100.0);
  const int refined = [&] {
    std::lock_guard<std::mutex> l(n.mutex);
    return n.refined_box_count;
  }();
  n.refineBoxFrom(refined, [&] { n.det_box.publish(n.detection(n.truth_box, "camera_color_optical_frame")); },
                  "no refined pose after the floods");
}

bool loadGoodFrame(Node& n, const std::string& bag_path) {
  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  bool have[5] = {false, false, false, false, false};
  rosbag::View view(bag);
  for (rosbag::View::iterator it = view.begin(); it != view.end(); ++it) {
    const rosbag::MessageInstance& m = *it;
    const std::string t = m.getTopic();
    if (t == "/camera/rgb/image_rect_color" && !have[0]) {
      n.good_rgb = *m.instantiate<sensor_msgs::Image>();
      have[0] = true;
    }
    if (t == "/camera/depth/image_rect" && !have[1]) {
      n.good_depth = *m.instantiate<sensor_msgs::Image>();
      have[1] = true;
    }
    if (t == "/camera/mask" && !have[2]) {
      n.good_mask = *m.instantiate<sensor_msgs::Image>();
      have[2] = true;
    }
    if (t == "/camera/rgb/camera_info" && !have[3]) {
      n.good_info = *m.instantiate<sensor_msgs::CameraInfo>();
      have[3] = true;
    }
    if (t == "/ground_truth" && !have[4]) {
      const auto truth = m.instantiate<diffdope_ros::InitialPoseArray>();  // keep it alive over the loop
      for (const auto& p : truth->poses)
        if (p.name == "box") {
          // The bag's truth is the mesh pose; the node speaks in the object frame of the config's
          // model_transform (mesh in object frame, CMakeLists.txt: bad/objects.yaml): object = mesh * M^-1.
          const diffdope::Pose M = diffdope::Pose::from_quaternion(0, 0, std::sqrt(0.5), std::sqrt(0.5),
                                                                   Eigen::Vector3d(0.01, -0.02, 0.03));
          n.truth_box = diffdope_ros::pose_from_msg(p.pose.pose, "truth") * M.inverse();
          have[4] = true;
        }
    }
  }
  return have[0] && have[1] && have[2] && have[3] && have[4];
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_bad_input");
  ros::NodeHandle pnh("~");
  Node n;
  node = &n;
  if (!loadGoodFrame(n, pnh.param<std::string>("bag", ""))) {
    std::fprintf(stderr, "cannot read a frame from the bag\n");
    return 1;
  }
  n.rgb = n.nh.advertise<sensor_msgs::Image>("/camera/rgb/image_rect_color", 5);
  n.info = n.nh.advertise<sensor_msgs::CameraInfo>("/camera/rgb/camera_info", 5);
  n.depth = n.nh.advertise<sensor_msgs::Image>("/camera/depth/image_rect", 5);
  n.mask = n.nh.advertise<sensor_msgs::Image>("/camera/mask", 5);
  n.det_box = n.nh.advertise<geometry_msgs::PoseStamped>("/dope/pose_box", 5);
  n.initial_poses = n.nh.advertise<diffdope_ros::InitialPoseArray>("/diffdope_refiner/initial_poses", 5);
  n.rosout = n.nh.subscribe("/rosout", 1000, &Node::onLog, &n);
  n.diag = n.nh.subscribe("/diagnostics", 10, &Node::onDiag, &n);
  n.refined_box = n.nh.subscribe("/diffdope_refiner/refined/box", 10, &Node::onRefinedBox, &n);
  n.refined_all = n.nh.subscribe("/diffdope_refiner/refined_poses", 10, &Node::onRefinedAll, &n);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  if (!ros::service::waitForService("/diffdope_refiner/refine", ros::Duration(60))) return 1;
  // Every publisher connected before the first message (a message before the connection is lost).
  const ros::WallTime start = ros::WallTime::now();
  while ((n.rgb.getNumSubscribers() == 0 || n.info.getNumSubscribers() == 0 || n.depth.getNumSubscribers() == 0 ||
          n.mask.getNumSubscribers() == 0 || n.det_box.getNumSubscribers() == 0 ||
          n.initial_poses.getNumSubscribers() == 0) &&
         (ros::WallTime::now() - start).toSec() < 30)
    ros::WallDuration(0.1).sleep();
  ros::WallDuration(0.5).sleep();
  return RUN_ALL_TESTS();
}
