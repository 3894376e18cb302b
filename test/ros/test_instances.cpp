// rostest (instances.test): two instances of one object (the printed box twice, one mask label, both detected in
// one InitialPoseArray in a random order). Each instance must be refined onto its own box, keep its index for the
// whole bag (tracking carries on after the detector goes silent), appear on TF as <prefix>box_<k>; and ~refine
// must take two initial poses of the box (its instances) and refuse more than max_instances.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <map>
#include <mutex>
#include <set>

#include "diffdope_ros/InitialPoseArray.h"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/RefinedPoseArray.h"
#include "diffdope_ros/conversions.hpp"

namespace {

const char* kService = "/diffdope_refiner/refine";

struct Match {
  int truth = -1;  // index in the ground truth message (which box)
  double error_m = 0, error_deg = 0;
  std::string source;
};

struct World {
  std::mutex mutex;
  std::map<int64_t, diffdope_ros::InitialPoseArray> truth;  // by stamp
  std::vector<diffdope_ros::RefinedPoseArrayConstPtr> arrays;  // as received
  std::vector<std::pair<int, Match>> refined;                // (instance, match) of every plausible result
  int unmatched = 0;                                          // results without ground truth at their stamp

  void onTruth(const diffdope_ros::InitialPoseArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    truth[m->header.stamp.toNSec()] = *m;
  }
  /// The box nearest `pose` in the truth at `stamp` (-1 without truth at that stamp).
  Match match(const geometry_msgs::Pose& pose, const ros::Time& stamp) {
    Match best;
    auto it = truth.find(stamp.toNSec());
    if (it == truth.end()) return best;
    const diffdope::Pose p = diffdope_ros::pose_from_msg(pose, "refined");
    for (size_t j = 0; j < it->second.poses.size(); ++j) {
      const diffdope::Pose g = diffdope_ros::pose_from_msg(it->second.poses[j].pose.pose, "truth");
      const double e = (p.t - g.t).norm();
      if (best.truth < 0 || e < best.error_m) {
        best.truth = int(j), best.error_m = e;
        best.error_deg = Eigen::AngleAxisd(p.R * g.R.transpose()).angle() * 180.0 / M_PI;
      }
    }
    return best;
  }
  void onRefined(const diffdope_ros::RefinedPoseArrayConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    arrays.push_back(m);
  }
  /// The plausible results against the ground truth at their stamps, once the bag has played (a frame's truth
  /// comes on another connection and may be handled after its result). Call with the mutex held.
  void matchAll() {
    for (const auto& m : arrays)
      for (const auto& r : m->poses) {
        if (!r.plausible) continue;
        Match mt = match(r.pose.pose, m->header.stamp);
        mt.source = r.source;
        if (mt.truth < 0) ++unmatched;
        else refined.emplace_back(r.instance, mt);
      }
  }
};
World* world = nullptr;

}  // namespace

