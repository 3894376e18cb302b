// pose_checker_node: the demo's judge. Prints, per refined object and frame, the initial (detector / track)
// and refined errors against the bag's ground truth, then a summary once the refiner has been quiet for
// ~idle_timeout seconds (wall time: the bag's clock stops when it ends), and exits (0 = every object refined
// and every refined pose within ~max_translation / ~max_rotation_deg).
#include <ros/ros.h>

#include <cmath>
#include <cstdio>

#include "diffdope/object_config.hpp"
#include "diffdope_ros/pose_checker.hpp"

namespace {

struct CheckerNode {
  std::unique_ptr<diffdope_ros::PoseChecker> checker;
  std::vector<std::string> objects;
  ros::WallTime last_refined, started = ros::WallTime::now();
  double idle_timeout = 5, start_timeout = 60;
  int exit_code = -1;

  void onTruth(const diffdope_ros::InitialPoseArrayConstPtr& m) { checker->addGroundTruth(*m); }
  void onRefined(const diffdope_ros::RefinedPoseArrayConstPtr& m) {
    last_refined = ros::WallTime::now();
    for (const auto& row : checker->addRefined(*m)) std::printf("%s\n", diffdope_ros::PoseChecker::formatRow(row).c_str());
    std::fflush(stdout);
  }
  void onTimer(const ros::WallTimerEvent&) {
    const ros::WallTime now = ros::WallTime::now();
    if (last_refined.isZero() ? (now - started).toSec() < start_timeout : (now - last_refined).toSec() < idle_timeout)
      return;
    const auto summary = checker->summary();
    bool pass = !checker->rows().empty();
    std::printf("\n%-8s %6s %8s %22s %22s %10s\n", "object", "frames", "within", "initial mean mm / deg",
                "refined mean mm / deg", "max mm/deg");
    for (const auto& name : objects) {
      auto it = summary.find(name);
      if (it == summary.end()) {
        std::printf("%-8s %6d  (no refined pose)\n", name.c_str(), 0);
        pass = false;
        continue;
      }
      const auto& o = it->second;
      std::printf("%-8s %6d %7d%% %12.1f / %5.1f %14.1f / %5.2f %5.1f/%4.1f\n", name.c_str(), o.count,
                  int(std::round(100.0 * o.within / o.count)), 1e3 * o.mean_initial_translation_m,
                  o.mean_initial_rotation_rad * 180 / M_PI, 1e3 * o.mean_translation_m,
                  o.mean_rotation_rad * 180 / M_PI, 1e3 * o.max_translation_m, o.max_rotation_rad * 180 / M_PI);
      pass = pass && o.within == o.count;
    }
    double latency = 0;
    for (const auto& r : checker->rows()) latency += r.latency;
    if (!checker->rows().empty())
      std::printf("mean latency (image stamp to publish): %.0f ms over %zu refined poses\n",
                  1e3 * latency / checker->rows().size(), checker->rows().size());
    std::printf("%s\n", pass ? "PASS: every object refined within tolerance" : "FAIL: see the table above");
    std::fflush(stdout);
    exit_code = pass ? 0 : 1;
    ros::shutdown();
  }
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "pose_checker");
  ros::NodeHandle nh, pnh("~");
  CheckerNode node;
  std::map<std::string, bool> symmetric;
  try {
    const auto cfg = diffdope::load_objects_config(pnh.param<std::string>("objects_config", ""));
    for (const auto& o : cfg.objects) {
      node.objects.push_back(o.name);
      symmetric[o.name] = o.symmetric;
    }
  } catch (const std::exception& e) {
    ROS_FATAL("pose_checker: %s", e.what());
    return 2;
  }
  node.checker = std::make_unique<diffdope_ros::PoseChecker>(
      pnh.param("max_translation", 0.005), pnh.param("max_rotation_deg", 2.0) * M_PI / 180, symmetric);
  node.idle_timeout = pnh.param("idle_timeout", 5.0);
  node.start_timeout = pnh.param("start_timeout", 120.0);
  auto truth_sub = nh.subscribe("ground_truth", 100, &CheckerNode::onTruth, &node);
  auto refined_sub = nh.subscribe("refined_poses", 100, &CheckerNode::onRefined, &node);
  auto timer = nh.createWallTimer(ros::WallDuration(0.5), &CheckerNode::onTimer, &node);
  ros::spin();
  return node.exit_code < 0 ? 1 : node.exit_code;
}
