#pragma once
// Per-hypothesis region of interest, shared by the CPU and CUDA backends (internal header).
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

/// Pixel rectangle [x0, x1) x [y0, y1).
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int width() const { return x1 - x0; }
  int height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
};

inline PixelRect unite(const PixelRect& a, const PixelRect& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

/// Bounding box of the observed mask's nonzero pixels; the whole image when there is no mask and S is then
/// implicitly 1 everywhere (`no_mask_means_everywhere`), else empty.
inline PixelRect mask_box(const cv::Mat& mask, int width, int height, bool no_mask_means_everywhere) {
  if (mask.empty()) return no_mask_means_everywhere ? PixelRect{0, 0, width, height} : PixelRect{};
  cv::Mat nz;
  cv::compare(mask, 0.0, nz, cv::CMP_GT);
  const cv::Rect r = cv::boundingRect(nz);
  return {r.x, r.y, r.x + r.width, r.y + r.height};
}

/// The pixels a hypothesis can touch: the projected model box united with the observed mask's box, plus a
/// margin, clipped to the image; the whole image when `use_roi` is false.
inline PixelRect hypothesis_roi(const Camera& camera, const Mesh& mesh, const Pose& pose, double near_z,
                                const PixelRect& mask_box, int margin, bool use_roi) {
  if (!use_roi) return {0, 0, camera.width, camera.height};
  PixelRect model{0, 0, camera.width, camera.height};  // unbounded projection (box reaches the near plane)
  const Eigen::AlignedBox2d b = camera.project_bounds(mesh.bbox_corners(pose), near_z);
  if (!b.isEmpty()) {
    const Eigen::Vector2d lo = b.min().cwiseMax(-1e6), hi = b.max().cwiseMin(1e6);
    model = {static_cast<int>(std::floor(lo.x())), static_cast<int>(std::floor(lo.y())),
             static_cast<int>(std::ceil(hi.x())) + 1, static_cast<int>(std::ceil(hi.y())) + 1};
  }
  PixelRect roi = unite(model, mask_box);
  roi = {std::max(0, roi.x0 - margin), std::max(0, roi.y0 - margin), std::min(camera.width, roi.x1 + margin),
         std::min(camera.height, roi.y1 + margin)};
  if (roi.empty()) roi = {0, 0, 1, 1};
  return roi;
}

}  // namespace diffdope