TEST(Instances, EachInstanceOnItsOwnBoxWithAStableIndex) {
  tf2_ros::Buffer tf(ros::Duration(60));
  tf2_ros::TransformListener listener(tf);
  // Wait for the bag to play through (50 frames at 10 Hz; the detector is silent after frame 30).
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(90);
  size_t last = 0;
  ros::WallTime quiet_since = ros::WallTime::now();
  while (ros::WallTime::now() < end) {
    ros::WallDuration(0.5).sleep();
    std::lock_guard<std::mutex> l(world->mutex);
    if (world->arrays.size() != last) last = world->arrays.size(), quiet_since = ros::WallTime::now();
    if (last > 0 && ros::WallTime::now() - quiet_since > ros::WallDuration(6.0)) break;  // the bag has ended
  }
  std::lock_guard<std::mutex> l(world->mutex);
  world->matchAll();
  ASSERT_FALSE(world->refined.empty()) << "nothing refined";
  std::map<int, std::set<int>> truth_of;  // instance -> boxes it was refined onto
  std::map<int, int> results, tracked;
  double worst_m = 0, worst_deg = 0;
  for (const auto& [instance, m] : world->refined) {
    truth_of[instance].insert(m.truth);
    ++results[instance];
    tracked[instance] += m.source == "track" || m.source == "prediction";
    worst_m = std::max(worst_m, m.error_m), worst_deg = std::max(worst_deg, m.error_deg);
    EXPECT_LT(m.error_m, 0.005) << "instance " << instance << " " << m.error_m * 1e3 << " mm from box " << m.truth;
    EXPECT_LT(m.error_deg, 3.0) << "instance " << instance << " " << m.error_deg << " deg from box " << m.truth;
  }
  ASSERT_EQ(results.size(), 2u) << "expected instances 0 and 1";
  for (int k : {0, 1}) {
    EXPECT_GE(results[k], 5) << "instance " << k;
    EXPECT_EQ(truth_of[k].size(), 1u) << "instance " << k << " moved from one box to the other";
    EXPECT_GT(tracked[k], 0) << "instance " << k << " was never carried by its track";
  }
  EXPECT_NE(*truth_of[0].begin(), *truth_of[1].begin()) << "both instances on the same box";
  EXPECT_EQ(world->unmatched, 0);
  std::printf("instances: %d + %d plausible results, worst %.2f mm / %.2f deg, tracked %d + %d\n", results[0],
              results[1], worst_m * 1e3, worst_deg, tracked[0], tracked[1]);
  std::string frames = tf.allFramesAsString();
  EXPECT_NE(frames.find("diffdope_box_0"), std::string::npos) << frames;
  EXPECT_NE(frames.find("diffdope_box_1"), std::string::npos) << frames;
  EXPECT_EQ(frames.find("Frame diffdope_box exists"), std::string::npos) << frames;
}

TEST(Instances, ServiceTakesOnePosePerInstance) {
  diffdope_ros::InitialPoseArray truth;
  {
    std::lock_guard<std::mutex> l(world->mutex);
    ASSERT_FALSE(world->truth.empty());
    truth = world->truth.rbegin()->second;  // the last frame: the one the service refines on
  }
  ASSERT_EQ(truth.poses.size(), 2u);
  diffdope_ros::Refine srv;
  for (const auto& p : truth.poses) {
    diffdope_ros::InitialPose start = p;
    start.pose.pose.position.x += 0.004;  // a few millimetres off
    srv.request.initial_poses.push_back(start);
  }
  ASSERT_TRUE(ros::service::call(kService, srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  ASSERT_EQ(srv.response.results.size(), 2u);
  std::set<int> instances, boxes;
  for (const auto& r : srv.response.results) {
    instances.insert(r.instance);
    std::lock_guard<std::mutex> l(world->mutex);
    const Match m = world->match(r.pose.pose, r.pose.header.stamp);
    ASSERT_GE(m.truth, 0) << "no truth at the result's stamp";
    boxes.insert(m.truth);
    EXPECT_LT(m.error_m, 0.005);
    EXPECT_EQ(r.source, "request");
  }
  EXPECT_EQ(instances, (std::set<int>{0, 1}));
  EXPECT_EQ(boxes.size(), 2u);
  // A third box is more than max_instances (2): refused, naming why.
  srv.request.initial_poses.push_back(srv.request.initial_poses.front());
  ASSERT_TRUE(ros::service::call(kService, srv));
  EXPECT_FALSE(srv.response.success);
  EXPECT_NE(srv.response.message.find("max_instances 2"), std::string::npos) << srv.response.message;
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_instances");
  ros::NodeHandle nh;
  World w;
  world = &w;
  ros::Subscriber truth = nh.subscribe("/ground_truth", 100, &World::onTruth, &w);
  ros::Subscriber refined = nh.subscribe("/diffdope_refiner/refined_poses", 100, &World::onRefined, &w);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
