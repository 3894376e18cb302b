// Which instances the refiner nodelet refines from which starts (refine_targets.hpp), without a ROS master: a
// streamed frame takes every start, a ~refine call is checked before anything is used up.
#include <gtest/gtest.h>

#include <memory>

#include "diffdope_ros/refine_targets.hpp"

using namespace diffdope_ros;

namespace {

diffdope::Pose at(double x, double z = 1.0) {
  diffdope::Pose p;
  p.t = Eigen::Vector3d(x, 0, z);
  return p;
}

struct Scene {
  std::unique_ptr<diffdope::InstanceTracks> box, twins;
  std::vector<TargetObject> objects;
  Scene() {
    diffdope::TrackOptions options;
    box = std::make_unique<diffdope::InstanceTracks>(1, options, Eigen::Vector3d::Zero(), 0.1);
    twins = std::make_unique<diffdope::InstanceTracks>(2, options, Eigen::Vector3d::Zero(), 0.1);
    objects = {{"box", 1, "", box.get()}, {"twin", 2, "", twins.get()}, {"ghost", 1, "cannot load its mesh", nullptr}};
  }
};

}  // namespace

TEST(RefineTargets, StreamingTakesEveryDetectionOnce) {
  Scene scene;
  scene.box->add_detections({at(0)}, 10.0);
  scene.twins->add_detections({at(-0.5), at(0.5)}, 10.0);
  const StreamingTargets first = streaming_targets(scene.objects, 10.0);
  ASSERT_EQ(first.seeds.size(), 3u);
  EXPECT_EQ(first.seeds[0].object, 0u);
  EXPECT_EQ(first.seeds[1].object, 1u);
  EXPECT_EQ(first.seeds[2].instance, 1);
  for (const TargetSeeds& s : first.seeds) EXPECT_FALSE(s.steady);  // from detections, not from steady tracks
  EXPECT_TRUE(streaming_targets(scene.objects, 10.1).seeds.empty());  // used up, and nothing refined yet
}

TEST(RefineTargets, EachSeedSaysWhetherItStartsFromASteadyTrack) {
  // The box refined on two frames in a row starts the third from a steady track (the tracking budget); a twin with
  // a fresh detection on that frame does not, and the box keeps its budget beside it.
  Scene scene;
  scene.box->add_detections({at(0)}, 10.0);
  ASSERT_EQ(streaming_targets(scene.objects, 10.0).seeds.size(), 1u);
  EXPECT_FALSE(scene.box->report(0, at(0), true, 10.0));
  EXPECT_FALSE(scene.box->report(0, at(0.001), true, 10.033));
  scene.twins->add_detections({at(0.5)}, 10.066);
  const StreamingTargets third = streaming_targets(scene.objects, 10.066);
  ASSERT_EQ(third.seeds.size(), 2u);
  EXPECT_EQ(third.seeds[0].object, 0u);
  EXPECT_TRUE(third.seeds[0].steady);
  EXPECT_EQ(third.seeds[1].object, 1u);
  EXPECT_FALSE(third.seeds[1].steady);
}

TEST(RefineTargets, RequestNamesAreCheckedFirst) {
  Scene scene;
  diffdope::RefinerOptions configured;
  RefineRequestNames r;
  r.object_names = {"box", "typo"};
  EXPECT_EQ(check_refine_request(scene.objects, r, configured).error,
            "unknown object name(s): typo (not in the objects config)");
  r.object_names = {"ghost"};
  EXPECT_EQ(check_refine_request(scene.objects, r, configured).error,
            "object(s) disabled: ghost (cannot load its mesh)");
  r.object_names = {"box"};
  r.iterations = -1;
  EXPECT_EQ(check_refine_request(scene.objects, r, configured).error,
            "iterations and batch_size must be >= 0 (0 = configured)");
  r.iterations = 1001;
  EXPECT_NE(check_refine_request(scene.objects, r, configured).error.find("iterations <= 1000"), std::string::npos);
}

TEST(RefineTargets, RequestOverridesAndNames) {
  Scene scene;
  diffdope::RefinerOptions configured;
  RefineRequestNames r;
  r.object_names = {"twin"};
  r.pose_names = {"box"};
  r.iterations = 7;
  const CheckedRequest c = check_refine_request(scene.objects, r, configured);
  ASSERT_EQ(c.error, "");
  EXPECT_EQ(c.options.iterations, 7);
  EXPECT_EQ(c.options.batch_size, configured.batch_size);
  EXPECT_EQ(c.pose_object, std::vector<size_t>{0});
  EXPECT_EQ(c.named, (std::vector<bool>{false, true, false}));
  EXPECT_FALSE(c.everything);
  EXPECT_TRUE(check_refine_request(scene.objects, {}, configured).everything);
}

TEST(RefineTargets, RequestPlanUsesNothingUp) {
  Scene scene;
  diffdope::RefinerOptions configured;
  RefineRequestNames r;
  r.object_names = {"twin"};
  r.pose_names = {"box"};
  const CheckedRequest c = check_refine_request(scene.objects, r, configured);
  // A named object without any start: refused, saying which.
  RequestTargets t = plan_request_targets(scene.objects, c, {{0, {at(0)}}}, 10.0);
  EXPECT_EQ(t.error, "no initial pose for twin (no recent detection or track); pass initial_poses");
  scene.twins->add_detections({at(0.5)}, 10.0);
  t = plan_request_targets(scene.objects, c, {{0, {at(0)}}}, 10.0);
  ASSERT_EQ(t.error, "");
  ASSERT_EQ(t.seeds.size(), 1u);
  EXPECT_EQ(t.seeds[0].starts.front().source, diffdope::SeedSource::kRequest);
  ASSERT_EQ(t.known.size(), 1u);
  EXPECT_EQ(t.known[0].first, 1u);
  // Planning twice finds the same detection: only take_known_starts uses it up.
  EXPECT_EQ(plan_request_targets(scene.objects, c, {}, 10.0).known.size(), 1u);
  take_known_starts(scene.objects, t.known, 10.0, t.seeds);
  EXPECT_EQ(t.seeds.size(), 2u);
  EXPECT_TRUE(plan_request_targets(scene.objects, c, {}, 10.0).known.empty());
}

TEST(RefineTargets, MoreRequestPosesThanInstancesAreRefused) {
  Scene scene;
  RefineRequestNames r;
  r.pose_names = {"box", "box"};
  const CheckedRequest c = check_refine_request(scene.objects, r, diffdope::RefinerOptions());
  ASSERT_EQ(c.error, "");
  EXPECT_EQ(plan_request_targets(scene.objects, c, {{0, {at(0), at(0.3)}}}, 10.0).error,
            "object 'box' has 2 initial poses in the request but max_instances 1 in the objects config");
}
