#pragma once
// Evidence for the refiner's verdict that a pose is right, beyond how well its silhouette and depth fit: whether
// the object's print lines up with the image's.
#include <opencv2/core.hpp>

namespace diffdope {

/// How the print of a render lines up with the image's. Both sides are compared as texture gradients (Sobel of
/// log grey, observed_texture(): a light's strength and colour leave them alone) over the object's interior
/// (silhouette edges excluded: they fit whenever the shape fits), by normalised cross-correlation at the
/// render's own position and shifted by up to `radius` pixels.
struct PrintRegistration {
  double ncc = -1;         // correlation at the render's position, in [-1, 1]; -1 when not measurable
  double best_shifted = -1;  // the highest correlation of the shifted positions (ring at Chebyshev distance radius)
  double ring_mean = -1;   // mean correlation over that ring
  int pixels = 0;          // interior pixels compared
};

/// `observed_rgb`, `rendered_rgb`: CV_32FC3 of one size (the render premultiplied by coverage); `interior`:
/// CV_8U, nonzero where both the render covers the object fully and the observation shows it (the caller's
/// choice: eroded coverage ∩ observed mask). Fewer than `min_pixels` interior pixels, or a print without
/// contrast on either side, give ncc = -1.
PrintRegistration register_print(const cv::Mat& observed_rgb, const cv::Mat& rendered_rgb, const cv::Mat& interior,
                                 int radius = 2, double epsilon = 0.03, int min_pixels = 50);

}  // namespace diffdope
