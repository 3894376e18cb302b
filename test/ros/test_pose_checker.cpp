// Unit tests for pose_error and PoseChecker (scoring refined poses against ground truth; no ROS master needed).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/pose_checker.hpp"

namespace {

using diffdope_ros::InitialPose;
using diffdope_ros::InitialPoseArray;
using diffdope_ros::PoseChecker;
using diffdope_ros::PoseError;
using diffdope_ros::RefinedPose;
using diffdope_ros::RefinedPoseArray;
using diffdope_ros::pose_error;

constexpr double kDeg = M_PI / 180.0;

diffdope::Pose make_pose(const Eigen::Vector3d& axis, double angle_rad, const Eigen::Vector3d& t) {
  return diffdope::Pose(Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix(), t);
}

// A ground-truth pose that is not axis aligned, so errors are not trivially read off one axis.
diffdope::Pose truth_pose() { return make_pose(Eigen::Vector3d(0.3, -1.0, 0.4), 0.9, Eigen::Vector3d(0.05, -0.02, 0.8)); }

// truth moved by `dt` (camera frame) and rotated by `angle` about the model axis `model_axis` (applied on the
// right: R_est = R_truth * Rot(model_axis, angle)).
diffdope::Pose perturbed(const diffdope::Pose& truth, const Eigen::Vector3d& dt, const Eigen::Vector3d& model_axis,
                         double angle) {
  return diffdope::Pose(truth.R * Eigen::AngleAxisd(angle, model_axis.normalized()).toRotationMatrix(), truth.t + dt);
}

// ---------------------------------------------------------------------------------------------------------------
// pose_error

TEST(PoseError, IdenticalPosesHaveZeroError) {
  const diffdope::Pose p = truth_pose();
  for (bool sym : {false, true}) {
    const PoseError e = pose_error(p, p, sym);
    EXPECT_NEAR(e.translation_m, 0.0, 1e-12);
    EXPECT_NEAR(e.rotation_rad, 0.0, 1e-6);
  }
}

TEST(PoseError, TranslationIsEuclideanDistance) {
  const diffdope::Pose truth = truth_pose();
  const diffdope::Pose est = perturbed(truth, Eigen::Vector3d(0.003, -0.004, 0.012), Eigen::Vector3d::UnitX(), 0.0);
  for (bool sym : {false, true}) {
    const PoseError e = pose_error(est, truth, sym);
    EXPECT_NEAR(e.translation_m, 0.013, 1e-12);  // sqrt(9 + 16 + 144) mm
    EXPECT_NEAR(e.rotation_rad, 0.0, 1e-6);
  }
  // Symmetric in its arguments.
  EXPECT_NEAR(pose_error(truth, est, false).translation_m, 0.013, 1e-12);
}

TEST(PoseError, RotationIsRelativeAngle) {
  const diffdope::Pose truth = truth_pose();
  const Eigen::Vector3d axes[] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(),
                                  Eigen::Vector3d(1, 2, 3)};
  for (const Eigen::Vector3d& axis : axes) {
    for (double deg : {5.0, 30.0, 120.0}) {
      const diffdope::Pose est = perturbed(truth, Eigen::Vector3d::Zero(), axis, deg * kDeg);
      const PoseError e = pose_error(est, truth, false);
      EXPECT_NEAR(e.rotation_rad, deg * kDeg, 1e-7) << "axis " << axis.transpose() << " deg " << deg;
      EXPECT_NEAR(e.translation_m, 0.0, 1e-12);
      // Rotation applied in the camera frame instead of the model frame: same angle.
      const diffdope::Pose est_cam(Eigen::AngleAxisd(deg * kDeg, axis.normalized()).toRotationMatrix() * truth.R,
                                   truth.t);
      EXPECT_NEAR(pose_error(est_cam, truth, false).rotation_rad, deg * kDeg, 1e-7);
    }
  }
  // 180 degrees is the largest possible error.
  const diffdope::Pose flipped = perturbed(truth, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitY(), M_PI);
  EXPECT_NEAR(pose_error(flipped, truth, false).rotation_rad, M_PI, 1e-6);
}

