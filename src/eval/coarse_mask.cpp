// coarse_mask() (coarse_mask.hpp).
#include "diffdope/coarse_mask.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <vector>

namespace diffdope {

cv::Mat coarse_mask(const cv::Mat& exact, uint64_t seed, const CoarseMaskModel& model) {
  if (exact.empty()) throw std::invalid_argument("coarse_mask: empty mask image");
  cv::Mat on;
  if (exact.channels() != 1) throw std::invalid_argument("coarse_mask: the mask must have one channel");
  cv::compare(exact, 0, on, cv::CMP_NE);
  cv::Mat out = cv::Mat::zeros(exact.size(), CV_32F);
  const int area = cv::countNonZero(on);
  if (area == 0) return out;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);

  // Signed distance to the outline (positive inside), so that the outline can be moved by any field.
  cv::Mat inside, outside;
  cv::distanceTransform(on, inside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  cv::distanceTransform(~on, outside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  cv::Mat signed_distance = inside - outside;  // CV_32F

  // Grown or shrunk as a whole, then wandering smoothly.
  const double shift = (U(rng) < 0.5 ? -1.0 : 1.0) * (model.min_shift + (model.max_shift - model.min_shift) * U(rng));
  cv::Mat wander(exact.size(), CV_32F);
  std::normal_distribution<float> N(0.f, 1.f);
  for (int y = 0; y < wander.rows; ++y)
    for (int x = 0; x < wander.cols; ++x) wander.at<float>(y, x) = N(rng);
  if (model.wander_length > 0) cv::GaussianBlur(wander, wander, cv::Size(), model.wander_length);
  cv::Scalar mean, stddev;
  cv::meanStdDev(wander, mean, stddev);
  const double amplitude = model.max_wander * U(rng);
  if (stddev[0] > 0) wander = (wander - mean[0]) * (amplitude / stddev[0]);
  cv::Mat moved = signed_distance + wander + shift;
  cv::Mat coarse = moved > 0;

  // Blobs centred on the (exact) outline: some background taken in, some of the object cut out.
  std::vector<cv::Point> outline;
  cv::Mat edge;
  cv::morphologyEx(on, edge, cv::MORPH_GRADIENT, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
  cv::findNonZero(edge, outline);
  const double size = std::sqrt(double(area));
  if (!outline.empty())
    for (const bool add : {true, false}) {
      const int n = int(std::floor(U(rng) * (model.max_blobs + 1)));
      for (int k = 0; k < n; ++k) {
        const cv::Point c = outline[size_t(U(rng) * double(outline.size())) % outline.size()];
        const int r = std::max(1, int(std::lround(size * (0.04 + 0.08 * U(rng)))));
        cv::circle(coarse, c, r, cv::Scalar(add ? 255 : 0), cv::FILLED);
      }
    }
  coarse.convertTo(out, CV_32F, 1.0 / 255.0);
  return out;
}

}  // namespace diffdope
