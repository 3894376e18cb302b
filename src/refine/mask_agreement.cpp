#include "diffdope/mask_agreement.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <limits>
#include <stdexcept>

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

double outline_offset(const cv::Mat& mask, const cv::Mat& reference, const cv::Mat& depth) {
  if (mask.size() != reference.size() || mask.channels() != 1 || reference.channels() != 1)
    throw std::invalid_argument("outline_offset: the mask and the reference must be single-channel images of one size");
  if (!depth.empty() && (depth.size() != mask.size() || depth.type() != CV_32FC1))
    throw std::invalid_argument("outline_offset: the depth must be a CV_32FC1 image of the mask's size");
  cv::Mat from = outline(inside(mask), false);
  if (!depth.empty()) {  // only where depth reads on both sides of the outline (no hole within a pixel)
    cv::Mat read = depth > 0.0f;
    cv::erode(read, read, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    from &= read;
  }
  const cv::Mat ref = inside(reference);
  const cv::Mat to = outline(ref, false) | outline(ref, true);
  if (cv::countNonZero(from) == 0) return std::numeric_limits<double>::quiet_NaN();
  if (cv::countNonZero(to) == 0) return std::numeric_limits<double>::infinity();
  cv::Mat distance;
  cv::distanceTransform(~to, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  // Beyond twice the cap the reference has no edge near: it ran on into a neighbour at the object's depth. Such
  // pixels say nothing about the outline; nearer ones count, up to the cap.
  const cv::Mat near = from & (distance < 2 * kOutlineOffsetCap);
  const int m = cv::countNonZero(near);
  if (m == 0) return std::numeric_limits<double>::quiet_NaN();
  cv::min(distance, kOutlineOffsetCap, distance);
  return cv::sum(distance.setTo(0, ~near))[0] / m;
}

}  // namespace diffdope