TEST(PoseError, SymmetricIgnoresRotationAboutModelZ) {
  const diffdope::Pose truth = truth_pose();
  for (double deg : {10.0, 90.0, 179.0}) {
    const diffdope::Pose est = perturbed(truth, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), deg * kDeg);
    EXPECT_NEAR(pose_error(est, truth, false).rotation_rad, deg * kDeg, 1e-7);  // counts when not symmetric
    EXPECT_NEAR(pose_error(est, truth, true).rotation_rad, 0.0, 1e-6);          // not when symmetric
  }
}

TEST(PoseError, SymmetricIsAngleBetweenZAxes) {
  const diffdope::Pose truth = truth_pose();
  // Tilt of the z axis by 10 degrees (rotation about the model x axis).
  const diffdope::Pose tilted = perturbed(truth, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), 10 * kDeg);
  EXPECT_NEAR(pose_error(tilted, truth, true).rotation_rad, 10 * kDeg, 1e-7);
  // Same tilt about another in-plane axis, plus a spin about z first: still 10 degrees.
  const diffdope::Pose spun = perturbed(truth, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 70 * kDeg);
  const diffdope::Pose spun_tilted = perturbed(spun, Eigen::Vector3d::Zero(), Eigen::Vector3d(1, 1, 0), 10 * kDeg);
  EXPECT_NEAR(pose_error(spun_tilted, truth, true).rotation_rad, 10 * kDeg, 1e-7);
  // Upside down: 180 degrees.
  const diffdope::Pose flipped = perturbed(truth, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitX(), M_PI);
  EXPECT_NEAR(pose_error(flipped, truth, true).rotation_rad, M_PI, 1e-6);
  // Verify against the definition directly.
  const double c = spun_tilted.R.col(2).dot(truth.R.col(2));
  EXPECT_NEAR(pose_error(spun_tilted, truth, true).rotation_rad, std::acos(c), 1e-12);
}

// ---------------------------------------------------------------------------------------------------------------
// PoseChecker

InitialPose truth_entry(const std::string& name, const ros::Time& stamp, const diffdope::Pose& pose) {
  InitialPose p;
  p.name = name;
  p.pose.header.stamp = stamp;
  p.pose.header.frame_id = "camera_color_optical_frame";
  p.pose.pose = diffdope_ros::pose_to_msg(pose);
  return p;
}

RefinedPose refined_entry(const std::string& name, const ros::Time& stamp, const diffdope::Pose& refined,
                          const diffdope::Pose& initial, bool plausible = true, double iou = 0.9,
                          double time_ms = 42.0, const std::string& source = "detector") {
  RefinedPose p;
  p.name = name;
  p.pose.header.stamp = stamp;
  p.pose.header.frame_id = "camera_color_optical_frame";
  p.pose.pose = diffdope_ros::pose_to_msg(refined);
  p.initial_pose = diffdope_ros::pose_to_msg(initial);
  p.source = source;
  p.mask_iou = iou;
  p.depth_inliers = 0.75;
  p.plausible = plausible;
  p.time_ms = time_ms;
  return p;
}

