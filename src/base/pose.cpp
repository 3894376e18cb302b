#include "diffdope/pose.hpp"

#include <Eigen/SVD>
#include <cmath>

namespace diffdope {

Eigen::Matrix3d skew(const Eigen::Vector3d& r) {
  Eigen::Matrix3d S;
  S << 0, -r.z(), r.y(), r.z(), 0, -r.x(), -r.y(), r.x(), 0;
  return S;
}

Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  if (angle < 1e-12) {  // first order; the error is O(angle^2) < 1e-24
    Eigen::Matrix3d R;
    R << 1, -phi.z(), phi.y(), phi.z(), 1, -phi.x(), -phi.y(), phi.x(), 1;
    return R;
  }
  return Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix();
}

Pose se3_exp(const Vector6d& delta) {
  const Eigen::Vector3d rho = delta.head<3>(), phi = delta.tail<3>();
  const double th = phi.norm();
  Eigen::Matrix3d W;
  W << 0, -phi.z(), phi.y(), phi.z(), 0, -phi.x(), -phi.y(), phi.x(), 0;
  Eigen::Matrix3d V = Eigen::Matrix3d::Identity();
  if (th < 1e-8) {
    V += 0.5 * W;  // series: I + W/2 + W^2/6 + ...
  } else {
    V += (1 - std::cos(th)) / (th * th) * W + (th - std::sin(th)) / (th * th * th) * W * W;
  }
  return Pose(so3_exp(phi), V * rho);
}

double rotation_angle(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  const double c = 0.5 * ((A.transpose() * B).trace() - 1.0);
  return std::acos(std::max(-1.0, std::min(1.0, c)));
}

Pose Pose::from_quaternion(double x, double y, double z, double w, const Eigen::Vector3d& t) {
  Eigen::Quaterniond q(w, x, y, z);
  q.normalize();
  return Pose(q.toRotationMatrix(), t);
}

Pose Pose::from_rotation_rowmajor(const std::array<double, 9>& r, const Eigen::Vector3d& t) {
  Eigen::Matrix3d R;
  R << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
  return Pose(R, t);
}

Pose Pose::from_matrix(const Eigen::Matrix4d& T) { return Pose(T.topLeftCorner<3, 3>(), T.topRightCorner<3, 1>()); }

std::array<double, 4> Pose::quaternion_xyzw() const {
  Eigen::Quaterniond q(R);
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1;  // canonical hemisphere
  return {q.x(), q.y(), q.z(), q.w()};
}

std::array<double, 9> Pose::rotation_rowmajor() const {
  return {R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2)};
}

Eigen::Matrix4d Pose::matrix() const {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = t;
  return T;
}

Pose Pose::inverse() const { return Pose(R.transpose(), -R.transpose() * t); }

Pose Pose::updated(const Vector6d& delta) const { return se3_exp(delta) * (*this); }

bool Pose::is_valid(double tol) const {
  if (!R.allFinite() || !t.allFinite()) return false;
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > tol) return false;
  return std::abs(R.determinant() - 1.0) <= tol;
}

void Pose::orthonormalize() {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1;
  R = U * svd.matrixV().transpose();
}

}  // namespace diffdope
