// Rotations a shape cannot tell from no rotation (shape_rotations.hpp), and the refiner's starts from them.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include "diffdope/metrics.hpp"

#include "diffdope/print_alignment.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/synthetic.hpp"
#include "labelled_can.hpp"
#include "test_scenes.hpp"
#include "refine/refine_run.hpp"

using namespace diffdope;

namespace {

/// The ambiguous rotations at the refiner's default tolerance, at most `n`.
std::vector<ShapeRotation> ambiguous(const Mesh& m, int n = kMaxShapeTurns) {
  return ambiguous_rotations(analyse_shape_rotations(m), RefinerOptions().shape_tolerance, n);
}

double degrees(double radians) { return radians * 180.0 / M_PI; }
double angle_between(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return degrees(Eigen::AngleAxisd(a.transpose() * b).angle());
}

}  // namespace

TEST(ShapeRotations, ABoxIsAmbiguousByHalfTurnsAboutItsThreeAxes) {
  const Mesh box = make_box(Eigen::Vector3d(0.16, 0.06, 0.21), make_pattern_texture(64, 1));
  const auto r = ambiguous(box);
  ASSERT_EQ(r.size(), 3u);
  Eigen::Vector3d axes_seen = Eigen::Vector3d::Zero();
  for (const ShapeRotation& x : r) {
    EXPECT_NEAR(degrees(x.angle), 180.0, 1e-9);
    EXPECT_LT(x.discrepancy, 0.002);
    axes_seen += x.axis.cwiseAbs();
    EXPECT_LT((x.pivot - box.center()).norm(), 1e-9);  // the box's centroid is its centre
  }
  EXPECT_TRUE(axes_seen.isApprox(Eigen::Vector3d::Ones(), 1e-6)) << axes_seen.transpose();
}

TEST(ShapeRotations, ACylinderIsTurnedEvery30DegreesAboutItsAxisAndFlippedEndOverEnd) {
  const Mesh can = make_cylinder(0.035, 0.11, 64, make_label_texture(128, 3));
  const auto r = ambiguous(can);
  ASSERT_EQ(r.size(), 13u);
  for (int k = 0; k < 11; ++k) {  // about the axis first, 30 degrees apart
    EXPECT_NEAR(std::abs(r[size_t(k)].axis.z()), 1.0, 1e-6);
    EXPECT_NEAR(degrees(r[size_t(k)].angle), 30.0 * (k + 1), 1e-9);
  }
  for (int k = 11; k < 13; ++k) {  // then the flips about axes across it
    EXPECT_NEAR(r[size_t(k)].axis.z(), 0.0, 1e-6);
    EXPECT_NEAR(degrees(r[size_t(k)].angle), 180.0, 1e-9);
  }
  // Fewer allowed: fewer, still spread over the turn.
  const auto two = ambiguous(can, 2);
  ASSERT_EQ(two.size(), 2u);
  EXPECT_NEAR(degrees(two[0].angle), 120.0, 1e-9);
  EXPECT_NEAR(degrees(two[1].angle), 240.0, 1e-9);
}

TEST(ShapeRotations, AnAsymmetricShapeHasNone) {
  const Mesh l = make_l_block(0.12, make_label_texture(64, 2));
  EXPECT_TRUE(ambiguous(l).empty());
  const auto all = analyse_shape_rotations(l);
  EXPECT_EQ(all.size(), size_t(3 * (kShapeAngleSteps - 1)));
  EXPECT_TRUE(ambiguous_rotations(all, 0.0, 8).empty());  // tolerance 0: exploration off
}

TEST(ShapeRotations, TheAnalysisIsDeterministicAndAsPoseTurnsAboutThePivot) {
  const Mesh can = make_cylinder(0.03, 0.1, 48, make_label_texture(64, 3));
  const auto a = analyse_shape_rotations(can), b = analyse_shape_rotations(can);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].discrepancy, b[i].discrepancy);
  ShapeRotation r;
  r.axis = Eigen::Vector3d::UnitZ();
  r.pivot = Eigen::Vector3d(1, 0, 0);
  r.angle = M_PI;
  const Pose T = r.as_pose();
  EXPECT_TRUE((T * r.pivot).isApprox(r.pivot));
  EXPECT_TRUE((T * Eigen::Vector3d(2, 0, 5)).isApprox(Eigen::Vector3d(0, 0, 5)));
}

