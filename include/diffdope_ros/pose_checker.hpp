#pragma once
// Scores refined poses against ground truth (the demo bag's /ground_truth): for the demo's per-frame printout
// and the rostests' accuracy checks. Matching is by object name and exact image stamp.
#include <map>
#include <string>
#include <vector>

#include <memory>
#include <ros/node_handle.h>

#include "diffdope/pose.hpp"
#include "diffdope_ros/InitialPoseArray.h"
#include "diffdope_ros/RefinedPoseArray.h"

namespace diffdope_ros {

struct PoseError {
  double translation_m = 0;  // distance between the origins
  double rotation_rad = 0;   // relative rotation angle; for symmetric objects the angle between their z axes
};

/// Error of `estimate` against `truth`. `symmetric`: rotation about the model z axis does not count.
PoseError pose_error(const diffdope::Pose& estimate, const diffdope::Pose& truth, bool symmetric);

class PoseChecker {
 public:
  struct Row {
    double stamp = 0;
    std::string name, source;
    PoseError initial, refined;
    bool plausible = false;
    double mask_iou = -1, depth_inliers = -1, time_ms = 0, latency = 0;
  };
  struct ObjectSummary {
    int count = 0, within = 0, plausible = 0;
    double max_translation_m = 0, max_rotation_rad = 0, mean_translation_m = 0, mean_rotation_rad = 0;
    double mean_initial_translation_m = 0, mean_initial_rotation_rad = 0;
  };

  /// `max_rotation_by_object` (radians) replaces max_rotation_rad for the objects it names.
  PoseChecker(double max_translation_m, double max_rotation_rad, std::map<std::string, bool> symmetric = {},
              std::map<std::string, double> max_rotation_by_object = {})
      : max_t_(max_translation_m), max_r_(max_rotation_rad), symmetric_(std::move(symmetric)),
        max_r_by_object_(std::move(max_rotation_by_object)) {}

  /// From the private parameters ~max_translation (m, 0.005), ~max_rotation_deg (2) and
  /// ~max_rotation_deg_by_object ({name: degrees}, for the objects it names).
  static std::unique_ptr<PoseChecker> fromParams(const ros::NodeHandle& pnh, std::map<std::string, bool> symmetric);

  void addGroundTruth(const InitialPoseArray& truth);
  /// Returns the rows this message could be matched with ground truth (also kept for summary()).
  std::vector<Row> addRefined(const RefinedPoseArray& refined);
  /// Refined poses without ground truth at their stamp so far.
  int unmatched() const { return unmatched_; }

  const std::vector<Row>& rows() const { return rows_; }
  std::map<std::string, ObjectSummary> summary() const;
  bool within(const Row& r) const {
    const auto it = max_r_by_object_.find(r.name);
    return r.refined.translation_m <= max_t_ && r.refined.rotation_rad <= (it == max_r_by_object_.end() ? max_r_ : it->second);
  }
  static std::string formatRow(const Row& r);

 private:
  double max_t_, max_r_;
  std::map<std::string, bool> symmetric_;
  std::map<std::string, double> max_r_by_object_;
  std::map<std::pair<int64_t, std::string>, diffdope::Pose> truth_;
  std::vector<Row> rows_;
  int unmatched_ = 0;
};

}  // namespace diffdope_ros
