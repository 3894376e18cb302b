// The verdict's evidence (verdict.hpp).
#include "diffdope/verdict.hpp"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "diffdope/observation.hpp"

namespace diffdope {

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
  const double c0 = ncc_at(0, 0);
  if (c0 < -1.5) return out;  // no contrast: nothing to register
  out.ncc = c0;
  double best = -1, sum = 0;
  int n = 0;
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx) {
      if (std::max(std::abs(dx), std::abs(dy)) != radius) continue;
      const double c = ncc_at(dx, dy);
      best = std::max(best, c);
      sum += c;
      ++n;
    }
  out.best_shifted = best;
  out.ring_mean = n ? sum / n : -1;
  return out;
}

}  // namespace diffdope