TEST(Refiner, ARollOnlyTheLabelShowsIsFoundByTheShapeScan) {
  // A labelled can seen from the side, started half a turn off about its axis: silhouette and depth fit the
  // start as well as the truth, so descent stays there; the scan of the turns about the axis finds the label.
  // (Our own renders: the plain colour term sees the label. Real images need loss.weight_texture.)
  const test::LabelledCan s = test::labelled_can();
  const Camera& cam = s.cam;
  const Mesh& can = s.can;
  const Pose& truth = s.truth;
  const Observation& obs = s.obs;
  const Pose start = truth * test::about_can_axis(180);
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 40;
  o.image_scale = 1.0;
  o.shape_tolerance = 0.01;
  const RefineResult explored = Refiner(o).refine(cam, obs, can, start);
  o.shape_tolerance = 0;
  const RefineResult plain = Refiner(o).refine(cam, obs, can, start);
  const double r_explored = angle_between(explored.pose.R, truth.R);
  const double r_plain = angle_between(plain.pose.R, truth.R);
  EXPECT_LT(r_explored, 3.0);
  EXPECT_GT(r_plain, 90.0);  // the start's basin: the label alone does not turn it half a turn
  EXPECT_GT(explored.scan_turns, 0);
  EXPECT_EQ(plain.scan_turns, 0);
  EXPECT_LT(explored.loss.total, plain.loss.total);
  o.shape_tolerance = 0.01;
  o.shape_scan = false;
  EXPECT_EQ(Refiner(o).refine(cam, obs, can, start).scan_turns, 0);
}

TEST(ShapeRotations, RevolutionAxesAreTheCylindersAxisAndNoneOfABox) {
  const Mesh can = make_cylinder(0.035, 0.11, 64, make_label_texture(128, 3));
  const auto axes = revolution_axes(analyse_shape_rotations(can), 0.01);
  ASSERT_EQ(axes.size(), 1u);
  EXPECT_NEAR(std::abs(axes[0].axis.z()), 1.0, 1e-6);
  EXPECT_EQ(axes[0].angle, 0.0);
  const Mesh box = make_box(Eigen::Vector3d(0.16, 0.06, 0.21), make_pattern_texture(64, 1));
  EXPECT_TRUE(revolution_axes(analyse_shape_rotations(box), 0.01).empty());  // half turns only
  EXPECT_TRUE(revolution_axes(analyse_shape_rotations(can), 0.0).empty());   // off
}

TEST(Refiner, ThePrintIsAlignedAgainOnceTheNewtonStepsHaveConverged) {
  // The labelled can 12 degrees off about its axis, 3 cm too far and 2.5 cm aside, with next to no descent (one
  // iteration at a negligible rate): the first alignment compares turns of a label drawn too small and out of
  // place, and its best turn is refused (the print registers neither there nor at the result). The Newton
  // steps then bring the can to its silhouette and depth (and, blind about the axis without the colour term,
  // turn it further), and the alignment, run again there, turns it to the label.
  const test::LabelledCan s = test::labelled_can();
  Pose start = s.truth * test::about_can_axis(12);
  start.t += Eigen::Vector3d(0.025, 0.0, 0.03);
  RefinerOptions o = test::steps_only_options();
  o.batch_size = 8;
  o.image_scale = 1.0;
  o.loss.weight_rgb = 0;
  o.newton_rounds = 8;
  const RefineResult r = Refiner(o).refine(s.cam, s.obs, s.can, start);
  EXPECT_GE(r.newton_steps, 3);
  EXPECT_GT(degrees(r.print_turn), 10.0);
  test::expect_within_plan(r, o, "the can");  // both alignments and both rounds of steps within the plan
  EXPECT_GT(r.stage_evaluations[size_t(RefineStage::kAlignPrintAndStep)], 0);
  EXPECT_LT(angle_between(r.pose.R, s.truth.R), 1.5);
  EXPECT_LT((r.pose.t - s.truth.t).norm(), 0.002);
}

