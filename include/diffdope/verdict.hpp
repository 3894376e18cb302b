#pragma once
// Evidence for the refiner's verdict that a pose is right, beyond how well its silhouette and depth fit: whether
// the object's print lines up with the image's.
#include "diffdope/refine_tuning.hpp"
#include <limits>
#include <opencv2/core.hpp>

namespace diffdope {

/// How the print of a render lines up with the image's. Both sides are compared as texture gradients (Sobel of
/// log grey, observed_texture(): a light's strength and colour leave them alone) over the object's interior
/// (silhouette edges excluded: they fit whenever the shape fits), by normalised cross-correlation at the
/// render's own position and shifted by up to `radius` pixels.
struct PrintRegistration {
  double ncc = -1;   // correlation at the render's position, in [-1, 1]; -1 when not measurable
  /// The best correlation over shifts of up to `radius` pixels, and that shift (image minus render, pixels): a
  /// print that sits elsewhere in the image than in the render (a wrong turn of a bottle, a mug's handle side)
  /// shows as a clearly better correlation away from zero.
  double best_ncc = -1;
  int best_dx = 0, best_dy = 0;
  /// The correlation's spread over the shifts at least radius / 2 away (the chance level of this print).
  double far_mean = 0, far_std = 0;
  int pixels = 0;    // interior pixels compared
  /// RMS texture gradient of the render over the interior: how much print the model has there (a plain model:
  /// ~0, and nothing to register).
  double render_contrast = 0;
  /// How far the correlation at the render's position stands above this print's chance level, in standard
  /// deviations of the far shifts' correlations; NaN when not measured.
  double significance() const;
};


/// `observed_rgb`, `rendered_rgb`: CV_32FC3 of one size (the render premultiplied by coverage); `interior`:
/// CV_8U, nonzero where both the render covers the object fully and the observation shows it (the caller's
/// choice: eroded coverage ∩ observed mask). Fewer than `min_pixels` interior pixels, or a print without
/// contrast on either side (render_contrast < kMinPrintContrast), give ncc = -1.
PrintRegistration register_print(const cv::Mat& observed_rgb, const cv::Mat& rendered_rgb, const cv::Mat& interior,
                                 int radius = 8, double epsilon = 0.03, int min_pixels = 50);

/// How an observed depth agrees with a render, judged against the sensor's own noise. Depth noise grows with z^2
/// (stereo and structured light: sigma(z) = sigma1 z^2). sigma1 is measured per image from the residuals
/// observed - rendered over the object's readings: 1.4826 x the median of |residual - their median| / z^2 (z the
/// render's depth), then again over the readings within the band that gives. The median leaves a bias out of
/// the scale, and the second round the readings far off (a wrong silhouette's misses): disagreement counts
/// against the band, the noise widens it. A reading is an inlier within max(min_band, kDepthNoiseBand x
/// min(sigma1, max_noise_at_1m) x z^2) of the render: never tighter than min_band (a mesh's own error, the depth's
/// quantisation), and never wider than the noisiest camera excused allows.
struct DepthAgreement {
  /// Fraction of the object's observed readings within the band of the render, in [0, 1] (a reading where the
  /// render has no depth is outside); -1 without observed readings.
  double inliers = -1;
  double noise_at_1m = -1;  // sigma1 as measured (metres at 1 m), before the cap; -1 without readings
  int readings = 0;         // the object's pixels with both an observed and a rendered depth (sigma1's sample)
};


/// `observed`, `rendered`: CV_32F depth (metres; <= 0 or NaN: no reading); `object`: CV_8U, nonzero where the
/// object is (observed mask, derived pixels, or the render's coverage). min_band, max_noise_at_1m in metres.
DepthAgreement depth_agreement(const cv::Mat& observed, const cv::Mat& rendered, const cv::Mat& object,
                               double min_band, double max_noise_at_1m);

/// What the verdict weighs; each is optional.
struct VerdictEvidence {
  double mask_iou = -1;       // -1: no observed mask
  double depth_inliers = -1;  // -1: no depth
  double print_significance = std::numeric_limits<double>::quiet_NaN();  // NaN: no print measured
  /// The print's significance at the pose's best-registering shape-equivalent turn (a box's back face, a can's
  /// far end), converged from; NaN: not measured.
  double rival_print_significance = std::numeric_limits<double>::quiet_NaN();
};

struct Verdict {
  /// In [0, 1]: the weakest of the evidence's scores, each 0.5 at its threshold (1 = perfect: IoU or inlier
  /// fraction 1; a print significance far above its threshold, z / (z + threshold)). 0 without evidence.
  double confidence = 0;
  /// Some evidence was weighed. Without any (colour alone, no mask, a model without print) nothing can judge
  /// the pose, and it is not called plausible.
  bool judged = false;
  bool plausible = false;  // judged, and every available evidence passes its threshold
};


/// Thresholds as in RefinerOptions: min_mask_iou, min_depth_inliers (fractions in [0, 1]) and
/// min_print_significance (standard deviations; 0 = the print is not weighed). A print below its bar contradicts
/// the pose. One that lines up, but less than clearly (z < kClearPrint), raises the shape's thresholds t towards
/// 1: to t + (1 - t) / 2 at the bar, t at kClearPrint, linearly between (a weak print leaves more to the shape).
/// A rival turn whose print registers at least as well (and above the bar) contradicts the pose: shape and depth
/// cannot tell the two apart, and the print does not prefer this one.
Verdict judge(const VerdictEvidence& e, double min_mask_iou, double min_depth_inliers, double min_print_significance);

}  // namespace diffdope
