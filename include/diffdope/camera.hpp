#pragma once
// Pinhole camera. Units: pixels. Integer pixel coordinates are pixel centres (OpenCV convention); the image
// spans [-0.5, width - 0.5] x [-0.5, height - 0.5]. Frame: OpenCV optical (x right, y down, z forward).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>
#include <string>

namespace diffdope {

struct Camera {
  double fx = 0, fy = 0;  // focal lengths, pixels
  double cx = 0, cy = 0;  // principal point, pixels
  int width = 0, height = 0;

  Camera() = default;
  Camera(double fx_, double fy_, double cx_, double cy_, int w, int h)
      : fx(fx_), fy(fy_), cx(cx_), cy(cy_), width(w), height(h) {}

  /// The camera of the same view resized by `scale` (e.g. 0.5): size rounded, intrinsics scaled exactly to the
  /// resulting size, keeping pixel centres consistent (u' + 0.5 = (u + 0.5) * sx).
  Camera scaled(double scale) const;
  /// The camera of the same view resized to width x height.
  Camera resized(int new_width, int new_height) const;

  /// Pixel position of a camera-frame point (z > 0).
  Eigen::Vector2d project(const Eigen::Vector3d& X) const { return {fx * X.x() / X.z() + cx, fy * X.y() / X.z() + cy}; }
  /// The camera-frame point that pixel centre (x, y) shows at depth z.
  Eigen::Vector3d back_project(double x, double y, double z) const { return {(x - cx) * z / fx, (y - cy) * z / fy, z}; }
  /// Pixel bounding box of `points` (camera frame, e.g. a model's box corners moved by its pose); empty when a
  /// point is not beyond `min_z` metres (the projection of such a set is unbounded).
  Eigen::AlignedBox2d project_bounds(const std::vector<Eigen::Vector3d>& points, double min_z) const;

  /// 3x3 intrinsic matrix K.
  Eigen::Matrix3d K() const;
  /// Throws std::invalid_argument with the reason when intrinsics or size are unusable: focal lengths in
  /// [kMinFocal, kMaxFocal] pixels and fx / fy within [1 / kMaxPixelAspect, kMaxPixelAspect] (pixels are near
  /// square; fx = 0.1 with fy = 1e7 is a typo, not a lens), width and height in [1, kMaxSize], the principal
  /// point within ten image sizes of the origin, everything finite.
  void validate() const;
  static constexpr double kMinFocal = 0.1, kMaxFocal = 1e7, kMaxPixelAspect = 10;
  static constexpr int kMaxSize = 16384;
  bool valid() const;
};

}  // namespace diffdope