TEST(Refiner, ThePrintAlignmentTurnsAboutTheAxisToTheLabel) {
  // The labelled can started 12 degrees off about its axis, refined on depth and mask only (as if its colour
  // could not be trusted, as a flat render against a lit image): the descent cannot see the turn, the shape
  // scan's 30-degree turns do not reach it, and only the print alignment's texture comparison brings it back.
  const test::LabelledCan s = test::labelled_can();
  const Pose start = s.truth * test::about_can_axis(12);
  RefinerOptions o;
  o.batch_size = 8;
  o.iterations = 30;
  o.coarse_fraction = 0.5;  // (at 0.75, 8 fine iterations: the scan then turns this colourless fit by 60
                            // degrees on a near tie, out of the alignment's range; see docs/benchmarks.md)
  o.image_scale = 1.0;
  o.loss.weight_rgb = 0;
  const RefineResult aligned = Refiner(o).refine(s.cam, s.obs, s.can, start);
  o.print_search = 0;
  const RefineResult plain = Refiner(o).refine(s.cam, s.obs, s.can, start);
  EXPECT_LT(angle_between(aligned.pose.R, s.truth.R), 1.0);
  EXPECT_GT(angle_between(plain.pose.R, s.truth.R), 8.0);
  EXPECT_NEAR(degrees(std::abs(aligned.print_turn)), 12.0, 1.0);
  EXPECT_EQ(plain.print_turn, 0.0);
  EXPECT_LT((aligned.pose.t - s.truth.t).norm(), 0.002);
  // The loss at the turned pose: within kPrintLossTolerance of the start's, which fits silhouette and depth as well.
  EXPECT_LE(aligned.loss.total, (1 + kPrintLossTolerance) * aligned.initial_loss);
  // Without the shape scan the alignment turns it all the same: the shape's axis is known (shape_tolerance).
  o.print_search = RefinerOptions().print_search;
  o.shape_scan = false;
  const RefineResult unscanned = Refiner(o).refine(s.cam, s.obs, s.can, start);
  EXPECT_EQ(unscanned.scan_turns, 0);
  EXPECT_LT(angle_between(unscanned.pose.R, s.truth.R), 1.0);
  EXPECT_NEAR(degrees(std::abs(unscanned.print_turn)), 12.0, 1.0);
}

