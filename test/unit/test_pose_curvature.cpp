// The loss around a refined pose (pose_curvature.hpp): the probe's least curved direction and the covariance built
// from it.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <cmath>

#include "diffdope/device.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;

namespace {

/// A texture of one colour: a plain object.
Texture plain_texture() {
  Texture t;
  t.width = t.height = 4;
  t.rgb.assign(3 * 16, 0.6f);
  return t;
}

ObjectSymmetry about_z() {
  ObjectSymmetry s;
  s.continuous.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero()});
  return s;
}

/// Standard deviation of the rotation about the unit `axis` (camera axes) in a twist covariance.
double rotation_std(const Matrix6d& cov, const Eigen::Vector3d& axis) {
  return std::sqrt(axis.dot(cov.bottomRightCorner<3, 3>() * axis));
}

}  // namespace

TEST(PoseCurvature, TheWeakestDirectionOfAPlainCylinderIsItsAxisUnlessDeclared) {
  // A plain (one-colour) cylinder: nothing in the image changes when it turns about its axis, so that is the
  // direction the probe finds least curved and flat; declared symmetric, the probe looks elsewhere and finds a
  // loss that rises.
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  Mesh can = make_cylinder(0.035, 0.11, 64, plain_texture());
  Vector6d d;
  d << 0, 0, 0, 1.1, 0.3, 0.2;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.01, 0.0, 0.45));
  auto renderer = make_cpu_renderer();
  const Observation obs = synthesize_observation(*renderer, cam, can, truth, SyntheticNoise(), 5);
  const PoseCurvature free = probe_pose_curvature(*renderer, cam, can, obs, LossOptions(), truth, 0.01);
  ASSERT_TRUE(free.valid);
  const Eigen::Vector3d axis = truth.R.col(2);
  const Eigen::Vector3d w = free.weakest_twist.tail<3>();
  EXPECT_GT(std::abs(w.normalized().dot(axis)), 0.95) << w.transpose();
  EXPECT_LT(std::abs(free.weakest_rise), 0.05);  // (64 facets: a turn shifts them a little)
  // One metre of surface displacement along it (the metric's unit).
  EXPECT_NEAR(std::sqrt(free.weakest_twist.dot(free.metric * free.weakest_twist)), 1.0, 1e-6);
  can.symmetry = about_z();
  const PoseCurvature declared = probe_pose_curvature(*renderer, cam, can, obs, LossOptions(), truth, 0.01,
                                                      can.symmetry.free_twists(truth, truth * can.center()));
  ASSERT_TRUE(declared.valid);
  EXPECT_LT(std::abs(declared.weakest_twist.tail<3>().normalized().dot(axis)), 0.5);
  EXPECT_GT(declared.weakest_rise, 4 * std::max(free.weakest_rise, 1e-3));
}

TEST(PoseCovariance, GrowsAboutAPlainCylindersAxis) {
  // Nothing in the image changes when a plain cylinder turns about its axis: the covariance says so, and is
  // capped there at the object's size; about a perpendicular axis the silhouette and depth pin it down.
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  const Mesh can = make_cylinder(0.035, 0.11, 64, plain_texture());
  Vector6d d;
  d << 0, 0, 0, 1.1, 0.3, 0.2;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.01, 0.0, 0.45));
  auto renderer = make_cpu_renderer();
  const Observation obs = synthesize_observation(*renderer, cam, can, truth, SyntheticNoise(), 5);
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;  // the truth itself
  o.image_scale = 1.0;
  o.shape_tolerance = 0;
  const RefineResult r = Refiner(o).refine(cam, obs, can, truth);
  ASSERT_TRUE(r.curvature.valid);
  const Eigen::Vector3d axis = truth.R.col(2), across = truth.R.col(0);
  const double about_axis = rotation_std(r.covariance, axis), about_across = rotation_std(r.covariance, across);
  EXPECT_GT(about_axis, 10 * about_across) << about_axis << " vs " << about_across;
  EXPECT_LT(about_across, 0.2);  // radians
  EXPECT_GT(about_axis, 1.0);    // radians: unknown (up to the cap: a turn moving the surface by one diameter)
  EXPECT_LT(about_axis, 6.0);
  EXPECT_LT(std::sqrt(r.covariance(0, 0)), 0.01);  // metres
  EXPECT_TRUE(r.covariance.isApprox(r.covariance.transpose(), 1e-9));
}

