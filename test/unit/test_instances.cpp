// Several instances of one object: association of detections with instances (instance_tracks.hpp) and the
// split of one observed mask among them (instance_masks.hpp).
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "diffdope/instance_masks.hpp"
#include "diffdope/instance_tracks.hpp"
#include "diffdope/procedural.hpp"

using namespace diffdope;

namespace {

Pose at(double x, double y = 0) { return Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, y, 0.6)); }

TrackOptions options() {
  TrackOptions o;
  o.max_detection_age = 0.5;
  o.track_timeout = 2.0;
  o.max_failures = 2;
  return o;
}

InstanceTracks tracks(int n) { return InstanceTracks(n, options(), Eigen::Vector3d::Zero(), 0.1); }

}  // namespace

TEST(InstanceTracks, OneInstanceTakesEveryDetectionAsAnObjectTrackDoes) {
  InstanceTracks t = tracks(1);
  EXPECT_EQ(t.add_detections({at(0.0)}, 10.0), std::vector<int>({0}));
  EXPECT_EQ(t.add_detections({at(0.5)}, 10.1), std::vector<int>({0}));  // far from the last: still the one
  auto seeds = t.track(0).seeds_for(10.1);
  ASSERT_EQ(seeds.size(), 1u);
  EXPECT_DOUBLE_EQ(seeds[0].pose.t.x(), 0.5);
  // Two in one message: the first (the detector's best) wins wherever it is, the other is reported.
  EXPECT_EQ(t.add_detections({at(0.0), at(0.51)}, 10.2), std::vector<int>({0, -1}));
}

TEST(InstanceTracks, StableIndicesByProximity) {
  InstanceTracks t = tracks(3);
  EXPECT_EQ(t.add_detections({at(0.0), at(0.3)}, 10.0), std::vector<int>({0, 1}));
  // The next message lists them the other way round, both moved by 3 cm.
  EXPECT_EQ(t.add_detections({at(0.33), at(0.03)}, 10.1), std::vector<int>({1, 0}));
  // A third one far from both takes the free index 2; the two others keep theirs.
  EXPECT_EQ(t.add_detections({at(0.03), at(-0.4), at(0.33)}, 10.2), std::vector<int>({0, 2, 1}));
  EXPECT_TRUE(t.seen(2, 10.2));
  // More detections than instances: the extra one is reported (-1), the seen ones keep theirs.
  EXPECT_EQ(t.add_detections({at(0.03), at(0.33), at(-0.4), at(0.8)}, 10.3), std::vector<int>({0, 1, 2, -1}));
}

TEST(InstanceTracks, RefinedPosesLeadTheAssociationAndLostInstancesAreFreed) {
  InstanceTracks t = tracks(2);
  t.add_detections({at(0.0), at(0.3)}, 10.0);
  t.track(0).seeds_for(10.0), t.track(1).seeds_for(10.0);
  // Instance 0 was refined 8 cm away from its detection: the next detection near the refined pose is its.
  EXPECT_FALSE(t.report(0, at(0.08), true, 10.0));
  EXPECT_FALSE(t.report(1, at(0.3), true, 10.0));
  EXPECT_EQ(t.assign({at(0.3), at(0.15)}, 10.1), std::vector<int>({1, 0}));
  // Instance 1 fails twice: its track is lost, its index free; a new object far away takes it.
  EXPECT_FALSE(t.report(1, at(0.3), false, 10.1));
  EXPECT_TRUE(t.report(1, at(0.3), false, 10.2));
  EXPECT_FALSE(t.seen(1, 10.2));
  EXPECT_EQ(t.assign({at(-0.5)}, 10.3), std::vector<int>({1}));
  // Past the horizon (max of track_timeout and max_detection_age), instance 0 is free again too.
  EXPECT_TRUE(t.seen(0, 11.9));
  EXPECT_FALSE(t.seen(0, 12.1));
  EXPECT_EQ(t.assign({at(0.9)}, 12.1), std::vector<int>({0}));
  t.reset();
  EXPECT_FALSE(t.seen(0, 10.0));
}

TEST(InstanceTracks, RefusesBadArguments) {
  EXPECT_THROW(InstanceTracks(0, options(), Eigen::Vector3d::Zero(), 0.1), std::invalid_argument);
  EXPECT_THROW(InstanceTracks(InstanceTracks::kMaxInstances + 1, options(), Eigen::Vector3d::Zero(), 0.1),
               std::invalid_argument);
  EXPECT_THROW(InstanceTracks(2, options(), Eigen::Vector3d::Zero(), 0.0), std::invalid_argument);
  EXPECT_THROW(InstanceTracks(2, options(), Eigen::Vector3d::Zero(), std::nan("")), std::invalid_argument);
  InstanceTracks t = tracks(2);
  TrackOptions bad = options();
  bad.max_failures = 0;
  EXPECT_THROW(t.set_options(bad), std::invalid_argument);
}

TEST(InstanceMasks, EachInstanceGetsItsOwnPartOfOneLabel) {
  const Camera cam(400, 400, 159.5, 119.5, 320, 240);
  const Mesh box = make_box(Eigen::Vector3d(0.06, 0.06, 0.06), make_label_texture(64, 3));
  // Two boxes 0.15 m apart at 0.6 m (100 px), a third blob of the same label far right that neither starts near.
  const Pose left = at(-0.075), right = at(0.075);
  cv::Mat mask = cv::Mat::zeros(240, 320, CV_8U);
  cv::rectangle(mask, cv::Rect(90, 100, 40, 40), cv::Scalar(3), cv::FILLED);   // around x = 110 (left)
  cv::rectangle(mask, cv::Rect(190, 100, 40, 40), cv::Scalar(3), cv::FILLED);  // around x = 210 (right)
  cv::rectangle(mask, cv::Rect(295, 10, 15, 15), cv::Scalar(3), cv::FILLED);   // nobody's
  // Starts a few pixels off the truth, as detections are.
  const std::vector<cv::Mat> parts = split_mask_among_instances(mask, cam, box, {at(-0.07, 0.005), at(0.08)}, 0.3);
  ASSERT_EQ(parts.size(), 2u);
  EXPECT_EQ(parts[0].type(), CV_32F);
  EXPECT_EQ(cv::countNonZero(parts[0]), 1600);
  EXPECT_EQ(cv::countNonZero(parts[1]), 1600);
  EXPECT_EQ(parts[0].at<float>(120, 110), 1.f);
  EXPECT_EQ(parts[1].at<float>(120, 210), 1.f);
  EXPECT_EQ(parts[0].at<float>(15, 300) + parts[1].at<float>(15, 300), 0.f);

  // Touching in the image: one component, shared pixel by pixel between the two boxes.
  cv::Mat touching = cv::Mat::zeros(240, 320, CV_8U);
  cv::rectangle(touching, cv::Rect(110, 100, 100, 40), cv::Scalar(1), cv::FILLED);
  const auto shared = split_mask_among_instances(touching, cam, box, {left, right}, 0.3);
  EXPECT_EQ(cv::countNonZero(shared[0]) + cv::countNonZero(shared[1]), 4000);
  EXPECT_EQ(shared[0].at<float>(120, 115), 1.f);
  EXPECT_EQ(shared[1].at<float>(120, 205), 1.f);
  EXPECT_EQ(shared[0].at<float>(120, 205), 0.f);
  EXPECT_NEAR(cv::countNonZero(shared[0]), 2000, 80);
}