TEST(PrintAlignment, TakesTheTextureMinimumWithinRangeUnlessTheLossRises) {
  ShapeRotation axis;
  axis.axis = Eigen::Vector3d::UnitZ();
  const Pose pose;
  const double target = 0.2;  // radians: the print's turn
  const auto turn_of = [&](const Pose& p) { return std::atan2(p.R(1, 0), p.R(0, 0)); };
  double loss_rise = 0;  // relative rise of the other terms: near the target, or at every turn
  bool rise_everywhere = false;
  double depth = 1.0;     // of the texture term's minimum
  int calls = 0;
  const PrintEvaluator eval = [&](const std::vector<Pose>& poses, std::vector<LossValue>& out) {
    ++calls;
    out.assign(poses.size(), LossValue());
    for (size_t i = 0; i < poses.size(); ++i) {
      const double a = turn_of(poses[i]);
      out[i].texture = 0.5 + depth * (a - target) * (a - target);
      const double near = std::exp(-std::pow((a - target) / 0.05, 2));
      const double other = 1.0 + loss_rise * (rise_everywhere ? (a != 0.0 ? 1.0 : 0.0) : near);
      out[i].total = other + out[i].texture;  // the texture at weight 1, the refiner's loss at weight 0
    }
  };
  PrintAlignment a = align_print(pose, axis, 0.7, 0.0, eval);
  EXPECT_EQ(calls, 2);  // the coarse steps, then the fine ones around the best
  EXPECT_EQ(a.evaluations, print_alignment_evaluations(0.7));
  EXPECT_NEAR(a.angle, target, kPrintFineStep / 2 + 1e-9);
  EXPECT_NEAR(turn_of(a.pose), a.angle, 1e-9);
  EXPECT_LT(a.print_after, a.print_before);
  // Out of range: the best turn within it, at the boundary, never beyond.
  a = align_print(pose, axis, 0.1, 0.0, eval);
  EXPECT_LE(std::abs(a.angle), 0.1 + 1e-9);
  EXPECT_GT(a.angle, 0.1 - kPrintFineStep);
  // The other terms rising more than kPrintLossTolerance near the target: the best print among the turns that
  // keep the fit, beside it.
  loss_rise = 3 * kPrintLossTolerance;
  a = align_print(pose, axis, 0.7, 0.0, eval);
  EXPECT_GT(std::abs(a.angle - target), 0.05);
  EXPECT_LT(a.print_after, a.print_before);
  EXPECT_LE(a.loss_after, (1 + kPrintLossTolerance) * a.loss_before + 1e-12);
  // ... and at every turn: no turn.
  rise_everywhere = true;
  a = align_print(pose, axis, 0.7, 0.0, eval);
  EXPECT_EQ(a.angle, 0.0);
  EXPECT_TRUE(a.pose.R.isApprox(pose.R));
  // A rise within kPrintLossTolerance, but more than the print gains (2 % against 1.5 %): no turn either.
  loss_rise = 0.75 * kPrintLossTolerance;
  EXPECT_NEAR(align_print(pose, axis, 0.7, 0.0, eval).angle, target, kPrintFineStep);  // gains 7 %
  depth = 0.25;
  EXPECT_EQ(align_print(pose, axis, 0.7, 0.0, eval).angle, 0.0);
  // A nearly flat print term (a pose where the print barely registers): of two acceptable dips, the one where the
  // loss falls, not the slightly deeper one where it rises (within kPrintLossTolerance).
  {
    const double a1 = -0.3, a2 = 0.25;
    const PrintEvaluator flat = [&](const std::vector<Pose>& poses, std::vector<LossValue>& out) {
      out.assign(poses.size(), LossValue());
      for (size_t i = 0; i < poses.size(); ++i) {
        const double a = turn_of(poses[i]);
        const double d1 = std::exp(-std::pow((a - a1) / 0.03, 2)), d2 = std::exp(-std::pow((a - a2) / 0.03, 2));
        out[i].texture = 0.7 * (1.0 - 0.03 * d1 - 0.025 * d2);
        out[i].total = 1.0 + 0.01 * d1 - 0.02 * d2 + out[i].texture;
      }
    };
    EXPECT_NEAR(align_print(pose, axis, 0.7, 0.0, flat).angle, a2, kPrintFineStep);
  }
  // No range: nothing evaluated.
  calls = 0;
  EXPECT_EQ(align_print(pose, axis, 0.0, 0.0, eval).angle, 0.0);
  EXPECT_EQ(calls, 0);
  EXPECT_EQ(print_alignment_evaluations(0.0), 0);
}

TEST(ShapeRotations, TheFittedAxisOfRevolutionIsAMugsBodyAxisDespiteItsHandle) {
  // The handle tilts the principal axes off the body's, so none is an axis of revolution; the normal lines of
  // the body still meet its axis (the bounding box is centred, so the body's axis is x = offset, y = 0).
  const Mesh mug = make_scan_like(ScanShape::Mug, Eigen::Vector3d(0.113, 0.084, 0.1), 3000, 256, 2);
  EXPECT_TRUE(revolution_axes(analyse_shape_rotations(mug), 0.01).empty());
  const auto fitted = fit_revolution_axis(mug, 0.01);
  ASSERT_TRUE(fitted.has_value());
  EXPECT_GT(std::abs(fitted->axis.z()), std::cos(2.0 * M_PI / 180));
  EXPECT_NEAR(fitted->pivot.y(), 0.0, 0.002);
  // A turn of the body about it keeps the body where it was: the axis runs through the body's centre, which
  // lies towards -x of the box centre (the handle is on +x).
  EXPECT_LT(fitted->pivot.x(), 0.0);
  EXPECT_EQ(fitted->angle, 0.0);
  // The cylinder's own axis; none for a box, an L-block or a switched-off tolerance.
  const auto can = fit_revolution_axis(make_cylinder(0.035, 0.11, 64, make_label_texture(64, 3)), 0.01);
  ASSERT_TRUE(can.has_value());
  EXPECT_GT(std::abs(can->axis.z()), std::cos(1.0 * M_PI / 180));
  EXPECT_FALSE(fit_revolution_axis(make_box(Eigen::Vector3d(0.16, 0.06, 0.21), make_pattern_texture(64, 1)), 0.01));
  EXPECT_FALSE(fit_revolution_axis(make_l_block(0.12, make_label_texture(64, 2)), 0.01));
  EXPECT_FALSE(fit_revolution_axis(mug, 0.0));
}