TEST(PoseCovariance, ADepthOnlyRefinementKnowsLessOfItsTurnInTheImagePlane) {
  // An L-block seen by depth alone (no colour, no mask): its turn about the viewing ray shows only at its
  // outline (in the depth term and the pixels derived from it), against the full observation's print and mask.
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  const Mesh block = make_l_block(0.12, make_label_texture(256, 31));
  Vector6d d;
  d << 0, 0, 0, 0.3, -0.2, 0.1;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.01, -0.01, 0.55));
  auto renderer = make_cpu_renderer();
  const Observation full = synthesize_observation(*renderer, cam, block, truth, SyntheticNoise(), 2);
  Observation depth_only;
  depth_only.depth = full.depth;
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;
  o.image_scale = 1.0;
  o.shape_tolerance = 0;
  const RefineResult a = Refiner(o).refine(cam, full, block, truth);
  const RefineResult b = Refiner(o).refine(cam, depth_only, block, truth);
  ASSERT_TRUE(a.curvature.valid);
  ASSERT_TRUE(b.curvature.valid);
  const Eigen::Vector3d ray = a.pivot.normalized();
  EXPECT_GT(rotation_std(b.covariance, ray), 1.25 * rotation_std(a.covariance, ray))
      << rotation_std(b.covariance, ray) << " vs " << rotation_std(a.covariance, ray);
}

TEST(PoseCovariance, AtTheOriginARotationAboutThePivotMovesTheOrigin) {
  Matrix6d twist = Matrix6d::Zero();
  twist(5, 5) = 0.01;  // 0.1 rad about the camera z axis, through the pivot
  const Eigen::Vector3d pivot(0, 0, 0.5), origin(0.1, 0, 0.5);
  const Matrix6d at = covariance_at_origin(twist, pivot, origin);
  EXPECT_NEAR(at(1, 1), 0.01 * 0.1 * 0.1, 1e-12);  // the origin, 0.1 m off the axis, swings along y
  EXPECT_NEAR(at(0, 0), 0.0, 1e-12);
  EXPECT_NEAR(at(5, 5), 0.01, 1e-12);
  EXPECT_NEAR(at(1, 5), 0.01 * 0.1, 1e-12);
}

TEST(PoseCurvature, ViewsOfOnePoseWeighTheirMeanLoss) {
  // Two views of one pose: the same view twice probes as that view alone; a second, different view (the block
  // seen with a box beside it, as a robot's links differ between captures) adds what it sees: the mean loss's
  // Hessian is close to the mean of the views' Hessians about the common pivot (each probed along its own
  // metric's axes: a secant Hessian, not exact).
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  const Mesh block = make_l_block(0.12, make_label_texture(128, 3));
  const Mesh cube = make_box(Eigen::Vector3d(0.04, 0.04, 0.04), make_label_texture(32, 4));
  const Mesh other =
      merge_meshes({{&block, Pose()}, {&cube, Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.1, 0, 0))}}, "other");
  Vector6d d;
  d << 0, 0, 0, 0.5, -0.3, 0.2;
  const Pose pose(se3_exp(d).R, Eigen::Vector3d(0.0, 0.01, 0.6));
  auto renderer = make_cpu_renderer();
  const Observation a = synthesize_observation(*renderer, cam, block, pose, SyntheticNoise(), 1);
  const Observation b = synthesize_observation(*renderer, cam, other, pose, SyntheticNoise(), 2);
  const Eigen::Vector3d pivot = block.center();
  const PoseCurvature one = probe_pose_curvature(*renderer, {{cam, block, a}}, LossOptions(), pose, pivot, 0.01);
  const PoseCurvature twice =
      probe_pose_curvature(*renderer, {{cam, block, a}, {cam, block, a}}, LossOptions(), pose, pivot, 0.01);
  ASSERT_TRUE(one.valid);
  ASSERT_TRUE(twice.valid);
  EXPECT_NEAR(twice.loss, one.loss, 1e-12);
  EXPECT_LT((twice.hessian - one.hessian).norm(), 1e-9 * one.hessian.norm());
  // The single-view call is the one-view case of the several-view probe.
  const PoseCurvature single = probe_pose_curvature(*renderer, cam, block, a, LossOptions(), pose, 0.01);
  EXPECT_EQ(single.hessian, one.hessian);
  const PoseCurvature only_b = probe_pose_curvature(*renderer, {{cam, other, b}}, LossOptions(), pose, pivot, 0.01);
  const PoseCurvature both =
      probe_pose_curvature(*renderer, {{cam, block, a}, {cam, other, b}}, LossOptions(), pose, pivot, 0.01);
  ASSERT_TRUE(both.valid);
  EXPECT_NEAR(both.loss, 0.5 * (one.loss + only_b.loss), 1e-9);
  EXPECT_LT((both.hessian - 0.5 * (one.hessian + only_b.hessian)).norm(), 0.1 * both.hessian.norm());
}

