// The verdict (verdict.hpp): the print registration test and how the evidence becomes plausible / confidence.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "diffdope/device.hpp"
#include "diffdope/pose_curvature.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "diffdope/verdict.hpp"
#include "labelled_can.hpp"

using namespace diffdope;

namespace {

/// A printed image (random blobs), lit: a gain and a smooth shading ramp (what a flat render does not have).
cv::Mat printed(int w, int h, uint32_t seed, double gain) {
  cv::Mat noise(h / 4, w / 4, CV_32FC3);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::UNIFORM, 0.1, 0.9);
  cv::Mat img;
  cv::resize(noise, img, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) img.at<cv::Vec3f>(y, x) *= float(gain * (0.7 + 0.3 * x / w));
  return img;
}

cv::Mat shifted(const cv::Mat& img, int dx, int dy) {
  cv::Mat out;
  const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, dx, 0, 1, dy);
  cv::warpAffine(img, out, M, img.size(), cv::INTER_NEAREST, cv::BORDER_REFLECT);
  return out;
}

}  // namespace

TEST(PrintRegistration, ALitImageOfTheSamePrintRegistersAtZeroAndAShiftedOneDoesNot) {
  const cv::Mat render = printed(160, 120, 3, 1.0);
  cv::Mat interior = cv::Mat::zeros(120, 160, CV_8U);
  interior(cv::Rect(30, 20, 100, 80)).setTo(1);
  const PrintRegistration same = register_print(printed(160, 120, 3, 0.6), render, interior);
  EXPECT_GT(same.ncc, 0.8);
  EXPECT_EQ(same.best_dx, 0);
  EXPECT_EQ(same.best_dy, 0);
  EXPECT_GT(same.significance(), 5.0);
  EXPECT_GT(same.render_contrast, kMinPrintContrast);
  // The print sits 5 px to the right in the image: found there, and nothing at zero.
  const PrintRegistration moved = register_print(shifted(printed(160, 120, 3, 0.6), 5, 0), render, interior);
  EXPECT_EQ(moved.best_dx, 5);
  EXPECT_EQ(moved.best_dy, 0);
  EXPECT_LT(moved.significance(), 2.0);
  EXPECT_GT(moved.best_ncc, 0.8);
  // Another print altogether: nothing registers.
  EXPECT_LT(register_print(printed(160, 120, 99, 0.6), render, interior).significance(), 3.0);
}

TEST(PrintRegistration, APlainModelOrTooFewPixelsAreNotMeasured) {
  const cv::Mat image = printed(160, 120, 3, 1.0);
  cv::Mat interior = cv::Mat::zeros(120, 160, CV_8U);
  interior(cv::Rect(30, 20, 100, 80)).setTo(1);
  const cv::Mat plain(120, 160, CV_32FC3, cv::Scalar(0.5, 0.4, 0.3));
  const PrintRegistration p = register_print(image, plain, interior);
  EXPECT_EQ(p.ncc, -1);
  EXPECT_TRUE(std::isnan(p.significance()));
  cv::Mat tiny = cv::Mat::zeros(120, 160, CV_8U);
  tiny(cv::Rect(50, 50, 5, 5)).setTo(1);
  EXPECT_EQ(register_print(image, image, tiny).ncc, -1);
  EXPECT_EQ(register_print(image, cv::Mat(), interior).ncc, -1);  // no render: nothing, no throw
}

