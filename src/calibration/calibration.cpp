// Camera-to-robot calibration (calibration.hpp): captures become views of one pose for Refiner::refine_views().
#include "diffdope/calibration.hpp"

#include "diffdope/input_limits.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "base/option_range.hpp"

namespace diffdope {

RefinerOptions CalibrationOptions::default_refiner() {
  RefinerOptions o;
  o.loss.weight_rgb = 0;
  o.explore_tolerance = 0;
  o.probe_distance = 0;
  o.iterations = 200;
  o.lr_low = 0.0002;
  o.lr_high = 0.006;
  return o;
}

void CalibrationOptions::validate() const {
  refiner.validate();
  const OptionRange check{"calibration options"};
  check.above("mask_margin", mask_margin, 0, 1, " metres");
  check("passes", passes, 1, 10);
}

Calibrator::Calibrator(const CalibrationOptions& options)
    : options_((options.validate(), options)),
      refiner_(options.refiner),
      renderer_(make_cpu_renderer(options.refiner.render)) {}

cv::Mat Calibrator::derive_mask(const Mesh& posed_robot, const Camera& camera, const Observation& observed,
                                const Pose& camera_from_base) {
  observed.validate(camera);
  if (!observed.has_depth()) throw std::invalid_argument("derive_mask: no depth image");
  // The robot at the guess, full frame (what it covers, and at what depth).
  const RenderImage img = renderer_->render(camera, posed_robot, {camera_from_base})[0];
  cv::Mat covered = img.coverage >= 0.5f;
  if (cv::countNonZero(covered) == 0) return cv::Mat::zeros(camera.height, camera.width, CV_32F);
  double z_near = 0;
  {
    cv::Mat d = img.depth.clone();
    d.setTo(std::numeric_limits<float>::infinity(), ~covered);
    cv::minMaxLoc(d, &z_near);
  }
  const double margin = options_.mask_margin;
  const int radius = std::clamp(int(std::ceil(margin * std::max(camera.fx, camera.fy) / std::max(z_near, 0.05))), 1, 200);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1));
  cv::Mat nearest = img.depth.clone(), farthest = img.depth.clone();
  nearest.setTo(std::numeric_limits<float>::infinity(), ~covered);
  cv::erode(nearest, nearest, kernel);     // smallest robot depth around each pixel
  cv::dilate(farthest, farthest, kernel);  // largest
  const cv::Mat d = observed.depth;
  cv::Mat mask = (d > 0) & (d >= nearest - margin) & (d <= farthest + margin) & (farthest > 0);
  cv::Mat out;
  mask.convertTo(out, CV_32F, 1.0 / 255.0);
  return out;
}

