#include "diffdope/metrics.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

namespace diffdope {

std::vector<Eigen::Vector3d> metric_points(const Mesh& mesh, size_t max_points) {
  std::set<std::tuple<float, float, float>> seen;
  std::vector<Eigen::Vector3d> unique;
  for (const auto& p : mesh.positions)
    if (seen.emplace(p.x, p.y, p.z).second) unique.emplace_back(p.x, p.y, p.z);
  if (unique.size() <= max_points) return unique;
  std::vector<Eigen::Vector3d> out;
  const double stride = double(unique.size()) / max_points;
  for (size_t i = 0; i < max_points; ++i) out.push_back(unique[size_t(i * stride)]);
  return out;
}

double add_error(const std::vector<Eigen::Vector3d>& pts, const Pose& est, const Pose& truth) {
  if (pts.empty()) return 0;
  double sum = 0;
  for (const auto& p : pts) sum += ((est * p) - (truth * p)).norm();
  return sum / pts.size();
}

double adds_error(const std::vector<Eigen::Vector3d>& pts, const Pose& est, const Pose& truth) {
  if (pts.empty()) return 0;
  std::vector<Eigen::Vector3d> gt(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) gt[i] = truth * pts[i];
  double sum = 0;
  for (const auto& p : pts) {
    const Eigen::Vector3d e = est * p;
    double best = std::numeric_limits<double>::infinity();
    for (const auto& g : gt) best = std::min(best, (e - g).squaredNorm());
    sum += std::sqrt(best);
  }
  return sum / pts.size();
}

double accuracy_auc(const std::vector<double>& errors, double max_threshold) {
  if (errors.empty()) return 0;
  // Exact integral of the step function acc(t) = #(e <= t)/n over [0, T], divided by T.
  double area = 0;
  for (double e : errors) area += std::max(0.0, max_threshold - std::max(0.0, e));
  return 100.0 * area / (max_threshold * errors.size());
}

Vector6d pose_error_twist(const Pose& estimate, const Pose& truth, const Eigen::Vector3d& pivot_model) {
  Vector6d e;
  e.head<3>() = truth * pivot_model - estimate * pivot_model;
  const Eigen::AngleAxisd turn(truth.R * estimate.R.transpose());
  e.tail<3>() = turn.angle() * turn.axis();
  return e;
}

CovarianceCheck check_covariance(const Vector6d& error, const Eigen::Matrix<double, 6, 6>& covariance) {
  CovarianceCheck out;
  const Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(covariance);
  if (llt.info() != Eigen::Success || !(covariance.diagonal().minCoeff() > 0)) {
    out.mahalanobis2 = std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  out.mahalanobis2 = error.dot(llt.solve(error));
  out.within_two_sigma = true;
  for (int i = 0; i < 6; ++i)
    out.within_two_sigma = out.within_two_sigma && std::abs(error[i]) <= 2 * std::sqrt(covariance(i, i));
  return out;
}

}  // namespace diffdope