TEST(Verdict, EachEvidenceScoresHalfAtItsThresholdAndTheWeakestDecides) {
  VerdictEvidence e;
  const Verdict none = judge(e, 0.5, 0.5, 3.0);
  EXPECT_FALSE(none.judged);  // no evidence: nothing can judge, and the pose is not called plausible
  EXPECT_FALSE(none.plausible);
  EXPECT_DOUBLE_EQ(none.confidence, 0.0);
  e.print_significance = 9.0;
  EXPECT_FALSE(judge(e, 0.5, 0.5, 0.0).judged);  // a print not weighed is no evidence
  e.print_significance = std::numeric_limits<double>::quiet_NaN();
  e.mask_iou = 0.5;
  EXPECT_DOUBLE_EQ(judge(e, 0.5, 0.5, 3.0).confidence, 0.5);
  EXPECT_TRUE(judge(e, 0.5, 0.5, 3.0).judged);
  e.mask_iou = 1.0;
  e.depth_inliers = 0.75;
  EXPECT_DOUBLE_EQ(judge(e, 0.5, 0.5, 3.0).confidence, 0.75);
  e.print_significance = 9.0;  // 9 / (9 + 3)
  Verdict v = judge(e, 0.5, 0.5, 3.0);
  EXPECT_DOUBLE_EQ(v.confidence, 0.75);
  EXPECT_TRUE(v.plausible);
  e.print_significance = 1.0;  // the print does not line up: implausible whatever the shape says
  v = judge(e, 0.5, 0.5, 3.0);
  EXPECT_FALSE(v.plausible);
  EXPECT_DOUBLE_EQ(v.confidence, 0.25);
  EXPECT_TRUE(judge(e, 0.5, 0.5, 0.0).plausible);  // 0: the print is not weighed
  e.print_significance = -2;
  EXPECT_DOUBLE_EQ(judge(e, 0.5, 0.5, 3.0).confidence, 0.0);
  e.print_significance = std::numeric_limits<double>::quiet_NaN();
  e.depth_inliers = 0.4;
  v = judge(e, 0.5, 0.5, 3.0);
  EXPECT_FALSE(v.plausible);
  EXPECT_DOUBLE_EQ(v.confidence, 0.4);
}

TEST(Verdict, TheRefinerTrustsARightPrintAndNotAWrongTurn) {
  // A labelled can seen from the side: at the truth its print lines up; turned 60 degrees about its axis (what
  // silhouette and depth cannot see) it does not, and the verdict says so although mask and depth fit.
  SyntheticNoise noise;
  noise.brightness = 0.8;
  const test::LabelledCan s = test::labelled_can(noise);
  const Camera& cam = s.cam;
  const Mesh& can = s.can;
  const Pose& truth = s.truth;
  const Observation& obs = s.obs;
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;  // score the start itself
  o.image_scale = 1.0;
  o.shape_tolerance = 0;
  const RefineResult right = Refiner(o).refine(cam, obs, can, truth);
  const Pose turned = truth * test::about_can_axis(60);
  const RefineResult wrong = Refiner(o).refine(cam, obs, can, turned);
  EXPECT_GT(right.mask_iou, 0.9);
  EXPECT_GT(wrong.mask_iou, 0.9);  // the shape fits either way
  EXPECT_GT(wrong.depth_inliers, 0.9);
  EXPECT_TRUE(right.plausible);
  EXPECT_GT(right.print.significance(), 3.0);
  EXPECT_FALSE(wrong.plausible);
  EXPECT_LT(wrong.print.significance(), 3.0);
  EXPECT_GT(right.confidence, 0.5);
  EXPECT_LT(wrong.confidence, 0.5);
}

TEST(Verdict, AnOccludedObjectAtItsTruthKeepsItsMaskIoU) {
  // A box in front hides part of the can: the can's visible mask leaves that part out, and so must the render's
  // side of the IoU wherever the observed depth shows the occluder in front (else IoU = the visible fraction).
  const test::LabelledCan s = test::labelled_can();
  const Mesh box = make_box(Eigen::Vector3d(0.05, 0.05, 0.05), make_label_texture(64, 4));
  const Pose box_pose(Eigen::Matrix3d::Identity(), s.truth.t + Eigen::Vector3d(0.03, 0.0, -0.1));
  const SyntheticScene scene =
      synthesize_scene(*make_cpu_renderer(), s.cam, {{&s.can, s.truth}, {&box, box_pose}}, SyntheticNoise(), 9);
  ASSERT_LT(scene.visible_fraction[0], 0.85);
  ASSERT_GT(scene.visible_fraction[0], 0.4);
  Observation obs;
  obs.rgb = scene.rgb;
  obs.mask = scene.visible_masks[0];
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;  // score the start itself
  o.image_scale = 1.0;
  const RefineResult rgb_only = Refiner(o).refine(s.cam, obs, s.can, s.truth);
  EXPECT_NEAR(rgb_only.mask_iou, scene.visible_fraction[0], 0.05);  // without depth the occluder is not seen
  obs.depth = scene.depth;
  const RefineResult with_depth = Refiner(o).refine(s.cam, obs, s.can, s.truth);
  EXPECT_GT(with_depth.mask_iou, 0.95);
  // A wrong pose is still told apart: moved by a third of its width, the IoU falls.
  const Pose moved(s.truth.R, s.truth.t + Eigen::Vector3d(0.025, 0, 0));
  EXPECT_LT(Refiner(o).refine(s.cam, obs, s.can, moved).mask_iou, 0.8);
}

