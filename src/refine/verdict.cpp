// The verdict's evidence (verdict.hpp).
#include "diffdope/verdict.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "diffdope/observation.hpp"

namespace diffdope {

double PrintRegistration::significance() const {
  if (ncc <= -1) return std::numeric_limits<double>::quiet_NaN();
  return (ncc - far_mean) / std::max(far_std, 1e-3);
}

PrintRegistration register_print(const cv::Mat& observed_rgb, const cv::Mat& rendered_rgb, const cv::Mat& interior,
                                 int radius, double epsilon, int min_pixels) {
  PrintRegistration out;
  if (observed_rgb.empty() || rendered_rgb.empty() || interior.empty() || observed_rgb.size() != rendered_rgb.size() ||
      interior.size() != observed_rgb.size())
    return out;
  const cv::Mat obs = observed_texture(observed_rgb, epsilon), ren = observed_texture(rendered_rgb, epsilon);
  // Interior pixels far enough from the border for every shift.
  std::vector<cv::Point> pts;
  for (int y = radius; y < interior.rows - radius; ++y)
    for (int x = radius; x < interior.cols - radius; ++x)
      if (interior.at<uchar>(y, x)) pts.emplace_back(x, y);
  out.pixels = int(pts.size());
  if (out.pixels < min_pixels) return out;
  const auto ncc_at = [&](int dx, int dy) {
    double sab = 0, saa = 0, sbb = 0;
    for (const cv::Point& p : pts) {
      const cv::Vec2f a = obs.at<cv::Vec2f>(p.y + dy, p.x + dx), b = ren.at<cv::Vec2f>(p);
      sab += a[0] * b[0] + a[1] * b[1];
      saa += a[0] * a[0] + a[1] * a[1];
      sbb += b[0] * b[0] + b[1] * b[1];
    }
    return saa > 1e-12 && sbb > 1e-12 ? sab / std::sqrt(saa * sbb) : -2.0;
  };
  {
    double e = 0;
    for (const cv::Point& p : pts) {
      const cv::Vec2f b = ren.at<cv::Vec2f>(p);
      e += b[0] * b[0] + b[1] * b[1];
    }
    out.render_contrast = std::sqrt(e / pts.size());
  }
  if (out.render_contrast < kMinPrintContrast) return out;  // a plain model: nothing to register
  const double c0 = ncc_at(0, 0);
  if (c0 < -1.5) return out;  // no contrast in the image: nothing to register
  out.ncc = out.best_ncc = c0;
  double sum = 0, sum2 = 0;
  int n = 0;
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx) {
      if (dx == 0 && dy == 0) continue;
      const double c = ncc_at(dx, dy);
      if (c > out.best_ncc) out.best_ncc = c, out.best_dx = dx, out.best_dy = dy;
      if (2 * std::max(std::abs(dx), std::abs(dy)) >= radius) sum += c, sum2 += c * c, ++n;
    }
  if (n > 0) {
    out.far_mean = sum / n;
    out.far_std = std::sqrt(std::max(0.0, sum2 / n - out.far_mean * out.far_mean));
  }
  return out;
}

namespace {

/// A fraction in [0, 1] against its threshold t: 0.5 at t, 1 at 1, linear on either side.
double fraction_score(double x, double t) {
  x = std::clamp(x, 0.0, 1.0);
  if (t <= 0) return 0.5 + 0.5 * x;
  if (x <= t) return 0.5 * x / t;
  return t >= 1 ? 1.0 : 0.5 + 0.5 * (x - t) / (1 - t);
}

}  // namespace

Verdict judge(const VerdictEvidence& e, double min_mask_iou, double min_depth_inliers, double min_print_significance) {
  Verdict v;
  double weakest = std::numeric_limits<double>::infinity();
  bool passes = true;
  const auto weigh = [&](double score, bool pass) {
    weakest = std::min(weakest, score);
    passes = passes && pass;
  };
  const bool print_weighed = std::isfinite(e.print_significance) && min_print_significance > 0;
  const double z = e.print_significance;
  // A print that lines up only weakly (between the bar and kClearPrint) leaves more to the shape: its thresholds
  // rise towards 1 by up to half the way, in proportion to the print's shortfall.
  const double clear = std::max(kClearPrint, min_print_significance);
  const double shortfall = print_weighed && z < clear && clear > min_print_significance
                               ? std::clamp((clear - z) / (clear - min_print_significance), 0.0, 1.0)
                               : 0.0;
  const auto raised = [&](double t) { return t + 0.5 * shortfall * (1.0 - t); };
  if (e.mask_iou >= 0) weigh(fraction_score(e.mask_iou, raised(min_mask_iou)), e.mask_iou >= raised(min_mask_iou));
  if (e.depth_inliers >= 0)
    weigh(fraction_score(e.depth_inliers, raised(min_depth_inliers)), e.depth_inliers >= raised(min_depth_inliers));
  if (print_weighed) weigh(z > 0 ? z / (z + min_print_significance) : 0.0, z >= min_print_significance);
  v.judged = std::isfinite(weakest);
  v.plausible = v.judged && passes;
  if (v.judged) v.confidence = weakest;
  return v;
}

}  // namespace diffdope