TEST(PoseCurvature, CarriedToALaterFramesPoseItTurnsWithTheObject) {
  // A printed bar (20 x 3 x 2 cm) turned a quarter turn about the line of sight through its centre (and moved
  // 5 mm) between two frames: its image turns with it, and so do the directions the loss pins down least and
  // most. The curvature measured on the first frame, carried to the second pose, is near the second frame's own
  // probe; carried without the turn, it is far. The loss and the weakest direction's rise are the second frame's.
  // (Secant Hessians of one scene vary with the pose itself, so the carried one is only near: the test measures
  // the turn.)
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  const Mesh bar = make_box(Eigen::Vector3d(0.20, 0.03, 0.02), make_label_texture(256, 5));
  const Pose first(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix(), Eigen::Vector3d(0.0, 0.01, 0.6));
  const Eigen::Vector3d pivot = first * bar.center();
  Vector6d motion = Vector6d::Zero();
  motion.head<3>() = Eigen::Vector3d(0.005, 0, 0);
  motion.tail<3>() = pivot.normalized() * (M_PI / 2);
  const Pose second = twist_about(first, motion, pivot);
  auto renderer = make_cpu_renderer();
  const Observation a = synthesize_observation(*renderer, cam, bar, first, SyntheticNoise(), 1);
  const Observation b = synthesize_observation(*renderer, cam, bar, second, SyntheticNoise(), 2);
  const PoseCurvature measured = probe_pose_curvature(*renderer, cam, bar, a, LossOptions(), first, 0.01);
  const PoseCurvature fresh = probe_pose_curvature(*renderer, cam, bar, b, LossOptions(), second, 0.01);
  ASSERT_TRUE(measured.valid);
  ASSERT_TRUE(fresh.valid);
  const PoseCurvature carried =
      carry_pose_curvature(*renderer, {{cam, bar, b}}, LossOptions(), measured, first, second, bar.center(), 0.01);
  const PoseCurvature unturned =
      carry_pose_curvature(*renderer, {{cam, bar, b}}, LossOptions(), measured, second, second, bar.center(), 0.01);
  ASSERT_TRUE(carried.valid);
  EXPECT_NEAR(carried.loss, fresh.loss, 1e-9 * fresh.loss);
  EXPECT_EQ(carried.metric, fresh.metric);
  EXPECT_GT(carried.weakest_rise, 0);
  // Compared in the metric's units (metres of mean surface displacement in every direction, so that turns and
  // shifts weigh alike): the Hessians' relative difference.
  const Matrix6d Linv = Eigen::LLT<Matrix6d>(fresh.metric).matrixL().toDenseMatrix().inverse();
  const auto off = [&](const PoseCurvature& c) {
    return (Linv * (c.hessian - fresh.hessian) * Linv.transpose()).norm() /
           (Linv * fresh.hessian * Linv.transpose()).norm();
  };
  EXPECT_LT(off(carried), 0.5);
  EXPECT_GT(off(unturned), 4 * off(carried));
  // Nothing measured, nothing carried.
  EXPECT_FALSE(carry_pose_curvature(*renderer, {{cam, bar, b}}, LossOptions(), PoseCurvature(), first, second,
                                    bar.center(), 0.01)
                   .valid);
}

TEST(PoseCurvature, ATrackedStartCarriesTheCurvatureItIsGivenAndAFreshOneProbes) {
  const Camera cam{420, 420, 159.5, 119.5, 320, 240};
  const Mesh block = make_l_block(0.12, make_label_texture(128, 3));
  Vector6d d;
  d << 0, 0, 0, 0.5, -0.3, 0.2;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.0, 0.01, 0.6));
  auto renderer = make_cpu_renderer();
  const Observation obs = synthesize_observation(*renderer, cam, block, truth, SyntheticNoise(), 1);
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 10;
  Refiner refiner(o);
  ObjectTarget t;
  t.mesh = &block;
  t.initial = truth;
  t.start_kind = StartKind::kTracked;
  const RefineResult probed = refiner.refine_all(cam, obs, {t}).front();
  ASSERT_TRUE(probed.curvature.valid);
  EXPECT_FALSE(probed.curvature_carried);
  t.carried_curvature = MeasuredCurvature{probed.curvature, probed.pose};
  const RefineResult carried = refiner.refine_all(cam, obs, {t}).front();
  EXPECT_TRUE(carried.curvature_carried);
  ASSERT_TRUE(carried.curvature.valid);
  EXPECT_FALSE(carried.covariance.isZero(0));
  // 3 evaluations instead of the probe's 15 (the scores' render is the stage's other one).
  EXPECT_EQ(carried.stage_evaluations[size_t(RefineStage::kScore)], 1 + kCarriedCurvatureEvaluations);
  EXPECT_EQ(probed.stage_evaluations[size_t(RefineStage::kScore)], 1 + kCurvatureProbeEvaluations);
  // A fresh start (a detection) is not a frame from the last: it probes its own.
  t.start_kind = StartKind::kFresh;
  EXPECT_FALSE(refiner.refine_all(cam, obs, {t}).front().curvature_carried);
}