TEST(Refiner, WithRgbAloneThePrintAlignmentIsSkipped) {
  // A scan-like mug seen in colour only (no mask, no depth), started 20 degrees off. The alignment's licence to
  // raise the loss by kPrintLossTolerance rests on a mask or depth holding everything but the turn; without them
  // it turned the handle (unseen) to where the print fitted slightly better, 30-40 degrees from the truth, on 3
  // of these 4 starts. Skipped, every result ends nearer the truth than its start.
  const test::LabelledCan scene = test::labelled_can();
  const Mesh mug = make_scan_like(ScanShape::Mug, Eigen::Vector3d(0.11, 0.08, 0.095), 3000, 512, 1);
  const Pose truth(se3_exp((Vector6d() << 0, 0, 0, 1.9, -0.3, 0.4).finished()).R, Eigen::Vector3d(0.01, -0.01, 0.45));
  Observation rgb_only = synthesize_observation(*make_cpu_renderer(), scene.cam, mug, truth, SyntheticNoise(), 1);
  rgb_only.depth = cv::Mat();
  rgb_only.mask = cv::Mat();
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 40;
  o.image_scale = 1.0;
  Refiner refiner(o);
  ASSERT_GT(o.print_search, 0.0);
  for (const uint64_t seed : {1, 2, 3, 4}) {
    SCOPED_TRACE(seed);
    std::mt19937_64 rng(seed);
    const Pose start = perturb_pose(truth, mug.center(), 20 * M_PI / 180, 0.01, rng);
    const RefineResult r = refiner.refine(scene.cam, rgb_only, mug, start);
    EXPECT_EQ(r.print_turn, 0.0);
    EXPECT_LT(angle_between(r.pose.R, truth.R), 18.0);
  }
}

TEST(Refiner, AboutATrackedStartThePrintIsSoughtOnlyNearby) {
  // The labelled can of the test above in refine_all: from a tracked start (StartKind::kTracked) the alignment
  // searches +-kTrackedPrintSearch (10 degrees), enough for the spin since the last frame; from a detection, its
  // whole range.
  const test::LabelledCan s = test::labelled_can();
  RefinerOptions o;
  o.batch_size = 8;
  o.iterations = 30;
  o.coarse_fraction = 0.5;
  o.image_scale = 1.0;
  o.loss.weight_rgb = 0;
  Refiner refiner(o);
  const auto refined = [&](double degrees_off, StartKind kind) {
    ObjectTarget t{&s.can, s.truth * test::about_can_axis(degrees_off), s.obs.mask, {}, kind};
    return refiner.refine_all(s.cam, s.obs, {t})[0];
  };
  const RefineResult near_track = refined(6, StartKind::kTracked);
  EXPECT_LT(angle_between(near_track.pose.R, s.truth.R), 1.0);
  EXPECT_NEAR(degrees(std::abs(near_track.print_turn)), 6.0, 1.0);
  const RefineResult far_track = refined(20, StartKind::kTracked);
  EXPECT_LE(degrees(std::abs(far_track.print_turn)), degrees(kTrackedPrintSearch) + 1e-6);
  EXPECT_GT(angle_between(far_track.pose.R, s.truth.R), 8.0);
  const RefineResult far_detection = refined(20, StartKind::kFresh);
  EXPECT_LT(angle_between(far_detection.pose.R, s.truth.R), 1.0);
}

