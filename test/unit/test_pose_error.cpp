// pose_error_twist() and check_covariance(): how diffdope_eval holds a result's covariance against its true error.
#include <gtest/gtest.h>

#include <cmath>

#include "diffdope/metrics.hpp"

using namespace diffdope;

TEST(PoseError, TheTwistIsThePivotsShiftAndTheTurnInCameraAxes) {
  const Pose estimate = Pose::from_quaternion(0.1, 0.2, 0.3, 0.9, Eigen::Vector3d(0.1, -0.05, 0.8));
  const Eigen::Vector3d pivot(0.02, 0.01, -0.03);
  const Eigen::Vector3d w(0.01, -0.02, 0.005), v(0.003, -0.001, 0.002);
  // Turned by w about the pivot's place, then moved by v: the truth.
  const Eigen::Vector3d c = estimate * pivot;
  Pose truth;
  truth.R = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix() * estimate.R;
  truth.t = truth.R * (-pivot) + c + v;
  const Vector6d e = pose_error_twist(estimate, truth, pivot);
  EXPECT_TRUE(e.head<3>().isApprox(v, 1e-12)) << e.transpose();
  EXPECT_TRUE(e.tail<3>().isApprox(w, 1e-9)) << e.transpose();
  EXPECT_TRUE(pose_error_twist(estimate, estimate, pivot).isZero(1e-12));
}

TEST(PoseError, TheCovarianceCheckIsMahalanobisAndTwoSigma) {
  Vector6d sd;
  sd << 0.001, 0.002, 0.004, 0.01, 0.02, 0.03;
  const Eigen::Matrix<double, 6, 6> cov = sd.cwiseProduct(sd).asDiagonal();
  Vector6d e = 1.5 * sd;  // 1.5 sigma on every coordinate: 6 x 2.25
  CovarianceCheck c = check_covariance(e, cov);
  EXPECT_NEAR(c.mahalanobis2, 13.5, 1e-9);
  EXPECT_TRUE(c.within_two_sigma);
  EXPECT_GT(c.mahalanobis2, kChiSquared6At95);  // within 2 sigma each, outside the 95 % ellipsoid together
  e[4] = 2.5 * sd[4];
  EXPECT_FALSE(check_covariance(e, cov).within_two_sigma);
  EXPECT_TRUE(std::isnan(check_covariance(e, Eigen::Matrix<double, 6, 6>::Zero()).mahalanobis2));
}
