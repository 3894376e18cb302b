#pragma once
// Pose error metrics as the pose community uses them (BOP toolkit definitions): ADD, ADD-S, and the area
// under the accuracy-threshold curve. Units: metres unless a name says otherwise.
#include <vector>

#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

/// Mean distance between the model's points under the estimated and the true pose.
double add_error(const std::vector<Eigen::Vector3d>& points, const Pose& estimate, const Pose& truth);
/// Mean distance from each point under the estimate to the closest point under the truth (symmetric objects).
double adds_error(const std::vector<Eigen::Vector3d>& points, const Pose& estimate, const Pose& truth);
/// Up to `max_points` of the mesh's vertices (evenly strided), duplicates at seams removed.
std::vector<Eigen::Vector3d> metric_points(const Mesh& mesh, size_t max_points = 2000);
/// Area under the curve of accuracy (fraction of errors <= threshold) for thresholds in [0, max_threshold],
/// scaled to [0, 100]. 50 mm as in the paper: auc(errors, 0.05).
double accuracy_auc(const std::vector<double>& errors, double max_threshold);

}  // namespace diffdope