TEST(PoseChecker, MatchesByStampAndNameWithInitialAndRefinedErrors) {
  const ros::Time t1(100, 250000000), t2(100, 283333333);
  const diffdope::Pose mug = truth_pose();
  const diffdope::Pose box = make_pose(Eigen::Vector3d::UnitY(), 0.4, Eigen::Vector3d(-0.1, 0.05, 0.6));

  PoseChecker checker(0.01, 5 * kDeg);
  InitialPoseArray truth;
  truth.poses = {truth_entry("mug", t1, mug), truth_entry("box", t1, box), truth_entry("mug", t2, mug)};
  checker.addGroundTruth(truth);

  RefinedPoseArray refined;
  refined.header.stamp = t1;
  refined.latency = 0.125;
  refined.poses = {
      refined_entry("mug", t1, perturbed(mug, Eigen::Vector3d(0.002, 0, 0), Eigen::Vector3d::UnitX(), 1 * kDeg),
                    perturbed(mug, Eigen::Vector3d(0, 0.02, 0), Eigen::Vector3d::UnitY(), 8 * kDeg), true, 0.91, 37.0,
                    "track"),
      refined_entry("box", t1, perturbed(box, Eigen::Vector3d(0, 0, 0.004), Eigen::Vector3d::UnitZ(), 2 * kDeg),
                    perturbed(box, Eigen::Vector3d(0.03, 0, 0), Eigen::Vector3d::UnitZ(), 10 * kDeg), false, 0.4),
  };
  const std::vector<PoseChecker::Row> rows = checker.addRefined(refined);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(checker.unmatched(), 0);
  ASSERT_EQ(checker.rows().size(), 2u);

  const PoseChecker::Row& r = rows[0];
  EXPECT_EQ(r.name, "mug");
  EXPECT_EQ(r.source, "track");
  EXPECT_NEAR(r.stamp, t1.toSec(), 1e-9);
  EXPECT_NEAR(r.refined.translation_m, 0.002, 1e-9);
  EXPECT_NEAR(r.refined.rotation_rad, 1 * kDeg, 1e-6);
  EXPECT_NEAR(r.initial.translation_m, 0.02, 1e-9);
  EXPECT_NEAR(r.initial.rotation_rad, 8 * kDeg, 1e-6);
  EXPECT_TRUE(r.plausible);
  EXPECT_DOUBLE_EQ(r.mask_iou, 0.91);
  EXPECT_DOUBLE_EQ(r.depth_inliers, 0.75);
  EXPECT_DOUBLE_EQ(r.time_ms, 37.0);
  EXPECT_DOUBLE_EQ(r.latency, 0.125);

  const PoseChecker::Row& b = rows[1];
  EXPECT_EQ(b.name, "box");
  EXPECT_NEAR(b.refined.translation_m, 0.004, 1e-9);
  EXPECT_NEAR(b.refined.rotation_rad, 2 * kDeg, 1e-6);
  EXPECT_NEAR(b.initial.translation_m, 0.03, 1e-9);
  EXPECT_NEAR(b.initial.rotation_rad, 10 * kDeg, 1e-6);
  EXPECT_FALSE(b.plausible);
}

TEST(PoseChecker, UnmatchedStampOrNameIsCountedNotScored) {
  const ros::Time t1(5, 0);
  const diffdope::Pose mug = truth_pose();
  PoseChecker checker(0.01, 5 * kDeg);
  InitialPoseArray truth;
  truth.poses = {truth_entry("mug", t1, mug)};
  checker.addGroundTruth(truth);

  RefinedPoseArray refined;
  refined.poses = {
      refined_entry("mug", ros::Time(5, 1), mug, mug),  // one nanosecond later: no exact match
      refined_entry("mug", ros::Time(6, 0), mug, mug),  // a stamp with no truth at all
      refined_entry("cup", t1, mug, mug),               // right stamp, other name
      refined_entry("Mug", t1, mug, mug),               // names are case sensitive
  };
  EXPECT_TRUE(checker.addRefined(refined).empty());
  EXPECT_EQ(checker.unmatched(), 4);
  EXPECT_TRUE(checker.rows().empty());
  EXPECT_TRUE(checker.summary().empty());

  // The exact stamp and name match, and unmatched() keeps its count.
  refined.poses = {refined_entry("mug", t1, mug, mug)};
  const auto rows = checker.addRefined(refined);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_NEAR(rows[0].refined.translation_m, 0.0, 1e-12);
  EXPECT_EQ(checker.unmatched(), 4);
  EXPECT_EQ(checker.rows().size(), 1u);
}

TEST(PoseChecker, TruthAddedLaterAndPerStamp) {
  const diffdope::Pose mug = truth_pose();
  PoseChecker checker(0.01, 5 * kDeg);
  // Refined before any truth: unmatched.
  RefinedPoseArray refined;
  refined.poses = {refined_entry("mug", ros::Time(1, 0), mug, mug)};
  EXPECT_TRUE(checker.addRefined(refined).empty());
  EXPECT_EQ(checker.unmatched(), 1);

  // Two stamps with different truth: each refined pose is scored against its own stamp's truth.
  const diffdope::Pose mug2 = perturbed(mug, Eigen::Vector3d(0.1, 0, 0), Eigen::Vector3d::UnitX(), 0.0);
  InitialPoseArray truth;
  truth.poses = {truth_entry("mug", ros::Time(1, 0), mug), truth_entry("mug", ros::Time(2, 0), mug2)};
  checker.addGroundTruth(truth);
  refined.poses = {refined_entry("mug", ros::Time(1, 0), mug, mug), refined_entry("mug", ros::Time(2, 0), mug, mug)};
  const auto rows = checker.addRefined(refined);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_NEAR(rows[0].refined.translation_m, 0.0, 1e-12);
  EXPECT_NEAR(rows[1].refined.translation_m, 0.1, 1e-12);
}

