// rostest (bag_accuracy.test): the refiner on the generated bag, judged against the bag's ground truth.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <sensor_msgs/Image.h>
#include <visualization_msgs/MarkerArray.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <mutex>

#include "diffdope/object_config.hpp"
#include "diffdope/print_alignment.hpp"
#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/pose_checker.hpp"

namespace {

struct Recorder {
  std::mutex mutex;
  std::unique_ptr<diffdope_ros::PoseChecker> checker;
  std::vector<diffdope_ros::RefinedPoseArray> arrays;
  std::map<std::string, std::vector<geometry_msgs::PoseStamped>> per_object;
  ros::WallTime last_truth, last_refined;
  sensor_msgs::Image overlay;
  int overlays = 0;
  visualization_msgs::MarkerArray markers;
  std::vector<diagnostic_msgs::DiagnosticStatus> diagnostics;

  void onTruth(const diffdope_ros::InitialPoseArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    checker->addGroundTruth(*m);
    last_truth = ros::WallTime::now();
  }
  void onRefined(const diffdope_ros::RefinedPoseArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    arrays.push_back(*m);
    last_refined = ros::WallTime::now();
  }
  void onOverlay(const sensor_msgs::ImageConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    ++overlays;
    overlay.header = m->header;
    overlay.encoding = m->encoding;
    overlay.width = m->width;
    overlay.height = m->height;
  }
  void onMarkers(const visualization_msgs::MarkerArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    markers = *m;
  }
  void onDiagnostics(const diagnostic_msgs::DiagnosticArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    for (const auto& s : m->status)
      if (s.name.find("refiner") != std::string::npos) diagnostics.push_back(s);
  }
  void onObjectPose(const geometry_msgs::PoseStampedConstPtr& m, const std::string& name) {
    std::lock_guard<std::mutex> l(mutex);
    per_object[name].push_back(*m);
  }
  std::map<std::string, std::vector<geometry_msgs::PoseWithCovarianceStamped>> per_object_cov;
  void onObjectCovariance(const geometry_msgs::PoseWithCovarianceStampedConstPtr& m, const std::string& name) {
    std::lock_guard<std::mutex> l(mutex);
    per_object_cov[name].push_back(*m);
  }
};

// Parameters (private): the limits of PoseChecker::fromParams (max_translation, max_rotation_deg,
// max_rotation_deg_by_object), expect_track (true: some frames must be seeded by tracking once the detector is
// silent), check_outputs (true: overlay, markers, diagnostics).
TEST(BagAccuracy, RefinedPosesTfAndScores) {
  ros::NodeHandle nh, pnh("~");
  const bool expect_track = pnh.param("expect_track", true), check_outputs = pnh.param("check_outputs", true);
  // expect_detection_array: DOPE's Detection3DArray is played too; every detection in it must be read and matched
  // to an object by its class id.
  const bool expect_detection_array = pnh.param("expect_detection_array", false);
  const bool has_mask = pnh.param("has_mask", true), has_depth = pnh.param("has_depth", true);
  // each_within false: only require that refinement improves on the detector on average (rgb-only input).
  const bool each_within = pnh.param("each_within", true);
  // A looped bag (rosbag play -l): record for record_seconds of wall time, expect the node's time-jump warning;
  // TF is not compared (tf2 listeners clear their buffers on each jump back) nor latency (frames of one loop
  // can be published after the clock has jumped back).
  const double record_seconds = pnh.param("record_seconds", 0.0);
  const bool looped = record_seconds > 0;
  const auto cfg = diffdope::load_objects_config(pnh.param<std::string>("objects_config", ""));
  std::map<std::string, bool> symmetric;
  for (const auto& o : cfg.objects) symmetric[o.name] = o.symmetric;
  Recorder rec;
  // Per-object rotation limits, e.g. for a slender object whose roll about its long axis only the print decides.
  rec.checker = diffdope_ros::PoseChecker::fromParams(pnh, symmetric);
  tf2_ros::Buffer tf_buffer(ros::Duration(120));
  tf2_ros::TransformListener tf_listener(tf_buffer);
  auto truth_sub = nh.subscribe("/ground_truth", 100, &Recorder::onTruth, &rec);
  auto refined_sub = nh.subscribe("/diffdope_refiner/refined_poses", 100, &Recorder::onRefined, &rec);
  std::vector<ros::Subscriber> object_subs;
  for (const auto& o : cfg.objects) {
    object_subs.push_back(nh.subscribe<geometry_msgs::PoseStamped>(
        "/diffdope_refiner/refined/" + o.name, 100,
        boost::bind(&Recorder::onObjectPose, &rec, boost::placeholders::_1, o.name)));
    object_subs.push_back(nh.subscribe<geometry_msgs::PoseWithCovarianceStamped>(
        "/diffdope_refiner/refined_cov/" + o.name, 100,
        boost::bind(&Recorder::onObjectCovariance, &rec, boost::placeholders::_1, o.name)));
  }
  ros::Subscriber overlay_sub, markers_sub, diag_sub;
  if (check_outputs) {  // subscribing is what turns the overlay and markers on
    overlay_sub = nh.subscribe("/diffdope_refiner/overlay", 2, &Recorder::onOverlay, &rec);
    markers_sub = nh.subscribe("/diffdope_refiner/markers", 2, &Recorder::onMarkers, &rec);
  }
  if (check_outputs || expect_detection_array) diag_sub = nh.subscribe("/diagnostics", 10, &Recorder::onDiagnostics, &rec);
  ros::AsyncSpinner spinner(2);
  spinner.start();

  // Wait for the bag to end (ground truth stops) and the refiner to go quiet.
  const ros::WallTime start = ros::WallTime::now();
  while ((ros::WallTime::now() - start).toSec() < (looped ? record_seconds : 120)) {
    ros::WallDuration(0.5).sleep();
    if (looped) continue;
    std::lock_guard<std::mutex> l(rec.mutex);
    const ros::WallTime now = ros::WallTime::now();
    if (!rec.last_truth.isZero() && (now - rec.last_truth).toSec() > 3 &&
        (rec.last_refined.isZero() || (now - rec.last_refined).toSec() > 3))
      break;
  }
  spinner.stop();

  std::lock_guard<std::mutex> l(rec.mutex);
  ASSERT_FALSE(rec.arrays.empty()) << "no ~refined_poses message";
  for (const auto& a : rec.arrays) rec.checker->addRefined(a);
  EXPECT_EQ(rec.checker->unmatched(), 0) << "refined poses stamped with no image stamp of the bag";
  const auto summary = rec.checker->summary();
  for (const auto& o : cfg.objects) {
    SCOPED_TRACE(o.name);
    ASSERT_TRUE(summary.count(o.name)) << "no refined pose for " << o.name;
    const auto& s = summary.at(o.name);
    EXPECT_GE(s.count, 3);
    if (each_within) {
      EXPECT_EQ(s.within, s.count) << "max error " << 1e3 * s.max_translation_m << " mm, "
                                   << s.max_rotation_rad * 180 / M_PI << " deg";
    } else {  // detector-seeded frames of every object: below, after this loop
      int n = 0;
      for (const auto& row : rec.checker->rows()) n += row.name == o.name && row.source == "detector";
      EXPECT_GT(n, 0) << "no detector-seeded frame";
    }
    if (each_within) {
      std::string rejected;
      for (const auto& row : rec.checker->rows())
        if (row.name == o.name && !row.plausible) rejected += "\n  " + diffdope_ros::PoseChecker::formatRow(row);
      EXPECT_EQ(s.plausible, s.count) << "called implausible:" << rejected;
    } else {
      // RGB alone leaves the distance along the viewing ray looser (a few millimetres), but the track must not
      // drift: every pose called plausible is within 2 cm and 5 degrees (and some are). The verdict may reject a
      // pose the print no longer lines up with, but never a right one (within 1 cm and 5 degrees; a pose 9 mm but
      // 16 degrees off is wrong, and rejecting it is right).
      for (const auto& row : rec.checker->rows()) {
        if (row.name != o.name) continue;
        const bool right = row.refined.translation_m < 0.01 && row.refined.rotation_rad < 5 * M_PI / 180;
        if (!row.plausible)
          EXPECT_FALSE(right) << "a pose within 1 cm and 5 deg called implausible: "
                              << diffdope_ros::PoseChecker::formatRow(row);
        else
          EXPECT_TRUE(row.refined.translation_m < 0.02 && row.refined.rotation_rad < 5 * M_PI / 180)
              << "a plausible pose drifted: " << diffdope_ros::PoseChecker::formatRow(row);
      }
      EXPECT_GT(s.plausible, 0);
    }
    // Every plausible refined pose also went out on ~refined/<name> and on TF.
    // (Looped: recording stops at an arbitrary moment, maybe between a frame's array and its per-object poses.)
    EXPECT_NEAR(int(rec.per_object[o.name].size()), s.plausible, looped ? 1 : 0);
    // Each published pose also goes out with its covariance: the same pose, a symmetric matrix with positive
    // variances (metres², radians²), none beyond what the object's size allows.
    EXPECT_NEAR(int(rec.per_object_cov[o.name].size()), int(rec.per_object[o.name].size()), looped ? 1 : 0);
    for (const auto& c : rec.per_object_cov[o.name]) {
      for (int i = 0; i < 6; ++i) {
        EXPECT_GT(c.pose.covariance[size_t(7 * i)], 0.0) << i;
        for (int j = 0; j < 6; ++j)
          EXPECT_NEAR(c.pose.covariance[size_t(6 * i + j)], c.pose.covariance[size_t(6 * j + i)], 1e-12);
      }
      EXPECT_LT(c.pose.covariance[0], 0.05) << "x variance (m^2)";
    }
    if (!rec.per_object_cov[o.name].empty()) {
      const auto& k = rec.per_object_cov[o.name].back().pose.covariance;
      std::printf("%s: covariance std x y z %.1f %.1f %.1f mm, rotation about x y z %.2f %.2f %.2f deg\n", o.name.c_str(),
                  1e3 * std::sqrt(k[0]), 1e3 * std::sqrt(k[7]), 1e3 * std::sqrt(k[14]), std::sqrt(k[21]) * 180 / M_PI,
                  std::sqrt(k[28]) * 180 / M_PI, std::sqrt(k[35]) * 180 / M_PI);
    }
  }
  if (!each_within) {
    // Detector-seeded frames, all objects together: refined closer than the detections, on average. (Per object
    // there may be a single such frame, and RGB alone leaves the distance along the viewing ray loose.)
    double init_t = 0, ref_t = 0, init_r = 0, ref_r = 0;
    for (const auto& row : rec.checker->rows())
      if (row.source == "detector") {
        init_t += row.initial.translation_m, ref_t += row.refined.translation_m;
        init_r += row.initial.rotation_rad, ref_r += row.refined.rotation_rad;
      }
    EXPECT_LT(ref_t, init_t);
    EXPECT_LT(ref_r, init_r);
  }
  for (const auto& row : rec.checker->rows()) std::printf("%s\n", diffdope_ros::PoseChecker::formatRow(row).c_str());
  // max_step_deg > 0: an object's consecutive published poses turn by at most this much (the objects move a few
  // degrees per refined frame): a symmetric object must not spin or flip with its detections.
  const double max_step_deg = pnh.param("max_step_deg", 0.0);
  for (const auto& [name, poses] : rec.per_object) {
    if (!(max_step_deg > 0)) break;
    std::vector<geometry_msgs::PoseStamped> sorted = poses;
    std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.header.stamp < b.header.stamp; });
    double worst = 0;
    for (size_t k = 1; k < sorted.size(); ++k)
      worst = std::max(worst, diffdope::rotation_angle(diffdope_ros::pose_from_msg(sorted[k - 1].pose, "refined").R,
                                                       diffdope_ros::pose_from_msg(sorted[k].pose, "refined").R));
    std::printf("%s: largest turn between consecutive published poses %.1f deg (%zu poses)\n", name.c_str(),
                worst * 180 / M_PI, sorted.size());
    EXPECT_GE(sorted.size(), 5u) << name;
    EXPECT_LE(worst * 180 / M_PI, max_step_deg) << name << " spun or flipped between frames";
  }

  double latency = 0;
  int tf_checked = 0;
  for (const auto& a : rec.arrays) {
    if (!looped) EXPECT_GT(a.latency, -0.05);  // sim time: the bag's clock stops at its last message
    EXPECT_GT(a.processing_time, 0.0);
    latency += a.latency;
    EXPECT_EQ(a.header.frame_id, "camera_color_optical_frame");
    for (const auto& p : a.poses) {
      SCOPED_TRACE(p.name);
      if (has_mask) {
        // Against the visible mask: the bag's layout keeps every object at least 75 % visible, so the IoU of the
        // right pose's full silhouette with it is at least ~0.75.
        EXPECT_GT(p.mask_iou, 0.7);
        EXPECT_LE(p.mask_iou, 1.0);
      } else if (has_depth) {
        // Against the pixels derived from depth.
        EXPECT_GT(p.mask_iou, 0.7);
        EXPECT_LE(p.mask_iou, 1.0);
      } else {
        EXPECT_EQ(p.mask_iou, -1.0);
      }
      if (has_depth) EXPECT_GT(p.depth_inliers, 0.5);
      else EXPECT_EQ(p.depth_inliers, -1.0);
      EXPECT_GT(p.iterations, 0);
      EXPECT_GT(p.time_ms, 0.0);
      // What was checked: the terms used, and a verdict in three states that agrees with plausible and judged
      // (the bag's objects all carry print, so the colour alone can judge them too).
      const auto used = [&](const std::string& term) {
        return std::find(p.terms.begin(), p.terms.end(), term) != p.terms.end();
      };
      EXPECT_TRUE(used("rgb"));
      EXPECT_EQ(used("depth"), has_depth);
      EXPECT_TRUE(used("mask"));  // without a mask, the pixels derived from depth, or without depth from colour
      EXPECT_TRUE(p.judged);
      EXPECT_EQ(p.verdict, p.plausible ? diffdope_ros::RefinedPose::PLAUSIBLE : diffdope_ros::RefinedPose::IMPLAUSIBLE);
      EXPECT_EQ(p.error, "");
      if (!has_mask && !has_depth) EXPECT_TRUE(std::isfinite(p.print_significance));
      // The best pose seen (the start itself when already optimal), unless the print alignment then turned it:
      // it may trade up to kPrintLossTolerance of loss for a clearly better print (RefineResult::print_turn).
      EXPECT_LE(p.loss, (1 + diffdope::kPrintLossTolerance) * p.initial_loss);
      EXPECT_TRUE(p.source == "detector" || p.source == "track" || p.source == "prediction") << p.source;
      if (!p.plausible || looped) continue;
      const auto t = tf_buffer.lookupTransform(a.header.frame_id, "diffdope_" + p.name, a.header.stamp);
      const auto tf_pose = diffdope_ros::pose_from_transform(t.transform, "tf");
      const auto msg_pose = diffdope_ros::pose_from_msg(p.pose.pose, "msg");
      EXPECT_LT((tf_pose.t - msg_pose.t).norm(), 1e-6);
      EXPECT_LT(diffdope::rotation_angle(tf_pose.R, msg_pose.R), 1e-6);
      ++tf_checked;
    }
  }
  if (!looped) EXPECT_GT(tf_checked, 0);
  int from_track = 0;
  for (const auto& row : rec.checker->rows()) from_track += row.source == "track" || row.source == "prediction";
  if (expect_track) EXPECT_GT(from_track, 0) << "no frame was seeded by tracking after the detector went silent";
  if (check_outputs) {
    EXPECT_GT(rec.overlays, 0);
    EXPECT_EQ(rec.overlay.encoding, "bgr8");
    EXPECT_EQ(rec.overlay.header.frame_id, "camera_color_optical_frame");
    EXPECT_EQ(rec.overlay.width, 640u);
    EXPECT_EQ(rec.overlay.height, 480u);
    ASSERT_FALSE(rec.markers.markers.empty());
    for (const auto& m : rec.markers.markers) {
      EXPECT_EQ(m.type, visualization_msgs::Marker::MESH_RESOURCE);
      EXPECT_EQ(m.mesh_resource.rfind("file://", 0), 0u) << m.mesh_resource;
      EXPECT_NE(m.mesh_resource.find(".ply"), std::string::npos) << m.mesh_resource;
    }
    bool ok_with_refined = false, time_jump_said = false;
    for (const auto& d : rec.diagnostics)
      for (const auto& kv : d.values) time_jump_said = time_jump_said || (kv.key == "warnings: time" && kv.value != "0");
    if (looped) EXPECT_TRUE(time_jump_said) << "the looped bag's jump back in time was not reported";
    else EXPECT_FALSE(time_jump_said) << "a time jump reported on a bag played once";
    for (const auto& d : rec.diagnostics) {
      if (d.level != diagnostic_msgs::DiagnosticStatus::OK) continue;
      for (const auto& kv : d.values)
        if (kv.key == "frames refined" && std::stoi(kv.value) > 0) ok_with_refined = true;
    }
    EXPECT_TRUE(ok_with_refined) << "no OK diagnostics reporting refined frames (" << rec.diagnostics.size()
                                 << " statuses)";
  }
  if (expect_detection_array) {
    std::string counts;
    for (const auto& d : rec.diagnostics)
      for (const auto& kv : d.values)
        if (kv.key == "input detections (Detection3DArray)") counts = kv.value;
    ASSERT_FALSE(counts.empty()) << "no Detection3DArray counts in the diagnostics";
    EXPECT_EQ(counts.find("received 0 "), std::string::npos) << counts;
    EXPECT_NE(counts.find("(malformed 0)"), std::string::npos) << counts;
    EXPECT_EQ(counts.find("of a known class 0,"), std::string::npos) << counts;
    EXPECT_NE(counts.find("of an unknown class id 0, unusable 0"), std::string::npos) << counts;
    std::printf("DOPE's Detection3DArray: %s\n", counts.c_str());
  }
  const double span = rec.arrays.size() > 1 ? (rec.arrays.back().header.stamp - rec.arrays.front().header.stamp).toSec() : 0;
  std::printf("%d object poses seeded by tracking\n", from_track);
  std::printf("refined %zu frames (%d object poses), mean latency %.0f ms, %.2f refined frames per bag second\n",
              rec.arrays.size(), int(rec.checker->rows().size()), 1e3 * latency / rec.arrays.size(),
              span > 0 ? (rec.arrays.size() - 1) / span : 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_bag_accuracy");
  return RUN_ALL_TESTS();
}
