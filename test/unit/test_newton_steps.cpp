// The Newton steps after the descent (RefinerOptions::newton_rounds): where plain steps stop short (a thin
// object's roll, bounded by the rate its width allows), and what they leave alone.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <random>

#include "diffdope/metrics.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/pose_curvature.hpp"
#include "diffdope/primitives.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "test_scenes.hpp"

using namespace diffdope;

namespace {

/// A thin printed bar (20 x 3 x 2 cm) 60 cm from a 640 x 480 camera: its roll about its length moves the surface
/// a tenth as far as a turn across it does.
struct BarScene {
  Camera cam{600, 600, 319.5, 239.5, 640, 480};
  Mesh mesh = make_box(Eigen::Vector3d(0.20, 0.03, 0.02), make_label_texture(256, 5));
  Pose truth;
  Observation obs;
  explicit BarScene(const SyntheticNoise& noise) {
    Vector6d d;
    d << 0, 0, 0, 0.5, -0.3, 0.9;
    truth = Pose(se3_exp(d).R, Eigen::Vector3d(0.02, 0.01, 0.6));
    obs = synthesize_observation(*make_cpu_renderer(), cam, mesh, truth, noise, 3);
  }
};

RefineResult refine_with(const BarScene& s, const Pose& init, int newton_rounds) {
  RefinerOptions o;
  o.newton_rounds = newton_rounds;
  return Refiner(o).refine(s.cam, s.obs, s.mesh, init);
}

}  // namespace

TEST(NewtonSteps, ConvergeAThinObjectWherePlainStepsStopShort) {
  const BarScene s{SyntheticNoise()};
  const auto points = metric_points(s.mesh);
  double without = 0, with = 0;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(seed);
    const Pose init = perturb_pose(s.truth, s.mesh.center(), 10 * M_PI / 180, 0.01, rng);  // a medium start
    const RefineResult plain = refine_with(s, init, 0), newton = refine_with(s, init, RefinerOptions().newton_rounds);
    EXPECT_EQ(plain.newton_steps, 0);
    EXPECT_GE(newton.newton_steps, 1) << "seed " << seed;
    EXPECT_LE(newton.loss.total, plain.loss.total) << "seed " << seed;
    EXPECT_LT(1e3 * add_error(points, newton.pose, s.truth), 0.15) << "seed " << seed;
    without += 1e3 * add_error(points, plain.pose, s.truth) / 4;
    with += 1e3 * add_error(points, newton.pose, s.truth) / 4;
  }
  EXPECT_GT(without, 2 * with) << "mean ADD without " << without << " mm, with " << with << " mm";
}

TEST(NewtonSteps, LeaveAPoseTheLossCannotImproveAsItWas) {
  // A noiseless image and the truth as the start: no step lowers the loss by more than noise would, so the
  // result is exactly what the refinement gives without them.
  SyntheticNoise none;
  none.rgb_sigma = 0, none.depth_sigma_at_1m = 0, none.hole_fraction = 0;
  const BarScene s{none};
  const RefineResult plain = refine_with(s, s.truth, 0), newton = refine_with(s, s.truth, RefinerOptions().newton_rounds);
  EXPECT_EQ(newton.newton_steps, 0);
  EXPECT_EQ(newton.pose.t, plain.pose.t);
  EXPECT_EQ(newton.pose.R, plain.pose.R);
  EXPECT_EQ(newton.loss.total, plain.loss.total);
}

TEST(NewtonSteps, GrowTheirReachAlongAValleyThatGoesOn) {
  // A start 2 cm too far along the line of sight and 4 degrees rolled, and next to no descent before the steps
  // (one iteration at a negligible rate). The first round may move 4 mm (twice one working pixel at 60 cm, at
  // image_scale 0.5); a round whose whole step that held back doubles it, so the rounds reach the truth. A reach
  // halved every round would end at least 12 mm from it.
  const BarScene s{SyntheticNoise()};
  RefinerOptions o = test::steps_only_options();
  o.shape_tolerance = 0;
  o.print_search = 0;
  Vector6d roll = Vector6d::Zero();
  roll.tail<3>() = s.truth.R.col(0) * (4 * M_PI / 180);  // about the bar's length
  Pose init = twist_about(s.truth, roll, s.truth * s.mesh.center());
  init.t.z() += 0.02;
  const auto points = metric_points(s.mesh);
  const double start_mm = 1e3 * add_error(points, init, s.truth);
  ASSERT_GT(start_mm, 20.0);
  o.newton_rounds = 8;
  const RefineResult r = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_GE(r.newton_steps, 3);
  EXPECT_LT(1e3 * add_error(points, r.pose, s.truth), 0.5) << "from " << start_mm << " mm";
  o.newton_rounds = 0;
  EXPECT_GT(1e3 * add_error(points, Refiner(o).refine(s.cam, s.obs, s.mesh, init).pose, s.truth), 0.9 * start_mm);
}

