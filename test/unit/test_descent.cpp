// Smoke test of the gradients' usefulness: plain gradient descent on the mask term alone recovers a 1 cm / 5 deg
// offset of a textured box rendered by the same renderer. (The accuracy target belongs to the refiner.)
#include "test_scenes.hpp"

using namespace diffdope;
using namespace diffdope::test;

namespace {

/// One plain gradient step, rotation taken about the object's centre (better conditioned than about the
/// camera origin). Rotation steps are scaled by 1/radius^2 so a step moves surface points as far as a
/// translation step of the same size.
Pose descend(const Pose& pose, const Vector6d& g, double alpha, double radius) {
  const Eigen::Vector3d p = pose.t;  // object centre (the box is centred on its origin)
  const Eigen::Vector3d g_rho = g.head<3>();
  const Eigen::Vector3d g_omega = g.tail<3>() - p.cross(g_rho);
  const Eigen::Vector3d v = -alpha * g_rho, w = -alpha / (radius * radius) * g_omega;
  const Eigen::Matrix3d Rw = so3_exp(w);
  return Pose(Rw * pose.R, Rw * (pose.t - p) + p + v);
}

}  // namespace

TEST(Descent, MaskTermAloneRecoversOneCentimetreFiveDegrees) {
  const Camera cam = test_camera();
  const Mesh box = make_box(Eigen::Vector3d(0.12, 0.08, 0.06), make_label_texture(128, 21));
  auto r = make_cpu_renderer();
  const Pose truth = look_pose(0.5, 0.4, 0.3, 0.01, -0.01, 0.45);
  const Observation obs = observe(*r, cam, box, truth);
  LossOptions loss;
  loss.weight_rgb = loss.weight_depth = 0;
  // 1 cm along a random-ish direction and 5 degrees about another axis through the object's centre.
  const Eigen::Vector3d dir = Eigen::Vector3d(0.6, -0.3, 0.74).normalized();
  const Eigen::Vector3d axis = Eigen::Vector3d(-0.2, 0.9, 0.4).normalized();
  const Eigen::Matrix3d dR = so3_exp(axis * (5.0 * M_PI / 180.0));
  Pose pose(dR * truth.R, truth.t + 0.01 * dir);

  const double radius = 0.5 * box.diameter();
  const int iters = 150;
  std::vector<LossValue> v;
  double first = 0;
  for (int k = 0; k < iters; ++k) {
    r->evaluate(cam, box, obs, {pose}, loss, true, v);
    if (k == 0) first = v[0].total;
    pose = descend(pose, v[0].gradient, 4e-4 * std::pow(0.1, double(k) / iters), radius);
  }
  r->evaluate(cam, box, obs, {pose}, loss, false, v);
  const double t_err = (pose.t - truth.t).norm();
  const double r_err = rotation_angle(pose.R, truth.R) * 180 / M_PI;
  EXPECT_LT(v[0].total, 0.1 * first);
  EXPECT_LT(t_err, 0.002) << "translation error " << t_err << " m";
  EXPECT_LT(r_err, 1.0) << "rotation error " << r_err << " deg";
}
