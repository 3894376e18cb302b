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

DepthAgreement depth_agreement(const cv::Mat& observed, const cv::Mat& rendered, const cv::Mat& object,
                               double min_band, double max_noise_at_1m) {
  DepthAgreement out;
  if (observed.empty() || observed.size() != rendered.size() || observed.size() != object.size() ||
      observed.type() != CV_32F || rendered.type() != CV_32F || object.type() != CV_8U)
    return out;
  std::vector<float> residual, z2;  // observed - rendered (metres) and z^2, where both have a depth
  long unrendered = 0;  // observed readings of the object where the render has none: outliers
  for (int y = 0; y < observed.rows; ++y) {
    const float* o = observed.ptr<float>(y);
    const float* r = rendered.ptr<float>(y);
    const uchar* m = object.ptr<uchar>(y);
    for (int x = 0; x < observed.cols; ++x) {
      if (!m[x] || !(o[x] > 0.f) || !std::isfinite(o[x])) continue;
      if (!(r[x] > 0.f)) {
        ++unrendered;
        continue;
      }
      residual.push_back(o[x] - r[x]);
      z2.push_back(r[x] * r[x]);
    }
  }
  out.readings = int(residual.size());
  if (residual.empty()) {
    if (unrendered > 0) out.inliers = 0;
    return out;
  }
  const auto median = [](std::vector<float> v) {
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return double(v[v.size() / 2]);
  };
  // The median absolute deviation of the residuals about their median, each over its z^2; then again over the
  // readings within the band that gives: readings far off (a silhouette's misses, all on one side) move the
  // first median and widen the first scale (by 2x with a third of them); once left out, the scale is the noise's.
  std::vector<size_t> kept(residual.size());
  for (size_t i = 0; i < kept.size(); ++i) kept[i] = i;
  std::vector<float> values, deviation;
  for (int round = 0; round < 2; ++round) {
    values.clear();
    for (size_t i : kept) values.push_back(residual[i]);
    const double centre = median(values);
    deviation.clear();
    for (size_t i : kept) deviation.push_back(float(std::abs(residual[i] - centre) / z2[i]));
    out.noise_at_1m = 1.4826 * median(deviation);
    std::vector<size_t> inside;
    for (size_t k = 0; k < kept.size(); ++k)
      if (deviation[k] <= kDepthNoiseBand * out.noise_at_1m) inside.push_back(kept[k]);
    if (inside.size() < kept.size() / 2 || inside.size() == kept.size()) break;
    kept.swap(inside);
  }
  const double band_at_1m = kDepthNoiseBand * std::min(out.noise_at_1m, std::max(max_noise_at_1m, 0.0));
  int inliers = 0;
  for (size_t i = 0; i < residual.size(); ++i)
    inliers += std::abs(residual[i]) < std::max(min_band, band_at_1m * z2[i]);
  out.inliers = double(inliers) / double(residual.size() + size_t(unrendered));
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
  const double rival = e.rival_print_significance;
  if (print_weighed && std::isfinite(rival) && rival >= min_print_significance)
    weigh(z > 0 ? z / (z + rival) : 0.0, z > rival);
  v.judged = std::isfinite(weakest);
  v.plausible = v.judged && passes;
  if (v.judged) v.confidence = weakest;
  return v;
}

}  // namespace diffdope
