// One observed mask split among the instances of an object (instance_masks.hpp).
#include "diffdope/instance_masks.hpp"

#include <opencv2/imgproc.hpp>

#include <cmath>

namespace diffdope {

std::vector<cv::Mat> split_mask_among_instances(const cv::Mat& mask, const Camera& camera, const Mesh& mesh,
                                                const std::vector<Pose>& starts, double grow) {
  cv::Mat single = mask;
  if (mask.channels() > 1) cv::extractChannel(mask, single, 0);
  const cv::Mat on = single != 0;
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(on, labels, stats, centroids, 8, CV_32S);
  const cv::Rect frame(0, 0, mask.cols, mask.rows);
  std::vector<cv::Rect> boxes;
  std::vector<cv::Point2d> centres;
  for (const Pose& start : starts) {
    const Eigen::AlignedBox2d b = camera.project_bounds(mesh.bbox_corners(start), 1e-3);
    if (b.isEmpty()) {  // (behind the camera: the refiner refuses it anyway)
      boxes.emplace_back();
      centres.emplace_back(-1e9, -1e9);
      continue;
    }
    const Eigen::Vector2d g = grow * b.sizes();
    boxes.push_back(cv::Rect(cv::Point(int(std::floor(b.min().x() - g.x())), int(std::floor(b.min().y() - g.y()))),
                             cv::Point(int(std::ceil(b.max().x() + g.x())) + 1, int(std::ceil(b.max().y() + g.y())) + 1)) &
                    frame);
    centres.emplace_back(b.center().x(), b.center().y());
  }
  // Pixels of each component inside each instance's box.
  std::vector<std::vector<int>> inside(starts.size(), std::vector<int>(size_t(count), 0));
  for (size_t k = 0; k < boxes.size(); ++k) {
    const cv::Rect& r = boxes[k];
    for (int y = r.y; y < r.y + r.height; ++y) {
      const int* row = labels.ptr<int>(y);
      for (int x = r.x; x < r.x + r.width; ++x) ++inside[k][size_t(row[x])];
    }
  }
  // A component in one box is that instance's; one in several (instances whose images touch) is shared pixel
  // by pixel: each to the nearest centre among the boxes holding it, else among the boxes the component reaches.
  std::vector<int> owner(size_t(count), -1);
  std::vector<bool> shared(size_t(count), false);
  for (int c = 1; c < count; ++c)
    for (size_t k = 0; k < starts.size(); ++k) {
      if (inside[k][size_t(c)] == 0) continue;
      const int o = owner[size_t(c)];
      if (o >= 0) shared[size_t(c)] = true;
      if (o < 0 || inside[k][size_t(c)] > inside[size_t(o)][size_t(c)]) owner[size_t(c)] = int(k);
    }
  std::vector<cv::Mat> out;
  for (size_t k = 0; k < starts.size(); ++k) out.push_back(cv::Mat::zeros(mask.rows, mask.cols, CV_32F));
  for (int y = 0; y < mask.rows; ++y) {
    const int* row = labels.ptr<int>(y);
    for (int x = 0; x < mask.cols; ++x) {
      const int c = row[x];
      if (c == 0 || owner[size_t(c)] < 0) continue;
      int k = owner[size_t(c)];
      if (shared[size_t(c)]) {  // nearest centre among the boxes holding the pixel, else among the component's
        double best = -1;
        bool held = false;
        for (size_t j = 0; j < boxes.size(); ++j) {
          if (inside[j][size_t(c)] == 0) continue;
          const bool holds = boxes[j].contains(cv::Point(x, y));
          const double d = cv::norm(centres[j] - cv::Point2d(x, y));
          if ((holds && !held) || (holds == held && (best < 0 || d < best))) best = d, k = int(j), held = holds;
        }
      }
      out[size_t(k)].at<float>(y, x) = 1.f;
    }
  }
  return out;
}

}  // namespace diffdope
