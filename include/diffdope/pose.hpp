#pragma once
// Rigid pose of a model in the camera frame: X_cam = R * X_model + t. Units: metres, radians.
// The optimised parameters are a 6-D update delta = (rho, phi): rho translation (m), phi rotation vector
// (rad), both in camera axes, applied on the left: T' = exp(delta) * T.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>

namespace diffdope {

using Vector6d = Eigen::Matrix<double, 6, 1>;

struct Pose {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();  // metres

  Pose() = default;
  Pose(const Eigen::Matrix3d& R_, const Eigen::Vector3d& t_) : R(R_), t(t_) {}

  /// From a quaternion (x, y, z, w order as in ROS messages; normalised here) and a translation.
  static Pose from_quaternion(double x, double y, double z, double w, const Eigen::Vector3d& t);
  /// From 9 row-major rotation entries (BOP's cam_R_m2c layout) and a translation.
  static Pose from_rotation_rowmajor(const std::array<double, 9>& r, const Eigen::Vector3d& t);
  /// From a 4x4 homogeneous matrix.
  static Pose from_matrix(const Eigen::Matrix4d& T);

  /// Quaternion as (x, y, z, w).
  std::array<double, 4> quaternion_xyzw() const;
  std::array<double, 9> rotation_rowmajor() const;
  Eigen::Matrix4d matrix() const;

  Pose inverse() const;
  Pose operator*(const Pose& o) const { return Pose(R * o.R, R * o.t + t); }
  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return R * p + t; }

  /// exp(delta) * this, with the exact SE(3) exponential.
  Pose updated(const Vector6d& delta) const;
  /// True when every entry is finite and R is a rotation (orthonormal, det +1) within `tol`.
  bool is_valid(double tol = 1e-6) const;
  /// Projects R to the nearest rotation (keeps long optimisations from drifting off SO(3)).
  void orthonormalize();
};

/// SE(3) exponential of delta = (rho, phi).
Pose se3_exp(const Vector6d& delta);
/// The cross-product matrix: skew(r) x = r x x.
Eigen::Matrix3d skew(const Eigen::Vector3d& r);
/// Rotation vector -> matrix (Rodrigues).
Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi);
/// Rotation angle between two rotations, radians.
double rotation_angle(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B);

}  // namespace diffdope