TEST(NewtonSteps, EndWhereTheModelPromisesLessThanAStepNeeds) {
  // Starts a frame's motion from the truth (1 degree, 1 mm), steps alone: a round whose step ends where the
  // quadratic model promises less than kNewtonEvidence is the last, without a probe about its result. Each round
  // costs a probe and three tries, so rounds = (evaluations - the pixel count's render) / that.
  const BarScene s{SyntheticNoise()};
  RefinerOptions o = test::steps_only_options();
  o.shape_tolerance = 0;
  o.print_search = 0;
  const auto points = metric_points(s.mesh);
  int ended_by_promise = 0;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(seed);
    const Pose init = perturb_pose(s.truth, s.mesh.center(), M_PI / 180, 0.001, rng);
    const RefineResult r = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
    const long steps = r.stage_evaluations[size_t(RefineStage::kAlignPrintAndStep)];
    ASSERT_EQ((steps - 1) % (kSecantProbePoses + 3), 0) << steps;
    const long rounds = (steps - 1) / (kSecantProbePoses + 3);
    EXPECT_GE(r.newton_steps, 1) << "seed " << seed;
    ended_by_promise += rounds == r.newton_steps;
    EXPECT_LT(1e3 * add_error(points, r.pose, s.truth), 0.25) << "seed " << seed << " from " << 1e3 * add_error(points, init, s.truth) << " mm";
  }
  EXPECT_GT(ended_by_promise, 0) << "every refinement probed once more after its last step";
}

/// A quadratic model: H = U diag(curvatures) Uᵀ (U a random rotation) and a gradient g.
struct QuadraticModel {
  Vector6d curvatures = (Vector6d() << 4, 1, 0.25, 9, 2, 0.5).finished();
  Matrix6d U = Eigen::HouseholderQR<Matrix6d>(Matrix6d::Random()).householderQ();
  Matrix6d H = U * curvatures.asDiagonal() * U.transpose();
  Vector6d g = (Vector6d() << 0.3, -0.2, 0.1, 0.05, -0.4, 0.2).finished();
};

TEST(NewtonDecrease, IsTheQuadraticModelsDropAtItsMinimum) {
  const QuadraticModel m;
  const Matrix6d& H = m.H;
  const Matrix6d& U = m.U;
  const Vector6d& g = m.g;
  const Vector6d& curvatures = m.curvatures;
  EXPECT_NEAR(newton_decrease(H, g), 0.5 * g.dot(H.ldlt().solve(g)), 1e-12);
  // Along a declared symmetry's free direction nothing is promised.
  EXPECT_NEAR(newton_decrease(H, U.col(2), {U.col(2)}), 0, 1e-12);
  EXPECT_NEAR(newton_decrease(H, U.col(2)), 0.5 / curvatures[2], 1e-12);
  // No step (nowhere curved upwards, or not finite): nothing.
  EXPECT_EQ(newton_decrease(-H, g), 0);
  EXPECT_EQ(newton_decrease(H, Vector6d::Constant(std::nan(""))), 0);
}

TEST(NewtonStep, SolvesAQuadraticModelWithinItsTrustRadius) {
  const QuadraticModel m;
  Vector6d curvatures = m.curvatures;
  const Matrix6d& U = m.U;
  const Matrix6d& H = m.H;
  const Vector6d& g = m.g;
  const Vector6d exact = -H.ldlt().solve(g);
  EXPECT_LT((newton_step(H, g, 1e3) - exact).norm(), 1e-9 * exact.norm());
  // Beyond the trust radius: damped to it, -(H + λI)⁻¹ g for a λ > 0, which lowers the quadratic model more than
  // the Newton step shortened to that length would.
  const double trust = 0.1 * exact.norm();
  const Vector6d damped = newton_step(H, g, trust);
  EXPECT_NEAR(damped.norm(), trust, 1e-6 * trust);
  const Vector6d residual = H * damped + g;
  const double lambda = -residual.dot(damped) / damped.squaredNorm();
  EXPECT_GT(lambda, 0);
  EXPECT_LT((residual + lambda * damped).norm(), 1e-6 * g.norm());
  const auto model = [&](const Vector6d& x) { return g.dot(x) + 0.5 * x.dot(H * x); };
  EXPECT_LT(model(damped), model(0.1 * exact));
  // A direction curved downwards is not followed uphill: its curvature is raised to a thousandth of the largest,
  // so the step still lowers the quadratic model there.
  curvatures[2] = -1;
  const Matrix6d saddle = U * curvatures.asDiagonal() * U.transpose();
  const Vector6d step = newton_step(saddle, g, 1e3);
  const double along = U.col(2).dot(step), slope = U.col(2).dot(g);
  EXPECT_LT(along * slope, 0);
  EXPECT_NEAR(along, -slope / (1e-3 * 9), 1e-9 * std::abs(along));
  EXPECT_EQ(newton_step(H, Vector6d::Constant(std::nan("")), 1.0), Vector6d::Zero());
  // Nowhere curved upwards: no step (not a floor of nothing, which would be infinite).
  EXPECT_EQ(newton_step(-H, g, 1.0), Vector6d::Zero());
  EXPECT_EQ(newton_step(Matrix6d::Zero(), g, 1.0), Vector6d::Zero());
  // A declared symmetry's free direction gets no part of the step.
  const Vector6d free_step = newton_step(H, g, 1e3, {U.col(0), U.col(3)});
  EXPECT_NEAR(U.col(0).dot(free_step), 0, 1e-12);
  EXPECT_NEAR(U.col(3).dot(free_step), 0, 1e-12);
  EXPECT_NEAR(U.col(1).dot(free_step), U.col(1).dot(exact), 1e-9);
  // Damped within the free directions' complement: still none of the step along them, and trust long.
  const Vector6d damped_free = newton_step(H, g, 0.05 * exact.norm(), {U.col(0), U.col(3)});
  EXPECT_NEAR(damped_free.norm(), 0.05 * exact.norm(), 1e-6 * exact.norm());
  EXPECT_NEAR(U.col(0).dot(damped_free), 0, 1e-12);
  EXPECT_NEAR(U.col(3).dot(damped_free), 0, 1e-12);
}

