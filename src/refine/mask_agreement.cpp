#include "diffdope/mask_agreement.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace diffdope {
namespace {

cv::Mat inside(const cv::Mat& m) {
  cv::Mat in;
  if (m.depth() == CV_8U) in = m >= 128;
  else cv::compare(m, 0.5, in, cv::CMP_GE);
  return in;
}

// The pixels of `in` with a 4-neighbour outside it, or (outer) the pixels outside with a 4-neighbour in it. The
// image's border is no outline: there the frame cut the set.
cv::Mat outline(const cv::Mat& in, bool outer) {
  const cv::Mat cross = cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3));
  cv::Mat edge;
  if (outer) {
    cv::dilate(in, edge, cross);
    edge &= ~in;
  } else {
    cv::erode(in, edge, cross, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    edge = in & ~edge;
  }
  if (edge.rows > 0 && edge.cols > 0) {
    edge.row(0).setTo(0), edge.row(edge.rows - 1).setTo(0);
    edge.col(0).setTo(0), edge.col(edge.cols - 1).setTo(0);
  }
  return edge;
}

}  // namespace

namespace {

void check_images(const cv::Mat& mask, const cv::Mat& reference, const char* what) {
  if (mask.size() != reference.size() || mask.channels() != 1 || reference.channels() != 1)
    throw std::invalid_argument(std::string(what) +
                                ": the mask and the reference must be single-channel images of one size");
}

// The distance (pixels) of every pixel from the reference's outline; empty when it has none.
cv::Mat distance_to_outline(const cv::Mat& reference) {
  const cv::Mat ref = inside(reference);
  const cv::Mat to = outline(ref, false) | outline(ref, true);
  if (cv::countNonZero(to) == 0) return cv::Mat();
  cv::Mat distance;
  cv::distanceTransform(~to, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  return distance;
}

// Beyond twice the cap the reference has no edge near: it ran on into a neighbour at the object's depth. Such
// outline pixels say nothing about the outline; nearer ones count.
std::vector<cv::Point> counted(const cv::Mat& from, const cv::Mat& distance) {
  std::vector<cv::Point> points;
  cv::findNonZero(from & (distance < 2 * kOutlineOffsetCap), points);
  return points;
}

// The mean distance, each capped, of `points` moved by (dx, dy); those moved off the image do not count.
double offset_at(const std::vector<cv::Point>& points, const cv::Mat& distance, int dx, int dy) {
  double sum = 0;
  int m = 0;
  for (const cv::Point& p : points) {
    const int x = p.x + dx, y = p.y + dy;
    if (x < 0 || y < 0 || x >= distance.cols || y >= distance.rows) continue;
    sum += std::min(double(distance.at<float>(y, x)), kOutlineOffsetCap), ++m;
  }
  return m == 0 ? std::numeric_limits<double>::quiet_NaN() : sum / m;
}

}  // namespace

double outline_offset(const cv::Mat& mask, const cv::Mat& reference, const cv::Mat& depth) {
  check_images(mask, reference, "outline_offset");
  if (!depth.empty() && (depth.size() != mask.size() || depth.type() != CV_32FC1))
    throw std::invalid_argument("outline_offset: the depth must be a CV_32FC1 image of the mask's size");
  cv::Mat from = outline(inside(mask), false);
  if (!depth.empty()) {  // only where depth reads on both sides of the outline (no hole within a pixel)
    cv::Mat read = depth > 0.0f;
    cv::erode(read, read, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    from &= read;
  }
  if (cv::countNonZero(from) == 0) return std::numeric_limits<double>::quiet_NaN();
  const cv::Mat distance = distance_to_outline(reference);
  if (distance.empty()) return std::numeric_limits<double>::infinity();
  return offset_at(counted(from, distance), distance, 0, 0);
}

OutlineShift best_outline_shift(const cv::Mat& mask, const cv::Mat& reference, int max_shift) {
  check_images(mask, reference, "best_outline_shift");
  if (max_shift < 0) throw std::invalid_argument("best_outline_shift: max_shift must be >= 0");
  OutlineShift best;
  const cv::Mat distance = distance_to_outline(reference);
  if (distance.empty()) return best;
  // The pixels that count are those that count unmoved: a shift that carries part of a grown outline beyond
  // twice the cap must not leave it out.
  const std::vector<cv::Point> points = counted(outline(inside(mask), false), distance);
  // Nearer shifts first, so that of equal offsets the smallest shift wins.
  std::vector<cv::Point> shifts;
  for (int dy = -max_shift; dy <= max_shift; ++dy)
    for (int dx = -max_shift; dx <= max_shift; ++dx)
      if (dx * dx + dy * dy <= max_shift * max_shift) shifts.emplace_back(dx, dy);
  std::stable_sort(shifts.begin(), shifts.end(),
                   [](cv::Point a, cv::Point b) { return a.dot(a) < b.dot(b); });
  for (const cv::Point& s : shifts) {
    const double offset = offset_at(points, distance, s.x, s.y);
    if (offset < best.offset || std::isnan(best.offset)) best = {double(s.x), double(s.y), offset};
  }
  return best;
}

}  // namespace diffdope
