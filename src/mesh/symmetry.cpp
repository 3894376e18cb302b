// Declared object symmetries (symmetry.hpp).
#include "diffdope/symmetry.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace diffdope {

void ObjectSymmetry::validate_and_normalise(const std::string& origin) {
  const auto fail = [&](const std::string& what) { throw std::invalid_argument(origin + ": " + what); };
  if (continuous.size() > kMaxContinuous)
    fail(std::to_string(continuous.size()) + " continuous symmetries; at most " + std::to_string(kMaxContinuous));
  if (discrete.size() > kMaxDiscrete)
    fail(std::to_string(discrete.size()) + " discrete symmetries; at most " + std::to_string(kMaxDiscrete));
  for (size_t i = 0; i < continuous.size(); ++i) {
    Axis& a = continuous[i];
    const double n = a.direction.norm();
    if (!a.direction.allFinite() || !a.offset.allFinite() || !(n > 1e-9))
      fail("continuous symmetry " + std::to_string(i) + ": the axis must be finite and non-zero, the offset finite");
    a.direction /= n;
  }
  for (size_t i = 0; i < discrete.size(); ++i)
    if (!discrete[i].is_valid(1e-3))
      fail("discrete symmetry " + std::to_string(i) +
           ": not a rigid transform (finite values, orthonormal rotation with determinant +1)");
}

namespace {

/// Rotation by `angle` about the line through `offset` along `direction` (model frame).
Pose rotation_about(const ObjectSymmetry::Axis& a, double angle) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, a.direction).toRotationMatrix();
  return Pose(R, a.offset - R * a.offset);
}

/// The angle about `a` that brings R * Rot(a, angle) nearest to `reference`: maximises
/// trace(refᵀ R Rot) = A cos + B sin + const (Rodrigues).
double best_angle(const Eigen::Matrix3d& R, const Eigen::Vector3d& a, const Eigen::Matrix3d& reference) {
  const Eigen::Matrix3d M = reference.transpose() * R;
  Eigen::Matrix3d K;
  K << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  const double A = M.trace() - a.dot(M * a), B = (M * K).trace();
  return std::atan2(B, A);
}

}  // namespace

Pose ObjectSymmetry::nearest_equivalent(const Pose& pose, const Eigen::Matrix3d& reference) const {
  if (empty()) return pose;
  Pose best = pose;
  double best_angle_to_ref = rotation_angle(pose.R, reference);
  std::vector<Pose> starts{pose};
  for (const Pose& d : discrete) starts.push_back(pose * d);
  for (Pose p : starts) {
    // Several continuous axes (a sphere) are settled by alternating over them; one axis takes one pass.
    for (int pass = 0; pass < (continuous.size() > 1 ? 4 : 1); ++pass)
      for (const Axis& a : continuous) p = p * rotation_about(a, best_angle(p.R, a.direction, reference));
    p.orthonormalize();
    const double angle = rotation_angle(p.R, reference);
    if (angle < best_angle_to_ref - 1e-9) {
      best = p;
      best_angle_to_ref = angle;
    }
  }
  return best;
}

bool ObjectSymmetry::contains(const Pose& m, double angle_tol, double distance_tol, double radius) const {
  if (empty()) return false;
  // m is a symmetry when some declared element S makes S⁻¹ m the identity: the nearest equivalent of m to the
  // identity rotation is (about) the identity transform.
  const Pose e = nearest_equivalent(m, Eigen::Matrix3d::Identity());
  const double angle = rotation_angle(e.R, Eigen::Matrix3d::Identity());
  return angle <= angle_tol && e.t.norm() + angle * radius <= distance_tol + angle_tol * radius;
}

std::vector<Eigen::Matrix<double, 6, 1>> ObjectSymmetry::free_twists(const Pose& pose,
                                                                     const Eigen::Vector3d& pivot) const {
  std::vector<Eigen::Matrix<double, 6, 1>> out;
  for (const Axis& a : continuous) {
    // Rotation about the line through q along d: a point moves by w x (x - q) = v + w x (x - pivot) with
    // v = w x (pivot - q).
    const Eigen::Vector3d d = pose.R * a.direction, q = pose * a.offset;
    Eigen::Matrix<double, 6, 1> twist;
    twist.head<3>() = d.cross(pivot - q);
    twist.tail<3>() = d;
    out.push_back(twist);
  }
  return out;
}

}  // namespace diffdope
