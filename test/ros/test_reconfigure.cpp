// rostest (reconfigure.test): runtime tuning through dynamic_reconfigure while a bag plays. The values at start
// are the node's own (the objects YAML, then ~parameters), a change reaches the next frames (iterations and
// runs of every published result), a value clamped to its range's bound is said and iterations 0 is never
// plausible, mode on_request stops streaming and tracking resumes it, and a set of values the options' checks
// refuse (lr_low > lr_high) is reverted as a whole while the node keeps refining.
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>

#include <mutex>

#include "diffdope_ros/RefinedPoseArray.h"

namespace {

const char* kService = "/diffdope_refiner/set_parameters";

struct Received {
  ros::WallTime at;
  std::vector<int> iterations;  // of every result
  std::vector<bool> plausible;
  std::vector<int> verdicts;
  std::vector<std::string> errors;
};

struct World {
  std::mutex mutex;
  std::vector<Received> arrays;
  void onRefined(const diffdope_ros::RefinedPoseArrayConstPtr& m) {
    Received r{ros::WallTime::now(), {}};
    for (const auto& p : m->poses) {
      r.iterations.push_back(p.iterations);
      r.plausible.push_back(p.plausible);
      r.verdicts.push_back(p.verdict);
      r.errors.push_back(p.error);
    }
    std::lock_guard<std::mutex> l(mutex);
    arrays.push_back(r);
  }
  int refusals_logged = 0;
  std::vector<std::string> warnings;
  void onLog(const rosgraph_msgs::LogConstPtr& m) {
    std::lock_guard<std::mutex> l(mutex);
    if (m->level == rosgraph_msgs::Log::WARN) warnings.push_back(m->msg);
    if (m->level < rosgraph_msgs::Log::ERROR || m->msg.find("reconfigure refused") == std::string::npos) return;
    ++refusals_logged;
  }
  bool warned(const std::string& needle) {
    std::lock_guard<std::mutex> l(mutex);
    for (const auto& w : warnings)
      if (w.find(needle) != std::string::npos) return true;
    return false;
  }
  int refusals() {
    std::lock_guard<std::mutex> l(mutex);
    return refusals_logged;
  }
  std::vector<Received> since(ros::WallTime t) {
    std::lock_guard<std::mutex> l(mutex);
    std::vector<Received> out;
    for (const auto& r : arrays)
      if (r.at > t) out.push_back(r);
    return out;
  }
};
World* world = nullptr;

dynamic_reconfigure::Config set(const dynamic_reconfigure::Config& change) {
  dynamic_reconfigure::Reconfigure srv;
  srv.request.config = change;
  EXPECT_TRUE(ros::service::call(kService, srv)) << kService << " failed";
  return srv.response.config;
}
template <typename T, typename V>
void add(std::vector<T>& list, const std::string& name, V value) {
  T p;
  p.name = name;
  p.value = value;
  list.push_back(p);
}
int intValue(const dynamic_reconfigure::Config& c, const std::string& name) {
  for (const auto& p : c.ints)
    if (p.name == name) return p.value;
  ADD_FAILURE() << "no int parameter " << name;
  return -1;
}
double doubleValue(const dynamic_reconfigure::Config& c, const std::string& name) {
  for (const auto& p : c.doubles)
    if (p.name == name) return p.value;
  ADD_FAILURE() << "no double parameter " << name;
  return -1;
}
std::string strValue(const dynamic_reconfigure::Config& c, const std::string& name) {
  for (const auto& p : c.strs)
    if (p.name == name) return p.value;
  ADD_FAILURE() << "no string parameter " << name;
  return "";
}

/// Waits until `n` arrays arrived after `t` (false after `timeout` seconds).
bool waitForArrays(ros::WallTime t, size_t n, double timeout) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout);
  while (ros::WallTime::now() < end) {
    if (world->since(t).size() >= n) return true;
    ros::WallDuration(0.05).sleep();
  }
  return false;
}

}  // namespace