namespace {

/// A can's texture: a print of small sharp rectangles over a brightness ramp along the can's side (the side's
/// band of the atlas, make_cylinder: v in [0.02, 0.48]), rising from `from` to `to` along the axis.
Texture ramped_print(double from, double to) {
  const int n = 256;
  cv::Mat img(n, n, CV_32FC3);
  for (int y = 0; y < n; ++y) {
    const double f = double(y) / n, along = f < 0.5 ? f / 0.5 : (f - 0.5) / 0.5;
    img.row(y).setTo(cv::Scalar::all(from + (to - from) * along));
  }
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> at(0, n - 1), size(4, 14), sign(0, 1);
  for (int i = 0; i < 400; ++i) {
    const cv::Rect r(at(rng), at(rng), size(rng), size(rng) / 2 + 2);
    cv::Mat patch = img(r & cv::Rect(0, 0, n, n));
    patch += cv::Scalar::all(sign(rng) ? 0.18 : -0.18);
  }
  Texture t;
  t.width = t.height = n;
  t.source = "ramped print";
  t.rgb.assign(img.ptr<float>(0), img.ptr<float>(0) + 3 * n * n);
  return t;
}

}  // namespace

TEST(Refiner, AFlipThePrintContradictsIsNotTakenFromAGoodStart) {
  // A printed can lit from one end: the image's brightness rises along the axis the other way from the model's
  // albedo, so the can turned end over end fits the flat colour term better, although its print is upside
  // down. A scan that took the lower loss would flip a start 1 degree and 1 mm from the truth by half a turn.
  const Mesh model = make_cylinder(0.035, 0.11, 64, ramped_print(0.25, 0.75));
  const Mesh lit = make_cylinder(0.035, 0.11, 64, ramped_print(0.75, 0.25));
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  Vector6d d;
  d << 0, 0, 0, 1.3, 0.2, 0.1;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.0, 0.0, 0.45));
  const std::unique_ptr<Renderer> renderer = make_cpu_renderer();
  const Observation obs = synthesize_observation(*renderer, cam, lit, truth, SyntheticNoise(), 5);
  // The trap is real: the flip's loss is clearly lower than the truth's.
  const Pose flipped = truth * Pose(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                                    Eigen::Vector3d::Zero());
  std::vector<LossValue> v;
  renderer->evaluate(cam, model, obs, {truth, flipped}, LossOptions(), false, v);
  ASSERT_LT(v[1].total, 0.97 * v[0].total);

  std::mt19937_64 rng(3);
  const auto points = metric_points(model);
  for (int k = 0; k < 3; ++k) {
    const Pose start = perturb_pose(truth, Eigen::Vector3d::Zero(), M_PI / 180, 0.001, rng);
    RefinerOptions o;
    o.image_scale = 1.0;
    const RefineResult r = Refiner(o).refine(cam, obs, model, start);
    EXPECT_LT(add_error(points, r.pose, truth), 0.002) << "start " << k;
    EXPECT_GT(r.scan_turns, 0) << "start " << k;  // the flip was a candidate, and was refused
    EXPECT_FALSE(r.scan_taken) << "start " << k;
  }
  // As a real RGB-D camera gives it, the colour 5 px off the depth and the mask: the print no longer registers at
  // the truth (it cannot contradict the flip), and registers at the converged flip by chance (2-3 sigma). The
  // lower loss alone still does not turn the can end over end; the result follows the colour by a few millimetres.
  Observation misregistered = obs;
  misregistered.rgb = cv::Mat();  // (not in place: obs shares its pixels)
  cv::warpAffine(obs.rgb, misregistered.rgb, cv::Matx23d(1, 0, -5, 0, 1, 0), obs.rgb.size(), cv::INTER_LINEAR,
                 cv::BORDER_REPLICATE);
  std::mt19937_64 same_starts(3);
  for (int k = 0; k < 3; ++k) {
    const Pose start = perturb_pose(truth, Eigen::Vector3d::Zero(), M_PI / 180, 0.001, same_starts);
    RefinerOptions o;
    o.image_scale = 1.0;
    const RefineResult r = Refiner(o).refine(cam, misregistered, model, start);
    EXPECT_LT(add_error(points, r.pose, truth), 0.01) << "start " << k << ", colour 5 px off";
    EXPECT_FALSE(r.scan_taken) << "start " << k << ", colour 5 px off";
  }
}

