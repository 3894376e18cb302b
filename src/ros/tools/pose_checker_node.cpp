// pose_checker_node: the demo's judge. Prints, per refined object and frame, the initial (detector / track)
// and refined errors against the bag's ground truth, then a summary once the refiner has been quiet for
// ~idle_timeout seconds (wall time: the bag's clock stops when it ends), and exits (0 = every object refined
// and every refined pose within ~max_translation / ~max_rotation_deg, or ~max_rotation_deg_by_object[name]).
#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <boost/bind/bind.hpp>
#include <cmath>
#include <cstdio>

#include "diffdope/object_config.hpp"
#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/pose_checker.hpp"

namespace {

struct CheckerNode {
  std::unique_ptr<diffdope_ros::PoseChecker> checker;
  std::vector<std::string> objects;
  std::map<std::string, diffdope::Pose> model_transform;
  std::map<std::string, bool> symmetric;
  std::vector<std::string> detection_topics;
  // The detector's own error, for comparison: its poses (any frame) and the ground truth by stamp.
  std::vector<std::pair<std::string, geometry_msgs::PoseStamped>> detections;
  std::map<std::pair<int64_t, std::string>, geometry_msgs::PoseStamped> truth;
  tf2_ros::Buffer tf{ros::Duration(600)};

  void onDetection(const geometry_msgs::PoseStampedConstPtr& m, const std::string& name) {
    detections.emplace_back(name, *m);
  }
  ros::WallTime last_refined, started = ros::WallTime::now();
  double idle_timeout = 5, start_timeout = 60;
  int exit_code = -1;

  // Refined frames (one RefinedPoseArray each) against the bag time the ground truth spans.
  int refined_frames = 0;
  double first_truth = 0, last_truth = 0;

  void onTruth(const diffdope_ros::InitialPoseArrayConstPtr& m) {
    checker->addGroundTruth(*m);
    if (!m->poses.empty()) {
      const double t = m->poses.front().pose.header.stamp.toSec();
      if (first_truth == 0 || t < first_truth) first_truth = t;
      last_truth = std::max(last_truth, t);
    }
    for (const auto& p : m->poses) truth[{int64_t(p.pose.header.stamp.toNSec()), p.name}] = p.pose;
  }
  /// Mean detector error per object (translation m, rotation rad) over detections with ground truth.
  std::map<std::string, std::pair<double, double>> detectorErrors(std::map<std::string, int>* counts) {
    std::map<std::string, std::pair<double, double>> sum;
    for (const auto& [name, d] : detections) {
      auto it = truth.find({int64_t(d.header.stamp.toNSec()), name});
      if (it == truth.end()) continue;
      try {
        const auto t = tf.lookupTransform(it->second.header.frame_id, d.header.frame_id, d.header.stamp);
        const diffdope::Pose cam_from_det = diffdope_ros::pose_from_transform(t.transform, "tf");
        const diffdope::Pose mesh = cam_from_det * diffdope_ros::pose_from_msg(d.pose, "detection") *
                                    model_transform[name];
        const auto e = diffdope_ros::pose_error(mesh, diffdope_ros::pose_from_msg(it->second.pose, "truth"),
                                                symmetric[name]);
        sum[name].first += e.translation_m;
        sum[name].second += e.rotation_rad;
        ++(*counts)[name];
      } catch (const std::exception&) {  // no TF for that detection: not scored
      }
    }
    for (auto& [name, v] : sum) v.first /= (*counts)[name], v.second /= (*counts)[name];
    return sum;
  }
  void onRefined(const diffdope_ros::RefinedPoseArrayConstPtr& m) {
    if (last_refined.isZero())
      std::printf("Per refined object: its start (detector, track, or prediction = track extrapolated) and the\n"
                  "start's and the refined pose's error against ground truth.\n");
    last_refined = ros::WallTime::now();
    ++refined_frames;
    for (const auto& row : checker->addRefined(*m)) std::printf("%s\n", diffdope_ros::PoseChecker::formatRow(row).c_str());
    std::fflush(stdout);
  }
  void onTimer(const ros::WallTimerEvent&) {
    const ros::WallTime now = ros::WallTime::now();
    if (last_refined.isZero() ? (now - started).toSec() < start_timeout : (now - last_refined).toSec() < idle_timeout)
      return;
    const auto summary = checker->summary();
    std::map<std::string, int> det_counts;
    const auto det = detectorErrors(&det_counts);
    bool pass = !checker->rows().empty();
    std::printf("\n%-8s %6s %8s %22s %22s %10s\n", "object", "frames", "within", "start mean mm / deg",
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
    for (const auto& name : objects)
      if (det.count(name))
        std::printf("%-8s detector alone: %.1f mm / %.1f deg mean over %d detections\n", name.c_str(),
                    1e3 * det.at(name).first, det.at(name).second * 180 / M_PI, det_counts[name]);
    if (last_truth > first_truth)
      std::printf("refined frames per second: %.1f (%d frames refined over %.1f s of bag time)\n",
                  refined_frames / (last_truth - first_truth), refined_frames, last_truth - first_truth);
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
      node.model_transform[o.name] = o.model_transform;
      node.detection_topics.push_back(o.pose_topic.empty() ? pnh.param<std::string>("detection_topic_prefix",
                                                                                    "/dope/pose_") + o.name
                                                           : o.pose_topic);
    }
    node.symmetric = symmetric;
  } catch (const std::exception& e) {
    ROS_FATAL("pose_checker: %s", e.what());
    return 2;
  }
  node.checker = diffdope_ros::PoseChecker::fromParams(pnh, symmetric);
  node.idle_timeout = pnh.param("idle_timeout", 5.0);
  node.start_timeout = pnh.param("start_timeout", 120.0);
  auto truth_sub = nh.subscribe("ground_truth", 100, &CheckerNode::onTruth, &node);
  auto refined_sub = nh.subscribe("refined_poses", 100, &CheckerNode::onRefined, &node);
  auto timer = nh.createWallTimer(ros::WallDuration(0.5), &CheckerNode::onTimer, &node);
  tf2_ros::TransformListener tf_listener(node.tf);
  std::vector<ros::Subscriber> detection_subs;
  for (size_t i = 0; i < node.objects.size(); ++i)
    detection_subs.push_back(nh.subscribe<geometry_msgs::PoseStamped>(
        node.detection_topics[i], 50,
        boost::bind(&CheckerNode::onDetection, &node, boost::placeholders::_1, node.objects[i])));
  ros::spin();
  return node.exit_code < 0 ? 1 : node.exit_code;
}