TEST(Reconfigure, ChangesTakeEffectAtTheNextFramesAndBadSetsAreReverted) {
  ASSERT_TRUE(ros::service::waitForService(kService, ros::Duration(30))) << kService << " never appeared";
  // An empty request returns the values in force: the YAML's runs and iterations, the launch file's image scale
  // and extrapolation.
  const dynamic_reconfigure::Config start = set(dynamic_reconfigure::Config());
  EXPECT_EQ(intValue(start, "iterations"), 40);
  EXPECT_EQ(intValue(start, "batch_size"), 16);
  EXPECT_NEAR(doubleValue(start, "image_scale"), 0.45, 1e-9);
  EXPECT_NEAR(doubleValue(start, "max_extrapolation"), 1.5, 1e-9);  // a track option, read with the others
  EXPECT_NEAR(doubleValue(start, "shape_tolerance"), 0.02, 1e-9);   // set by its deprecated name
  EXPECT_EQ(strValue(start, "mode"), "tracking");
  ASSERT_TRUE(waitForArrays(ros::WallTime(), 3, 60)) << "the refiner never streamed";
  // 40: the detection budget; 10: the tracking budget (~track_iterations) of frames on steady tracks.
  for (const auto& r : world->since(ros::WallTime()))
    for (int it : r.iterations) EXPECT_TRUE(it == 40 || it == 10) << it;

  // Fewer, shorter runs: every result after the one in flight has 12 iterations, or the tracking budget's 10.
  dynamic_reconfigure::Config change;
  add(change.ints, "iterations", 12);
  add(change.ints, "batch_size", 6);
  const dynamic_reconfigure::Config fast = set(change);
  EXPECT_EQ(intValue(fast, "iterations"), 12);
  EXPECT_EQ(intValue(fast, "batch_size"), 6);
  const ros::WallTime changed = ros::WallTime::now();
  ASSERT_TRUE(waitForArrays(changed, 5, 60)) << "no frames refined after the change";
  const auto after = world->since(changed);
  int with_results = 0;
  // The first two may have been refined before the change: the one in flight, and one published just before
  // set() returned but handled here after `changed`.
  for (size_t i = 2; i < after.size(); ++i) {
    for (int it : after[i].iterations) EXPECT_TRUE(it == 12 || it == 10) << it;
    with_results += !after[i].iterations.empty();
  }
  EXPECT_GT(with_results, 0) << "no results to check after the change";

  // A set the options' checks refuse is reverted whole: the iterations in it do not apply either.
  dynamic_reconfigure::Config bad;
  add(bad.doubles, "lr_low", 0.5);
  add(bad.doubles, "lr_high", 0.1);
  add(bad.ints, "iterations", 25);
  const dynamic_reconfigure::Config reverted = set(bad);
  EXPECT_NEAR(doubleValue(reverted, "lr_low"), doubleValue(start, "lr_low"), 1e-12);
  EXPECT_NEAR(doubleValue(reverted, "lr_high"), doubleValue(start, "lr_high"), 1e-12);
  EXPECT_EQ(intValue(reverted, "iterations"), 12);
  const ros::WallTime refused = ros::WallTime::now();
  ASSERT_TRUE(waitForArrays(refused, 3, 60)) << "the node stopped refining after a refused set";
  const auto still = world->since(refused);
  for (size_t i = 1; i < still.size(); ++i)
    for (int it : still[i].iterations) EXPECT_TRUE(it == 12 || it == 10) << it;

  // A smaller tracking budget: frames on steady tracks take it, the others keep the 12 iterations.
  dynamic_reconfigure::Config tracked;
  add(tracked.ints, "track_iterations", 5);
  EXPECT_EQ(intValue(set(tracked), "track_iterations"), 5);
  const ros::WallTime retracked = ros::WallTime::now();
  ASSERT_TRUE(waitForArrays(retracked, 6, 60)) << "no frames refined after the tracking budget changed";
  const auto budgets = world->since(retracked);
  int on_track_budget = 0;
  for (size_t i = 1; i < budgets.size(); ++i)
    for (int it : budgets[i].iterations) {
      EXPECT_TRUE(it == 12 || it == 5) << it;
      on_track_budget += it == 5;
    }
  EXPECT_GT(on_track_budget, 0) << "no frame refined on the tracking budget";

  // iterations -5: the server clamps it to 0 before the node sees it. The node says that the value sits at its
  // range's bound, and never calls an unrefined start plausible.
  dynamic_reconfigure::Config none;
  add(none.ints, "iterations", -5);
  EXPECT_EQ(intValue(set(none), "iterations"), 0);
  for (int i = 0; i < 100 && !world->warned("iterations 0 (range 0 to 10000)"); ++i) ros::WallDuration(0.05).sleep();
  EXPECT_TRUE(world->warned("iterations 0 (range 0 to 10000)")) << "a clamped value was not said";
  const ros::WallTime unrefined = ros::WallTime::now();
  ASSERT_TRUE(waitForArrays(unrefined, 4, 60)) << "no frames refined with iterations 0";
  const auto zero = world->since(unrefined);
  int unrefined_results = 0;
  std::string seen;
  for (size_t i = 1; i < zero.size(); ++i)
    for (size_t k = 0; k < zero[i].iterations.size(); ++k) {
      seen += " " + std::to_string(zero[i].iterations[k]) + (zero[i].plausible[k] ? "+" : "-");
      if (zero[i].iterations[k] != 0) continue;
      EXPECT_FALSE(zero[i].plausible[k]);
      EXPECT_EQ(zero[i].verdicts[k], diffdope_ros::RefinedPose::UNDETERMINED);
      EXPECT_NE(zero[i].errors[k].find("iterations 0"), std::string::npos) << zero[i].errors[k];
      ++unrefined_results;
    }
  EXPECT_GT(unrefined_results, 0) << "iterations (+ plausible) of the results:" << seen;
  dynamic_reconfigure::Config again;
  add(again.ints, "iterations", 12);
  EXPECT_EQ(intValue(set(again), "iterations"), 12);

  // on_request: streaming stops (one refinement may be in flight); tracking: it resumes.
  dynamic_reconfigure::Config stop;
  add(stop.strs, "mode", std::string("on_request"));
  EXPECT_EQ(strValue(set(stop), "mode"), "on_request");
  ros::WallDuration(1.5).sleep();
  const ros::WallTime quiet = ros::WallTime::now();
  ros::WallDuration(3.0).sleep();
  EXPECT_EQ(world->since(quiet).size(), 0u) << "still streaming in on_request mode";
  dynamic_reconfigure::Config resume;
  add(resume.strs, "mode", std::string("tracking"));
  set(resume);
  EXPECT_TRUE(waitForArrays(ros::WallTime::now(), 2, 60)) << "streaming did not resume in tracking mode";

  // A mode that does not exist is refused.
  dynamic_reconfigure::Config unknown;
  add(unknown.strs, "mode", std::string("sometimes"));
  EXPECT_EQ(strValue(set(unknown), "mode"), "tracking");

  // Each refusal is logged, even two within the node's error throttle: each answers a request just made.
  const int logged = world->refusals();
  set(bad);
  set(unknown);
  for (int i = 0; i < 100 && world->refusals() < logged + 2; ++i) ros::WallDuration(0.05).sleep();
  EXPECT_EQ(world->refusals(), logged + 2);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_reconfigure");
  ros::NodeHandle nh;
  World w;
  world = &w;
  ros::Subscriber sub = nh.subscribe("/diffdope_refiner/refined_poses", 50, &World::onRefined, &w);
  ros::Subscriber log = nh.subscribe("/rosout", 100, &World::onLog, &w);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