TEST(JumpEvidence, AJumpNeedsALowerLossAndEvidenceThatGrowsWithItsAngle) {
  const double quarter = M_PI / 2, half = M_PI, none = std::nan("");
  const double weigh = 1.0;  // min_print_significance
  // Never without a lower loss, whatever the print says.
  EXPECT_FALSE(jump_is_supported({0.30, 0.0}, {0.30, 20.0}, quarter, weigh));
  // The print contradicts (a flipped label: 13 sigma at the start's basin, none at the flip): a 2 % lower loss
  // does not jump, nor would any.
  EXPECT_FALSE(jump_is_supported({0.2525, 13.2}, {0.2475, 0.2}, half, weigh));
  EXPECT_FALSE(jump_is_supported({0.30, 5.0}, {0.10, 3.9}, half, weigh));
  EXPECT_FALSE(jump_is_supported({0.30, 5.0}, {0.10, none}, half, weigh));  // the print is lost there
  // The print supports it clearly: a loss barely lower is enough. Half a turn needs twice the bar of a small one.
  EXPECT_TRUE(jump_is_supported({0.30, 0.5}, {0.299, 6.6}, 0.1, weigh));
  EXPECT_FALSE(jump_is_supported({0.30, 0.5}, {0.299, 5.5}, half, weigh));
  EXPECT_TRUE(jump_is_supported({0.30, 0.5}, {0.299, 6.6}, half, weigh));
  // The print neither contradicts nor decides (a label turned about its axis registers alike): the loss
  // decides, by a margin that grows with the angle.
  EXPECT_NEAR(jump_margin(0.0), kJumpMargin, 1e-12);
  EXPECT_NEAR(jump_margin(half), 5 * kJumpMargin, 1e-12);
  EXPECT_TRUE(jump_is_supported({0.2653, 6.29}, {0.2507, 6.32}, M_PI / 6, weigh));   // 5.5 % lower
  EXPECT_FALSE(jump_is_supported({0.2653, 6.29}, {0.2627, 6.32}, M_PI / 6, weigh));  // 1 % lower
  EXPECT_FALSE(jump_is_supported({0.30, none}, {0.294, none}, quarter, weigh));  // 2 %: not enough for a quarter
  EXPECT_TRUE(jump_is_supported({0.30, none}, {0.288, none}, quarter, weigh));   // 4 %
  // Beyond a quarter turn the loss alone never jumps, however much lower (a can lit from one end fits 51 %
  // better flipped): only the print can say which end or face is which.
  EXPECT_FALSE(jump_is_supported({0.30, none}, {0.15, none}, half, weigh));
  EXPECT_FALSE(jump_is_supported({0.30, 1.5}, {0.15, 1.8}, 0.6 * M_PI, weigh));
  // The print not weighed (min_print_significance 0): the loss alone.
  EXPECT_TRUE(jump_is_supported({0.2525, 13.2}, {0.2, 0.2}, M_PI / 6, 0.0));
  EXPECT_FALSE(jump_is_supported({0.2525, 13.2}, {0.2, 0.2}, half, 0.0));
  // A lower loss alone never jumps to a candidate whose print does not register: a real camera's mustard bottle,
  // its colour 3 px off its depth, registers at -0.7 sigma at the truth and -1.6 at half a turn, 7 % lower.
  EXPECT_FALSE(jump_is_supported({0.30, -0.7}, {0.279, -1.6}, half, weigh));
  EXPECT_FALSE(jump_is_supported({0.30, 0.5}, {0.20, 0.9}, M_PI / 6, weigh));
  EXPECT_TRUE(jump_is_supported({0.30, 0.5}, {0.20, 0.9}, M_PI / 6, 0.5));
}