TEST(Verdict, AWeakPrintLeavesMoreToTheShape) {
  VerdictEvidence e;
  e.mask_iou = 0.74;
  e.depth_inliers = 0.9;
  e.print_significance = 5.0;  // clear: the shape's own thresholds
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.print_significance = 1.0;  // at the bar: IoU must reach 0.75
  EXPECT_FALSE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.mask_iou = 0.76;
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
  EXPECT_DOUBLE_EQ(judge(e, 0.5, 0.5, 1.0).confidence, 0.5);  // the print's own score, 1 / (1 + 1)
  e.print_significance = 2.0;  // half way: 0.625
  e.mask_iou = 0.62;
  EXPECT_FALSE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.mask_iou = 0.63;
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.print_significance = 0.9;  // below the bar: contradicted, however well the shape fits
  e.mask_iou = e.depth_inliers = 1.0;
  EXPECT_FALSE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.print_significance = std::numeric_limits<double>::quiet_NaN();  // not measured: the shape's own thresholds
  e.mask_iou = 0.55;
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
}

TEST(Verdict, AShapeEquivalentTurnWhosePrintRegistersAsWellContradictsThePose) {
  // A box on its back face: shape and depth fit as well as on the front, and the back's print lines up clearly.
  VerdictEvidence e;
  e.mask_iou = 0.84;
  e.depth_inliers = 0.95;
  e.print_significance = 6.2;
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.rival_print_significance = 8.2;  // converged on the front, the print registers better: contradicted
  Verdict v = judge(e, 0.5, 0.5, 1.0);
  EXPECT_FALSE(v.plausible);
  EXPECT_DOUBLE_EQ(v.confidence, 6.2 / (6.2 + 8.2));
  e.rival_print_significance = 6.2;  // as well: the print does not prefer this face either
  EXPECT_FALSE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.rival_print_significance = 4.0;  // the print prefers the pose, less than clearly: plausible, less confident
  v = judge(e, 0.5, 0.5, 1.0);
  EXPECT_TRUE(v.plausible);
  EXPECT_DOUBLE_EQ(v.confidence, 6.2 / (6.2 + 4.0));
  EXPECT_LT(v.confidence, judge(VerdictEvidence{0.84, 0.95, 6.2}, 0.5, 0.5, 1.0).confidence);
  e.rival_print_significance = 8.2;
  e.print_significance = std::numeric_limits<double>::quiet_NaN();  // no print at the pose: no rival weighed
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
  e.print_significance = 6.2;
  EXPECT_TRUE(judge(e, 0.5, 0.5, 0.0).plausible);  // the print not weighed
  e.rival_print_significance = 0.5;  // a rival below the bar is no evidence against the pose
  EXPECT_TRUE(judge(e, 0.5, 0.5, 1.0).plausible);
}

TEST(Verdict, AShapeWhoseDepthDisagreesOnAFifthOfItIsContradicted) {
  // A plain can tilted in the plane of view: its outline barely changes, but its ends lie a centimetre and more
  // off the observed depth. Half the evidence agreeing is not enough by default; a fifth disagreeing contradicts.
  const test::LabelledCan s = test::labelled_can();
  const Mesh plain = make_cylinder(0.035, 0.11, 64, make_flat_texture(Eigen::Vector3f(0.6f, 0.6f, 0.6f)));
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;  // score the start itself
  o.image_scale = 1.0;
  const Eigen::Vector3d centre = s.truth * plain.center();
  const Eigen::Vector3d axis = s.truth.R * Eigen::Vector3d::UnitZ();
  Vector6d tilt = Vector6d::Zero();
  tilt.tail<3>() = 15 * M_PI / 180 * axis.cross(centre).normalized();
  const Pose tilted = twist_about(s.truth, tilt, centre);
  const RefineResult right = Refiner(o).refine(s.cam, s.obs, plain, s.truth);
  const RefineResult wrong = Refiner(o).refine(s.cam, s.obs, plain, tilted);
  EXPECT_TRUE(right.plausible);
  EXPECT_GT(wrong.mask_iou, o.min_mask_iou);  // the outline still fits
  EXPECT_GT(wrong.depth_inliers, 0.5);
  EXPECT_LT(wrong.depth_inliers, o.min_depth_inliers);
  EXPECT_FALSE(wrong.plausible);
  o.min_depth_inliers = 0.5;
  EXPECT_TRUE(Refiner(o).refine(s.cam, s.obs, plain, tilted).plausible);
}
