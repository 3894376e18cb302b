#include "diffdope_ros/pose_checker.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {

std::unique_ptr<PoseChecker> PoseChecker::fromParams(const ros::NodeHandle& pnh,
                                                     std::map<std::string, bool> symmetric) {
  std::map<std::string, double> by_object;
  pnh.getParam("max_rotation_deg_by_object", by_object);
  for (auto& [name, deg] : by_object) deg *= M_PI / 180;
  return std::make_unique<PoseChecker>(pnh.param("max_translation", 0.005),
                                       pnh.param("max_rotation_deg", 2.0) * M_PI / 180, std::move(symmetric),
                                       std::move(by_object));
}

PoseError pose_error(const diffdope::Pose& estimate, const diffdope::Pose& truth, bool symmetric) {
  PoseError e;
  e.translation_m = (estimate.t - truth.t).norm();
  if (symmetric) {
    const double c = std::clamp(estimate.R.col(2).dot(truth.R.col(2)), -1.0, 1.0);
    e.rotation_rad = std::acos(c);
  } else {
    e.rotation_rad = diffdope::rotation_angle(estimate.R, truth.R);
  }
  return e;
}

void PoseChecker::addGroundTruth(const InitialPoseArray& truth) {
  for (const auto& p : truth.poses)
    truth_[{int64_t(p.pose.header.stamp.toNSec()), p.name}] = pose_from_msg(p.pose.pose, "ground truth " + p.name);
}

std::vector<PoseChecker::Row> PoseChecker::addRefined(const RefinedPoseArray& refined) {
  std::vector<Row> out;
  for (const auto& p : refined.poses) {
    auto it = truth_.find({int64_t(p.pose.header.stamp.toNSec()), p.name});
    if (it == truth_.end()) {
      ++unmatched_;
      continue;
    }
    const bool sym = symmetric_.count(p.name) && symmetric_.at(p.name);
    Row r;
    r.stamp = p.pose.header.stamp.toSec();
    r.name = p.name;
    r.source = p.source;
    r.refined = pose_error(pose_from_msg(p.pose.pose, "refined " + p.name), it->second, sym);
    r.initial = pose_error(pose_from_msg(p.initial_pose, "initial " + p.name), it->second, sym);
    r.plausible = p.plausible;
    r.mask_iou = p.mask_iou;
    r.depth_inliers = p.depth_inliers;
    r.time_ms = p.time_ms;
    r.latency = refined.latency;
    rows_.push_back(r);
    out.push_back(r);
  }
  return out;
}

std::map<std::string, PoseChecker::ObjectSummary> PoseChecker::summary() const {
  std::map<std::string, ObjectSummary> s;
  for (const Row& r : rows_) {
    ObjectSummary& o = s[r.name];
    ++o.count;
    o.within += within(r);
    o.plausible += r.plausible;
    o.max_translation_m = std::max(o.max_translation_m, r.refined.translation_m);
    o.max_rotation_rad = std::max(o.max_rotation_rad, r.refined.rotation_rad);
    o.mean_translation_m += r.refined.translation_m;
    o.mean_rotation_rad += r.refined.rotation_rad;
    o.mean_initial_translation_m += r.initial.translation_m;
    o.mean_initial_rotation_rad += r.initial.rotation_rad;
  }
  for (auto& [name, o] : s) {
    o.mean_translation_m /= o.count;
    o.mean_rotation_rad /= o.count;
    o.mean_initial_translation_m /= o.count;
    o.mean_initial_rotation_rad /= o.count;
  }
  return s;
}

std::string PoseChecker::formatRow(const Row& r) {
  char b[256];
  std::snprintf(b, sizeof b, "t=%.3f %-8s %-8s initial %6.1f mm %5.1f deg -> refined %5.1f mm %5.2f deg  iou %.2f  %s  %4.0f ms",
                r.stamp, r.name.c_str(), r.source.c_str(), 1e3 * r.initial.translation_m,
                r.initial.rotation_rad * 180 / M_PI, 1e3 * r.refined.translation_m, r.refined.rotation_rad * 180 / M_PI,
                r.mask_iou, r.plausible ? "ok" : "IMPLAUSIBLE", r.time_ms);
  return b;
}

}  // namespace diffdope_ros