CalibrationResult Calibrator::calibrate(const RobotModel& robot, const std::vector<CalibrationCapture>& captures,
                                        const Pose& initial) {
  const auto start = std::chrono::steady_clock::now();
  if (captures.empty()) throw std::invalid_argument("calibrate: no capture");
  if (captures.size() > size_t(input_limits::kMaxCaptures))
    throw std::invalid_argument("calibrate: " + std::to_string(captures.size()) + " captures; at most " +
                                std::to_string(input_limits::kMaxCaptures) + " (input_limits.hpp)");
  if (!initial.is_valid(1e-4)) throw std::invalid_argument("calibrate: the initial transform is not a valid pose");
  std::vector<Mesh> posed;
  posed.reserve(captures.size());
  std::vector<RefineView> views;
  std::vector<bool> derived;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const CalibrationCapture& c : captures) {
    const std::string who = "capture '" + c.name + "': ";
    try {
      c.observed.validate(c.camera);
      if (!c.observed.has_depth()) throw std::invalid_argument("no depth image (calibration needs depth)");
      posed.push_back(merge_meshes(robot.posed_visuals(c.joint_positions), robot.name() + " at " + c.name));
    } catch (const std::exception& e) {
      throw std::invalid_argument(who + e.what());
    }
    centre += posed.back().center();
  }
  const bool with_masks = captures.front().observed.has_mask();
  for (size_t k = 0; k < captures.size(); ++k) {
    const CalibrationCapture& c = captures[k];
    if (c.observed.has_mask() != with_masks)
      throw std::invalid_argument("calibrate: either every capture has a mask or none (capture '" + c.name + "')");
    RefineView v{c.camera, c.observed, &posed[k]};
    if (!with_masks) {
      v.observed.mask = derive_mask(posed[k], c.camera, c.observed, initial);
      if (cv::countNonZero(v.observed.mask) == 0)
        throw std::invalid_argument("capture '" + c.name +
                                    "': no observed depth near the robot at the initial guess (is it in view?)");
    }
    views.push_back(v);
    derived.push_back(!with_masks);
  }
  centre /= double(captures.size());
  CalibrationResult out;
  out.initial_camera_from_base = initial;
  Pose from = initial;
  for (int pass = 0; pass < options_.passes; ++pass) {
    refiner_.on_iteration = nullptr;
    if (on_iteration)
      refiner_.on_iteration = [this, pass](int k, int total, double loss) { on_iteration(pass, k, total, loss); };
    out.refine = refiner_.refine_views(views, {from}, centre);
    if (!out.refine.error.empty()) throw std::invalid_argument("calibrate: " + out.refine.error);
    from = out.refine.pose;
    ++out.passes;
  }
  refiner_.on_iteration = nullptr;
  out.camera_from_base = out.refine.pose;
  out.plausible = out.refine.plausible;
  out.confidence = out.refine.confidence;
  // Per capture: the refiner's scores and the median depth residual at the result.
  const double scale = refiner_.options().image_scale;
  for (size_t k = 0; k < captures.size(); ++k) {
    CaptureResidual r;
    r.name = captures[k].name;
    r.derived_mask = derived[k];
    if (k < out.refine.view_scores.size()) {
      r.loss = out.refine.view_scores[k].loss;
      r.mask_iou = out.refine.view_scores[k].mask_iou;
      r.depth_inliers = out.refine.view_scores[k].depth_inliers;
    } else {  // one capture: the result's own scores
      r.loss = out.refine.loss.total;
      r.mask_iou = out.refine.mask_iou;
      r.depth_inliers = out.refine.depth_inliers;
    }
    const Camera cam = scale == 1.0 ? views[k].camera : views[k].camera.scaled(scale);
    const Observation obs = scale == 1.0 ? views[k].observed : views[k].observed.resized(cam);
    const RenderImage img = renderer_->render(cam, posed[k], {out.camera_from_base})[0];
    std::vector<float> diffs;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const float o = obs.depth.at<float>(y, x), d = img.depth.at<float>(y, x);
        if (o > 0 && d > 0 && obs.mask.at<float>(y, x) >= 0.5f && img.coverage.at<float>(y, x) >= 0.999f)
          diffs.push_back(std::abs(o - d));
      }
    if (!diffs.empty()) {
      std::nth_element(diffs.begin(), diffs.begin() + long(diffs.size() / 2), diffs.end());
      r.depth_median_mm = 1e3 * diffs[diffs.size() / 2];
    }
    out.captures.push_back(r);
  }
  out.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return out;
}

std::string easy_handeye_yaml(const Pose& base_from_camera, const std::string& base, const std::string& camera) {
  const auto q = base_from_camera.quaternion_xyzw();
  std::ostringstream y;
  y.precision(9);
  y << "# diffdope_ros calibration: the camera's pose in the robot base frame (easy_handeye's layout, eye on base).\n"
    << "eye_on_hand: false\nrobot_base_frame: " << base << "\ntracking_base_frame: " << camera
    << "\ntransformation:\n  x: " << base_from_camera.t.x() << "\n  y: " << base_from_camera.t.y()
    << "\n  z: " << base_from_camera.t.z() << "\n  qx: " << q[0] << "\n  qy: " << q[1] << "\n  qz: " << q[2]
    << "\n  qw: " << q[3] << "\n";
  return y.str();
}

std::string static_transform_launch(const Pose& base_from_camera, const std::string& base, const std::string& camera) {
  const auto q = base_from_camera.quaternion_xyzw();
  std::ostringstream l;
  l.precision(9);
  l << "<!-- diffdope_ros calibration: the calibrated camera (" << camera << ") in the robot base frame (" << base
    << ").\n     If your camera driver already publishes a parent of " << camera
    << " (e.g. camera_link), publish the\n     transform to that parent instead (compose with the driver's "
    << "camera_link -> optical transform). -->\n<launch>\n  <node pkg=\"tf2_ros\" type=\"static_transform_publisher\" "
    << "name=\"diffdope_camera_calibration\"\n        args=\"" << base_from_camera.t.x() << " " << base_from_camera.t.y()
    << " " << base_from_camera.t.z() << " " << q[0] << " " << q[1] << " " << q[2] << " " << q[3] << " " << base << " "
    << camera << "\"/>\n</launch>\n";
  return l.str();
}

}  // namespace diffdope
