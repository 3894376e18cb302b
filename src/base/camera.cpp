#include "diffdope/camera.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace diffdope {

Camera Camera::resized(int new_width, int new_height) const {
  const double sx = static_cast<double>(new_width) / width;
  const double sy = static_cast<double>(new_height) / height;
  return Camera(fx * sx, fy * sy, (cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5, new_width, new_height);
}

Camera Camera::scaled(double scale) const {
  if (!(scale > 0)) throw std::invalid_argument("Camera::scaled: scale must be > 0");
  const int w = std::max(1, static_cast<int>(std::lround(width * scale)));
  const int h = std::max(1, static_cast<int>(std::lround(height * scale)));
  return resized(w, h);
}

Eigen::AlignedBox2d Camera::project_bounds(const std::vector<Eigen::Vector3d>& points, double min_z) const {
  Eigen::AlignedBox2d box;  // empty
  for (const Eigen::Vector3d& X : points) {
    if (!(X.z() > min_z)) return Eigen::AlignedBox2d();
    box.extend(project(X));
  }
  return box;
}

Eigen::Matrix3d Camera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return k;
}

bool Camera::valid() const {
  return std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy) && fx >= kMinFocal &&
         fy >= kMinFocal && fx <= kMaxFocal && fy <= kMaxFocal && width > 0 && height > 0 && width <= kMaxSize &&
         height <= kMaxSize && std::abs(cx) <= 10.0 * width && std::abs(cy) <= 10.0 * height &&
         fx <= kMaxPixelAspect * fy && fy <= kMaxPixelAspect * fx;
}

void Camera::validate() const {
  if (!valid()) {
    std::ostringstream m;
    m << "camera: unusable intrinsics (fx=" << fx << ", fy=" << fy << ", cx=" << cx << ", cy=" << cy << ", " << width
      << "x" << height << "): focal lengths must be in [" << kMinFocal << ", " << kMaxFocal
      << "] pixels with fx / fy within [1/" << kMaxPixelAspect << ", " << kMaxPixelAspect << "], the size in [1, "
      << kMaxSize << "] and the principal point within 10 image sizes";
    throw std::invalid_argument(m.str());
  }
}

}  // namespace diffdope