TEST(JumpEvidence, APrintTurnIsRefusedWhereTheRegistrationFallsOrDoesNotRegister) {
  const double bar = 1.0;  // the verdict's min_print_significance
  EXPECT_TRUE(turn_is_supported(6.5, 6.4, bar));
  EXPECT_TRUE(turn_is_supported(2.0, 8.0, bar));
  EXPECT_FALSE(turn_is_supported(6.0, 4.5, bar));
  EXPECT_FALSE(turn_is_supported(6.0, std::nan(""), bar));
  EXPECT_FALSE(turn_is_supported(0.53, -0.32, bar));  // registers at neither: the turn is not the print's doing
  EXPECT_FALSE(turn_is_supported(0.2, 0.9, bar));     // better, still below the bar
  EXPECT_TRUE(turn_is_supported(std::nan(""), 1.0, bar));  // nothing measured at the result: nothing to lose
  EXPECT_TRUE(turn_is_supported(6.0, 1.0, 0.0));           // the print not weighed
}

TEST(Refiner, AResultOnABoxsBackFaceIsTurnedToTheFaceThePrintShows) {
  // A printed box started on its back face: silhouette and depth fit it as well as the truth. Without the scan
  // (one iteration: it never comes), only the result's shape-equivalent turns weighed by the print find the
  // front; with the print not weighed (min_print_significance 0) the result stays on the back.
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  const Mesh box = make_box(Eigen::Vector3d(0.16, 0.06, 0.21), make_label_texture(256, 7));
  Vector6d d;
  d << 0, 0, 0, 0.3, 0.5, 0.2;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.01, -0.01, 0.4));
  const Observation obs = synthesize_observation(*make_cpu_renderer(), cam, box, truth, SyntheticNoise(), 3);
  const Eigen::Matrix3d half = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Vector3d c = box.center().cast<double>();
  const Pose back = truth * Pose(half, c - half * c);
  RefinerOptions o;
  o.iterations = 1;
  o.image_scale = 1.0;
  o.retry_turn = 0;
  const RefineResult turned = Refiner(o).refine(cam, obs, box, back);
  EXPECT_LT(angle_between(turned.pose.R, truth.R), 2.0);
  EXPECT_LT((turned.pose.t - truth.t).norm(), 0.003);
  EXPECT_NEAR(degrees(turned.shape_turn), 180.0, 5.0);
  EXPECT_TRUE(turned.plausible);
  // The back face it left is its rival, which the print clearly does not prefer.
  ASSERT_TRUE(std::isfinite(turned.rival_print));
  EXPECT_LT(turned.rival_print + kClearPrint, turned.print.significance());
  test::expect_within_plan(turned, o, "turned");
  EXPECT_GT(turned.stage_evaluations[size_t(RefineStage::kWeighShapeTurns)], kMaxShapeTurns / 2);
  // Scoring the start (no iteration) leaves it as it was: no turn is weighed, nothing is aligned.
  RefinerOptions scored = o;
  scored.iterations = 0;
  const RefineResult start = Refiner(scored).refine(cam, obs, box, back);
  EXPECT_EQ(start.pose.R, back.R);
  EXPECT_EQ(start.pose.t, back.t);
  test::expect_within_plan(start, scored, "scored");
  o.min_print_significance = 0;
  const RefineResult kept = Refiner(o).refine(cam, obs, box, back);
  EXPECT_GT(angle_between(kept.pose.R, truth.R), 170.0);
  EXPECT_EQ(kept.shape_turn, 0.0);
  // With RGB alone nothing holds the other degrees of freedom while it converges from a turn: not weighed.
  o.min_print_significance = RefinerOptions().min_print_significance;
  Observation rgb_only = obs;
  rgb_only.depth = cv::Mat();
  rgb_only.mask = cv::Mat();
  EXPECT_EQ(Refiner(o).refine(cam, rgb_only, box, back).shape_turn, 0.0);
  // From the truth, no turn is preferred.
  o.min_print_significance = RefinerOptions().min_print_significance;
  const RefineResult right = Refiner(o).refine(cam, obs, box, truth);
  EXPECT_EQ(right.shape_turn, 0.0);
  EXPECT_LT(angle_between(right.pose.R, truth.R), 1.0);
  EXPECT_FALSE(right.rival_print >= right.print.significance());  // NaN (no turn registered better) or below
  EXPECT_TRUE(right.plausible);
}