TEST(SecantHessian, RecoversAQuadraticLossInWhitenedUnits) {
  // Gradients of the quadratic loss ½ δᵀ H δ at the probe's twists are H δ: the whitened Hessian is L⁻¹ H L⁻ᵀ.
  const Matrix6d A = Matrix6d::Random(), H = A * A.transpose() + Matrix6d::Identity();
  const Matrix6d B = Matrix6d::Random(), G = B * B.transpose() + 0.5 * Matrix6d::Identity();
  const Eigen::LLT<Matrix6d> llt(G);
  const Matrix6d L = llt.matrixL(), Linv = L.inverse(), LinvT = Linv.transpose();
  const double h = 0.003;
  std::vector<Vector6d> gradients;
  for (int i = 0; i < 6; ++i)
    for (const double s : {h, -h}) gradients.push_back(H * (s * LinvT.col(i)));
  gradients.push_back(Vector6d::Zero());
  EXPECT_LT((secant_hessian(gradients, Linv, h) - Linv * H * LinvT).norm(), 1e-9 * H.norm());
  // The probe's poses lie along those twists, the pose itself last.
  const Pose pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.1, 0, 0.6));
  const std::vector<Pose> probes = secant_probe_poses(pose, LinvT, h, pose.t);
  ASSERT_EQ(probes.size(), size_t(kSecantProbePoses));
  EXPECT_EQ(probes.back().t, pose.t);
  EXPECT_LT((probes[0].t - pose.t - h * LinvT.col(0).head<3>()).norm(), 1e-12);
}

TEST(NewtonSteps, ConvergeTrackedStartsToo) {
  // A tracked start (refine_all, StartKind::kTracked) on the tracking budget: its few plain steps leave the bar's
  // soft directions short, and the Newton steps converge them, as they do for a detection.
  const BarScene s{SyntheticNoise()};
  const auto points = metric_points(s.mesh);
  const RefinerOptions tracked = tracked_options(RefinerOptions(), TrackOptions());
  ASSERT_EQ(tracked.newton_rounds, kTrackedNewtonRounds);
  RefinerOptions plain = tracked;
  plain.newton_rounds = 0;
  Refiner refiner{RefinerOptions()};
  int steps = 0;
  double with = 0, without = 0;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(seed);
    ObjectTarget target;
    target.mesh = &s.mesh;
    target.initial = perturb_pose(s.truth, s.mesh.center(), 3 * M_PI / 180, 0.002, rng);
    target.start_kind = StartKind::kTracked;
    const RefineResult n = refiner.refine_all(s.cam, s.obs, {target}, tracked).front();
    const RefineResult p = refiner.refine_all(s.cam, s.obs, {target}, plain).front();
    EXPECT_EQ(p.newton_steps, 0);
    EXPECT_LE(n.loss.total, p.loss.total) << "seed " << seed;
    steps += n.newton_steps;
    with += 1e3 * add_error(points, n.pose, s.truth) / 4;
    without += 1e3 * add_error(points, p.pose, s.truth) / 4;
  }
  EXPECT_GE(steps, 2);
  EXPECT_LT(with, 0.7 * without) << "mean ADD (mm) with the Newton steps " << with << ", without " << without;
}
