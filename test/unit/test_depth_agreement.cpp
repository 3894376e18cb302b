// The verdict's depth evidence against the sensor's noise (depth_agreement() in verdict.hpp).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <opencv2/core.hpp>

#include "diffdope/device.hpp"
#include "diffdope/primitives.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "diffdope/verdict.hpp"

using namespace diffdope;

namespace {

/// A render of a slanted surface 1.2-1.6 m away (left to right), and an observation of it: depth noise of
/// `sigma_at_1m` growing with z^2, plus `bias` metres.
struct DepthPair {
  cv::Mat rendered, observed, object;
};

DepthPair noisy_surface(double sigma_at_1m, double bias = 0, uint64_t seed = 1) {
  DepthPair p;
  const int w = 160, h = 120;
  p.rendered = cv::Mat(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) p.rendered.at<float>(y, x) = float(1.2 + 0.4 * x / (w - 1));
  cv::Mat noise(h, w, CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
  p.observed = p.rendered + float(bias) + float(sigma_at_1m) * p.rendered.mul(p.rendered).mul(noise);
  p.object = cv::Mat(h, w, CV_8U, cv::Scalar(255));
  return p;
}

}  // namespace

TEST(DepthAgreement, MeasuresTheNoiseAndExcusesIt) {
  // A camera as noisy as a RealSense at 1.4 m (5 mm at 1 m: 7-13 mm here): a fixed 1 cm band leaves only about
  // two thirds inside; the measured noise's band keeps nearly all, and the noise is measured within 5 %.
  const DepthPair p = noisy_surface(0.005);
  const DepthAgreement fixed = depth_agreement(p.observed, p.rendered, p.object, 0.01, 0.0);
  EXPECT_LT(fixed.inliers, 0.8);
  const DepthAgreement a = depth_agreement(p.observed, p.rendered, p.object, 0.01, 0.01);
  EXPECT_NEAR(a.noise_at_1m, 0.005, 0.00025);
  EXPECT_GT(a.inliers, 0.99);
  EXPECT_EQ(a.readings, p.object.rows * p.object.cols);
  // Clean depth: the band stays at its floor.
  const DepthPair clean = noisy_surface(0.0005);
  EXPECT_GT(depth_agreement(clean.observed, clean.rendered, clean.object, 0.01, 0.01).inliers, 0.999);
}

TEST(DepthAgreement, DisagreementCountsAgainstTheBand) {
  // The whole render 6 cm in front of the readings (five times the noise at the far side): the scale leaves the
  // bias out, so it stays the noise's, and nearly every reading is outside its band.
  const DepthPair biased = noisy_surface(0.005, 0.06);
  const DepthAgreement b = depth_agreement(biased.observed, biased.rendered, biased.object, 0.01, 0.01);
  EXPECT_NEAR(b.noise_at_1m, 0.005, 0.00025);
  EXPECT_LT(b.inliers, 0.05);
  // A third of the readings on a surface 30 cm behind (a silhouette missing its object): the scale barely
  // grows, and that third is outside.
  DepthPair missed = noisy_surface(0.005);
  missed.observed.colRange(0, missed.observed.cols / 3) += 0.3f;
  const DepthAgreement m = depth_agreement(missed.observed, missed.rendered, missed.object, 0.01, 0.01);
  EXPECT_LT(m.noise_at_1m, 0.006);
  EXPECT_NEAR(m.inliers, 2.0 / 3.0, 0.02);
}

TEST(DepthAgreement, NoiseBeyondTheCapIsDisagreement) {
  // 30 mm at 1 m is three times the noisiest camera excused by default: the band stops at the cap's, a third of
  // the readings fall outside it, and the verdict's default bar is not met.
  const DepthPair p = noisy_surface(0.03);
  const DepthAgreement a = depth_agreement(p.observed, p.rendered, p.object, 0.01, RefinerOptions().max_depth_noise);
  EXPECT_NEAR(a.noise_at_1m, 0.03, 0.0015);
  EXPECT_LT(a.inliers, RefinerOptions().min_depth_inliers);
  EXPECT_GT(depth_agreement(p.observed, p.rendered, p.object, 0.01, 0.03).inliers, 0.99);
}

TEST(DepthAgreement, ReadingsOutsideTheRenderAndWithoutDepth) {
  DepthPair p = noisy_surface(0.002);
  // The render misses a quarter of the object's readings: they are outliers, not left out.
  p.rendered.rowRange(0, p.rendered.rows / 4) = 0.f;
  // Holes and invalid readings are no readings.
  p.observed.rowRange(p.observed.rows / 2, p.observed.rows / 2 + 10) = 0.f;
  p.observed.at<float>(100, 5) = std::numeric_limits<float>::quiet_NaN();
  p.observed.at<float>(100, 6) = std::numeric_limits<float>::infinity();
  p.observed.at<float>(100, 7) = -1.f;
  const DepthAgreement a = depth_agreement(p.observed, p.rendered, p.object, 0.01, 0.01);
  const int rows_seen = p.observed.rows - 10, rows_rendered = rows_seen - p.observed.rows / 4;
  EXPECT_EQ(a.readings, rows_rendered * p.observed.cols - 3);
  // (noise alone leaves 0.3 % of the rendered readings outside the band)
  EXPECT_NEAR(a.inliers, double(a.readings) / (rows_seen * p.observed.cols - 3), 5e-3);
  // Nothing rendered at all: every reading is outside; nothing observed: no evidence.
  const cv::Mat none = cv::Mat::zeros(p.rendered.size(), CV_32F);
  EXPECT_EQ(depth_agreement(p.observed, none, p.object, 0.01, 0.01).inliers, 0.0);
  const DepthAgreement empty = depth_agreement(none, p.rendered, p.object, 0.01, 0.01);
  EXPECT_EQ(empty.inliers, -1.0);
  EXPECT_EQ(empty.noise_at_1m, -1.0);
  // Mismatched sizes or types: no evidence rather than a guess.
  EXPECT_EQ(depth_agreement(p.observed, p.rendered(cv::Rect(0, 0, 10, 10)), p.object, 0.01, 0.01).inliers, -1.0);
  cv::Mat depth64;
  p.observed.convertTo(depth64, CV_64F);
  EXPECT_EQ(depth_agreement(depth64, p.rendered, p.object, 0.01, 0.01).inliers, -1.0);
}

TEST(DepthAgreement, AnObjectFarFromANoisyCameraIsJudgedByItsNoise) {
  // A printed box 1.3 m from a camera with 6 mm of noise at 1 m (10 mm there), grained as a stereo camera's. At
  // its truth the verdict measures that noise and calls the pose plausible; a fixed 1 cm band would not. A pose
  // 5 cm nearer along the line of sight keeps nearly the same outline, and its depth disagrees beyond the noise.
  const Camera cam{600, 600, 319.5, 239.5, 640, 480};
  const Mesh box = make_box(Eigen::Vector3d(0.16, 0.21, 0.06), make_label_texture(256, 5));
  Vector6d d;
  d << 0, 0, 0, 0.5, -0.6, 0.3;
  const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.02, -0.01, 1.3));
  SyntheticNoise noise;
  noise.depth_sigma_at_1m = 0.006;
  noise.depth_noise_grain_px = 1.5;
  noise.flying_pixel_fraction = 0.33;
  const Observation obs = synthesize_observation(*make_cpu_renderer(), cam, box, truth, noise, 21);
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 0;  // score the given pose itself: no scan, no retry, no print alignment, no Newton steps
  o.shape_tolerance = 0;
  o.retry_turn = 0;
  o.print_search = 0;
  o.newton_rounds = 0;
  const RefineResult right = Refiner(o).refine(cam, obs, box, truth);
  EXPECT_NEAR(right.depth_noise, 0.006, 0.0015);
  EXPECT_GT(right.depth_inliers, 0.95);
  EXPECT_TRUE(right.plausible);
  Pose nearer = truth;
  nearer.t *= (1.3 - 0.05) / 1.3;
  const RefineResult wrong = Refiner(o).refine(cam, obs, box, nearer);
  ASSERT_LT((wrong.pose.t - nearer.t).norm(), 1e-9);
  EXPECT_GT(wrong.mask_iou, o.min_mask_iou);
  EXPECT_LT(wrong.depth_inliers, 0.5);
  EXPECT_FALSE(wrong.plausible);
  // Without a mask, against the pixels derived from depth: the same.
  Observation unmasked = obs;
  unmasked.mask = cv::Mat();
  const RefineResult derived = Refiner(o).refine(cam, unmasked, box, truth);
  EXPECT_GT(derived.mask_iou, 0.9);
  EXPECT_GT(derived.depth_inliers, 0.95);
  EXPECT_TRUE(derived.plausible);
  o.max_depth_noise = 0;  // a fixed band of inlier_threshold
  const RefineResult fixed = Refiner(o).refine(cam, obs, box, truth);
  EXPECT_LT(fixed.depth_inliers, o.min_depth_inliers);
  EXPECT_FALSE(fixed.plausible);
  const RefineResult fixed_derived = Refiner(o).refine(cam, unmasked, box, truth);
  EXPECT_LT(fixed_derived.depth_inliers, o.min_depth_inliers);
  EXPECT_FALSE(fixed_derived.plausible);
}
