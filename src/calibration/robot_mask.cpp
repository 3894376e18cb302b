// The robot's pixels in a capture without a mask (Calibrator::derive_mask): derive_object_pixels() about the robot
// rendered at the current estimate, its surfaces sought in the whole image (a robot fills much of it).
#include "diffdope/calibration.hpp"
#include "diffdope/object_pixels.hpp"

namespace diffdope {

cv::Mat Calibrator::derive_mask(const Mesh& posed_robot, const Camera& camera, const Observation& observed,
                                const Pose& camera_from_mount, double margin) {
  observed.validate(camera);
  if (!observed.has_depth()) throw std::invalid_argument("derive_mask: no depth image");
  if (!(margin > 0)) throw std::invalid_argument("derive_mask: the margin must be positive");
  // The robot at the estimate, full frame: what it covers and at what depth.
  ObjectPixelsOptions options;
  options.margin = margin;
  options.holes_unknown = true;  // no colour here: the sensor's dropouts are neither the robot's nor not
  return derive_object_pixels(camera, observed.depth, renderer_->render(camera, posed_robot, {camera_from_mount}),
                              options);
}

}  // namespace diffdope