TEST(PoseChecker, SymmetricObjectsIgnoreSpinAboutZ) {
  const ros::Time t(3, 0);
  const diffdope::Pose can = truth_pose();
  const diffdope::Pose spun = perturbed(can, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ(), 60 * kDeg);
  PoseChecker checker(0.01, 5 * kDeg, {{"can", true}, {"box", false}});
  InitialPoseArray truth;
  truth.poses = {truth_entry("can", t, can), truth_entry("box", t, can), truth_entry("mug", t, can)};
  checker.addGroundTruth(truth);
  RefinedPoseArray refined;
  refined.poses = {refined_entry("can", t, spun, spun), refined_entry("box", t, spun, spun),
                   refined_entry("mug", t, spun, spun)};
  const auto rows = checker.addRefined(refined);
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_NEAR(rows[0].refined.rotation_rad, 0.0, 1e-6);  // can: symmetric
  EXPECT_NEAR(rows[0].initial.rotation_rad, 0.0, 1e-6);
  EXPECT_TRUE(checker.within(rows[0]));
  EXPECT_NEAR(rows[1].refined.rotation_rad, 60 * kDeg, 1e-6);  // box: listed as not symmetric
  EXPECT_FALSE(checker.within(rows[1]));
  EXPECT_NEAR(rows[2].refined.rotation_rad, 60 * kDeg, 1e-6);  // mug: not listed -> not symmetric
}

TEST(PoseChecker, WithinUsesBothThresholds) {
  const PoseChecker checker(0.01, 5 * kDeg);
  PoseChecker::Row r;
  r.refined = {0.005, 2 * kDeg};
  EXPECT_TRUE(checker.within(r));
  r.refined = {0.02, 2 * kDeg};  // translation too large
  EXPECT_FALSE(checker.within(r));
  r.refined = {0.005, 6 * kDeg};  // rotation too large
  EXPECT_FALSE(checker.within(r));
  r.refined = {0.02, 6 * kDeg};
  EXPECT_FALSE(checker.within(r));
  r.refined = {0.01, 5 * kDeg};  // on the thresholds counts as within
  EXPECT_TRUE(checker.within(r));
  // The initial error does not matter.
  r.refined = {0.0, 0.0};
  r.initial = {1.0, M_PI};
  EXPECT_TRUE(checker.within(r));
}

