#pragma once
// RenderImage from a hypothesis' region buffers, shared by the CPU and CUDA backends (internal header).
#include "render/kernels/silhouette.hpp"
#include "diffdope/renderer.hpp"
#include "render/pixel_rect.hpp"

namespace diffdope {

/// Full-size images; `pre` (before blends), `post` (after) and `tri` (visible triangle, -1 = none) cover `roi`
/// row by row.
inline RenderImage make_render_image(const Camera& camera, const PixelRect& roi, const PixelAttr* pre,
                                     const PixelAttr* post, const int* tri) {
  RenderImage img;
  img.roi = cv::Rect(roi.x0, roi.y0, roi.width(), roi.height());
  img.color = cv::Mat::zeros(camera.height, camera.width, CV_32FC3);
  img.depth = cv::Mat::zeros(camera.height, camera.width, CV_32FC1);
  img.coverage = cv::Mat::zeros(camera.height, camera.width, CV_32FC1);
  img.triangle = cv::Mat(camera.height, camera.width, CV_32SC1, cv::Scalar(-1));
  for (int y = roi.y0; y < roi.y1; ++y)
    for (int x = roi.x0; x < roi.x1; ++x) {
      const int i = (y - roi.y0) * roi.width() + (x - roi.x0);
      const PixelAttr& a = post[i];
      img.color.at<cv::Vec3f>(y, x) = cv::Vec3f(a.c[0], a.c[1], a.c[2]);
      img.coverage.at<float>(y, x) = a.cov;
      img.depth.at<float>(y, x) = tri[i] >= 0 ? pre[i].d : 0.f;
      img.triangle.at<int>(y, x) = tri[i];
    }
  return img;
}

}  // namespace diffdope
