#include <gtest/gtest.h>

#include <cmath>

#include "diffdope/camera.hpp"
#include "diffdope/pose.hpp"

using namespace diffdope;

TEST(Pose, QuaternionRoundTrip) {
  const Pose p = Pose::from_quaternion(0.1, -0.4, 0.3, 0.8, Eigen::Vector3d(0.1, 0.2, 0.7));
  EXPECT_TRUE(p.is_valid());
  const auto q = p.quaternion_xyzw();
  const double n = std::sqrt(0.01 + 0.16 + 0.09 + 0.64);
  EXPECT_NEAR(q[0], 0.1 / n, 1e-12);
  EXPECT_NEAR(q[1], -0.4 / n, 1e-12);
  EXPECT_NEAR(q[2], 0.3 / n, 1e-12);
  EXPECT_NEAR(q[3], 0.8 / n, 1e-12);
}

TEST(Pose, RowMajorAndMatrix) {
  const Pose p = Pose::from_quaternion(0.3, 0.2, -0.1, 0.9, Eigen::Vector3d(1, 2, 3));
  const auto r = p.rotation_rowmajor();
  EXPECT_DOUBLE_EQ(r[1], p.R(0, 1));  // row-major: second entry is row 0, column 1
  EXPECT_DOUBLE_EQ(r[3], p.R(1, 0));
  const Pose q = Pose::from_rotation_rowmajor(r, p.t);
  EXPECT_LT((q.R - p.R).norm(), 1e-15);
  const Pose m = Pose::from_matrix(p.matrix());
  EXPECT_LT((m.R - p.R).norm() + (m.t - p.t).norm(), 1e-15);
  const Pose id = p * p.inverse();
  EXPECT_LT((id.R - Eigen::Matrix3d::Identity()).norm() + id.t.norm(), 1e-12);
}

TEST(Pose, ExpUpdateIsLeftMultiplied) {
  const Pose p = Pose::from_quaternion(0.3, 0.2, -0.1, 0.9, Eigen::Vector3d(0.1, -0.05, 0.6));
  Vector6d d;
  d << 0.01, -0.02, 0.03, 0.2, -0.1, 0.05;
  const Pose u = p.updated(d);
  EXPECT_TRUE(u.is_valid());
  const Pose expected = se3_exp(d) * p;
  EXPECT_LT((u.matrix() - expected.matrix()).norm(), 1e-14);
  // Pure rotation about the camera origin: rotates the translation too.
  Vector6d r = Vector6d::Zero();
  r[5] = M_PI / 2;
  const Pose rz = Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(1, 0, 0)).updated(r);
  EXPECT_NEAR(rz.t.x(), 0, 1e-12);
  EXPECT_NEAR(rz.t.y(), 1, 1e-12);
  // First order: X' = X + rho + phi x X.
  Vector6d s;
  s << 1e-7, 2e-7, -1e-7, 3e-7, -2e-7, 1e-7;
  const Eigen::Vector3d X(0.2, -0.1, 0.5);
  const Eigen::Vector3d moved = se3_exp(s) * X;
  const Eigen::Vector3d lin = X + s.head<3>() + s.tail<3>().cross(X);
  EXPECT_LT((moved - lin).norm(), 1e-12);
  EXPECT_NEAR(rotation_angle(p.R, u.R), d.tail<3>().norm(), 1e-9);
}

TEST(Pose, InvalidPosesAreDetected) {
  Pose p;
  p.t.x() = std::nan("");
  EXPECT_FALSE(p.is_valid());
  Pose s;
  s.R *= 2.0;
  EXPECT_FALSE(s.is_valid());
  s.orthonormalize();
  EXPECT_TRUE(s.is_valid());
}

TEST(Camera, ScalingKeepsPixelCentresConsistent) {
  const Camera c(600, 610, 319.5, 239.5, 640, 480);
  const Camera h = c.scaled(0.5);
  EXPECT_EQ(h.width, 320);
  EXPECT_EQ(h.height, 240);
  const Eigen::Vector3d X(0.1, -0.05, 0.8);
  const double u = c.fx * X.x() / X.z() + c.cx, v = c.fy * X.y() / X.z() + c.cy;
  const double uh = h.fx * X.x() / X.z() + h.cx, vh = h.fy * X.y() / X.z() + h.cy;
  EXPECT_NEAR(uh + 0.5, (u + 0.5) * 0.5, 1e-12);
  EXPECT_NEAR(vh + 0.5, (v + 0.5) * 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(h.K()(0, 0), 300);
}

TEST(Camera, ValidateRejectsBadIntrinsics) {
  EXPECT_THROW(Camera(0, 1, 1, 1, 10, 10).validate(), std::invalid_argument);
  EXPECT_THROW(Camera(1, 1, 1, 1, 0, 10).validate(), std::invalid_argument);
  EXPECT_THROW(Camera(std::nan(""), 1, 1, 1, 10, 10).validate(), std::invalid_argument);
  EXPECT_NO_THROW(Camera(500, 500, 320, 240, 640, 480).validate());
}