TEST(PoseChecker, SummaryPerObject) {
  const diffdope::Pose mug = truth_pose();
  const diffdope::Pose box = make_pose(Eigen::Vector3d::UnitY(), 0.4, Eigen::Vector3d(-0.1, 0.05, 0.6));
  PoseChecker checker(0.01, 5 * kDeg);
  InitialPoseArray truth;
  for (int i = 0; i < 3; ++i) {
    truth.poses.push_back(truth_entry("mug", ros::Time(10 + i, 0), mug));
    truth.poses.push_back(truth_entry("box", ros::Time(10 + i, 0), box));
  }
  checker.addGroundTruth(truth);

  // mug: refined errors (2 mm, 1 deg), (4 mm, 3 deg), (20 mm, 2 deg) -> 2 within; initial (10, 20, 30) mm, 10 deg.
  const double mug_t[3] = {0.002, 0.004, 0.020}, mug_r[3] = {1, 3, 2}, mug_it[3] = {0.01, 0.02, 0.03};
  // box: one frame, refined (1 mm, 7 deg) -> not within; initial 40 mm, 20 deg.
  for (int i = 0; i < 3; ++i) {
    RefinedPoseArray refined;
    const ros::Time t(10 + i, 0);
    refined.poses.push_back(refined_entry(
        "mug", t, perturbed(mug, Eigen::Vector3d(mug_t[i], 0, 0), Eigen::Vector3d::UnitX(), mug_r[i] * kDeg),
        perturbed(mug, Eigen::Vector3d(0, mug_it[i], 0), Eigen::Vector3d::UnitY(), 10 * kDeg), i != 1));
    if (i == 0)
      refined.poses.push_back(refined_entry(
          "box", t, perturbed(box, Eigen::Vector3d(0, 0, 0.001), Eigen::Vector3d::UnitX(), 7 * kDeg),
          perturbed(box, Eigen::Vector3d(0.04, 0, 0), Eigen::Vector3d::UnitZ(), 20 * kDeg), true));
    checker.addRefined(refined);
  }
  // And one without truth, which must not appear in the summary.
  RefinedPoseArray stray;
  stray.poses = {refined_entry("mug", ros::Time(99, 0), mug, mug)};
  checker.addRefined(stray);
  EXPECT_EQ(checker.unmatched(), 1);

  const auto s = checker.summary();
  ASSERT_EQ(s.size(), 2u);
  ASSERT_EQ(s.count("mug"), 1u);
  ASSERT_EQ(s.count("box"), 1u);

  const PoseChecker::ObjectSummary& m = s.at("mug");
  EXPECT_EQ(m.count, 3);
  EXPECT_EQ(m.within, 2);
  EXPECT_EQ(m.plausible, 2);
  EXPECT_NEAR(m.max_translation_m, 0.020, 1e-9);
  EXPECT_NEAR(m.max_rotation_rad, 3 * kDeg, 1e-6);
  EXPECT_NEAR(m.mean_translation_m, (0.002 + 0.004 + 0.020) / 3, 1e-9);
  EXPECT_NEAR(m.mean_rotation_rad, 2 * kDeg, 1e-6);
  EXPECT_NEAR(m.mean_initial_translation_m, 0.02, 1e-9);
  EXPECT_NEAR(m.mean_initial_rotation_rad, 10 * kDeg, 1e-6);

  const PoseChecker::ObjectSummary& b = s.at("box");
  EXPECT_EQ(b.count, 1);
  EXPECT_EQ(b.within, 0);
  EXPECT_EQ(b.plausible, 1);
  EXPECT_NEAR(b.max_translation_m, 0.001, 1e-9);
  EXPECT_NEAR(b.max_rotation_rad, 7 * kDeg, 1e-6);
  EXPECT_NEAR(b.mean_translation_m, 0.001, 1e-9);
  EXPECT_NEAR(b.mean_rotation_rad, 7 * kDeg, 1e-6);
  EXPECT_NEAR(b.mean_initial_translation_m, 0.04, 1e-9);
  EXPECT_NEAR(b.mean_initial_rotation_rad, 20 * kDeg, 1e-6);
}

TEST(PoseChecker, FormatRowContainsNameAndNumbers) {
  PoseChecker::Row r;
  r.stamp = 12.5;
  r.name = "sugar_box";
  r.source = "track";
  r.initial = {0.0234, 12.3 * kDeg};
  r.refined = {0.0017, 0.85 * kDeg};
  r.plausible = true;
  r.mask_iou = 0.87;
  r.time_ms = 48;
  const std::string s = PoseChecker::formatRow(r);
  EXPECT_NE(s.find("sugar_box"), std::string::npos) << s;
  EXPECT_NE(s.find("track"), std::string::npos) << s;
  EXPECT_NE(s.find("12.500"), std::string::npos) << s;  // stamp
  EXPECT_NE(s.find("23.4"), std::string::npos) << s;    // initial mm
  EXPECT_NE(s.find("12.3"), std::string::npos) << s;    // initial deg
  EXPECT_NE(s.find("1.7"), std::string::npos) << s;     // refined mm
  EXPECT_NE(s.find("0.85"), std::string::npos) << s;    // refined deg
  EXPECT_NE(s.find("0.87"), std::string::npos) << s;    // iou
  EXPECT_NE(s.find("48"), std::string::npos) << s;      // time
  EXPECT_NE(s.find("ok"), std::string::npos) << s;
  EXPECT_EQ(s.find("IMPLAUSIBLE"), std::string::npos) << s;

  r.plausible = false;
  r.name = "a_rather_long_object_name_that_exceeds_the_column";
  const std::string s2 = PoseChecker::formatRow(r);
  EXPECT_NE(s2.find("IMPLAUSIBLE"), std::string::npos) << s2;
  EXPECT_NE(s2.find(r.name), std::string::npos) << s2;
}

}  // namespace
