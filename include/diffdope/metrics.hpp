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
/// The error of `estimate` as a twist about the model point `pivot_model` (RefineResult::covariance's
/// coordinates): v the pivot's displacement from the estimate to the truth (metres), w the rotation vector of
/// truth · estimate⁻¹ (radians), both along the camera's axes.
Vector6d pose_error_twist(const Pose& estimate, const Pose& truth, const Eigen::Vector3d& pivot_model);
/// How a covariance holds an error: its Mahalanobis distance squared (NaN when the covariance is not positive
/// definite), and whether every coordinate lies within two of its standard deviations.
struct CovarianceCheck {
  double mahalanobis2 = 0;
  bool within_two_sigma = false;
};
CovarianceCheck check_covariance(const Vector6d& error, const Eigen::Matrix<double, 6, 6>& covariance);
/// The Mahalanobis distance squared that holds 95 % of a six-dimensional Gaussian (chi-squared, 6 dof).
constexpr double kChiSquared6At95 = 12.5916;

/// Area under the curve of accuracy (fraction of errors <= threshold) for thresholds in [0, max_threshold],
/// scaled to [0, 100]. 50 mm as in the paper: auc(errors, 0.05).
double accuracy_auc(const std::vector<double>& errors, double max_threshold);

}  // namespace diffdope
