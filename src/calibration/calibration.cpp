// Camera-to-robot calibration (calibration.hpp): captures become views of one pose for Refiner::refine_views().
#include "diffdope/calibration.hpp"

#include "diffdope/input_limits.hpp"
#include "diffdope/object_pixels.hpp"

#include <opencv2/imgproc.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "base/option_range.hpp"

namespace diffdope {
namespace {

double millimetres_or_unknown(double metres) { return metres < 0 ? -1.0 : 1e3 * metres; }

}  // namespace

RefinerOptions CalibrationOptions::default_refiner() {
  RefinerOptions o;
  o.loss.weight_rgb = 0;
  o.shape_tolerance = 0;
  o.iterations = 200;
  o.newton_rounds = 0;  // the 200 iterations and the later passes' small rates converge
  o.derive_mask = false;  // the calibrator derives the robot's pixels itself (derive_mask()), per capture
  o.lr_low = 0.0002;
  o.lr_high = 0.006;
  // The arm spans a metre or more of depth, where a stereo camera's noise grows several times (z^2): each reading
  // weighs as its noise allows (docs/calibration.md).
  o.loss.depth_noise_power = 2;
  return o;
}

void CalibrationOptions::validate() const {
  refiner.validate();
  const OptionRange check{"calibration options"};
  check.above("mask_margin", mask_margin, 0, 1, " metres");
  check.above("refined_mask_margin", refined_mask_margin, 0, mask_margin, " metres (at most mask_margin)");
  check("passes", passes, 1, 10);
  check.above("later_pass_rates", later_pass_rates, 0, 1);
  check.above("max_position_std", max_position_std, 0, 1, " metres");
}

Calibrator::Calibrator(const CalibrationOptions& options)
    : options_((options.validate(), options)),
      refiner_(options.refiner),
      renderer_(make_cpu_renderer(options.refiner.render)) {}

void CameraMount::check(const RobotModel& robot) const {
  if (!eye_in_hand()) return;
  if (!robot.has_link(link)) throw std::invalid_argument("the robot has no link '" + link + "' to carry the camera");
  if (robot.links_fixed_to(link).count(robot.root_link()))
    throw std::invalid_argument(
        "link '" + link + "' " +
        (link == robot.root_link() ? "is the robot's base"
                                   : "is fixed to the robot's base '" + robot.root_link() + "'") +
        ": a camera there does not move with the arm (calibrate eye to hand)");
}

std::vector<MeshPart> CameraMount::posed_robot(const RobotModel& robot,
                                               const std::map<std::string, double>& joint_positions) const {
  if (!eye_in_hand()) return robot.posed_visuals(joint_positions);
  check(robot);
  std::vector<MeshPart> parts = robot.posed_visuals(joint_positions, robot.links_fixed_to(link));
  const Pose link_from_base = robot.link_poses(joint_positions).at(link).inverse();
  for (MeshPart& p : parts) p.pose = link_from_base * p.pose;
  return parts;
}

CalibrationResult Calibrator::calibrate(const RobotModel& robot, const std::vector<CalibrationCapture>& captures,
                                        const Pose& initial, const CameraMount& mount) {
  const auto start = std::chrono::steady_clock::now();
  if (captures.empty()) throw std::invalid_argument("calibrate: no capture");
  if (captures.size() > size_t(input_limits::kMaxCaptures))
    throw std::invalid_argument("calibrate: " + std::to_string(captures.size()) + " captures; at most " +
                                std::to_string(input_limits::kMaxCaptures) + " (input_limits.hpp)");
  if (!initial.is_valid(1e-4)) throw std::invalid_argument("calibrate: the initial transform is not a valid pose");
  try {
    mount.check(robot);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("calibrate: ") + e.what());
  }
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
      const std::vector<MeshPart> parts = mount.posed_robot(robot, c.joint_positions);
      if (parts.empty())
        throw std::invalid_argument("every link with a visual is fixed to the camera's link '" + mount.link +
                                    "': nothing moves in the image");
      posed.push_back(merge_meshes(parts, robot.name() + " at " + c.name));
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
    v.mask_from_depth = !with_masks;
    if (!with_masks) {
      v.observed.mask = derive_mask(posed[k], c.camera, c.observed, initial, options_.mask_margin);
      if (cv::countNonZero(v.observed.mask) == 0)
        throw std::invalid_argument("capture '" + c.name +
                                    "': no observed depth near the robot at the initial guess (is it in view?)");
    }
    views.push_back(v);
    derived.push_back(!with_masks);
  }
  centre /= double(captures.size());
  CalibrationResult out;
  out.initial_camera_from_mount = initial;
  out.mount_frame = mount.eye_in_hand() ? mount.link : robot.root_link();
  Pose from = initial;
  for (int pass = 0; pass < options_.passes; ++pass) {
    if (pass > 0 && !with_masks)  // around the pass before's result, closer: less of what stands near the robot
      for (size_t k = 0; k < captures.size(); ++k) {
        cv::Mat mask = derive_mask(posed[k], captures[k].camera, captures[k].observed, from,
                                   options_.refined_mask_margin);
        if (cv::countNonZero(mask) > 0) views[k].observed.mask = mask;
      }
    refiner_.on_iteration = nullptr;
    if (on_iteration)
      refiner_.on_iteration = [this, pass](int k, int total, double loss) { on_iteration(pass, k, total, loss); };
    RefinerOptions pass_refiner = pass_options(pass, (from * centre).norm(), captures.front().camera);
    if (!with_masks) pass_refiner.loss.weight_mask *= kDerivedMaskWeight;
    RefineResult r = refiner_.refine_views(views, {from}, centre, pass_refiner);
    if (!r.error.empty()) {
      if (pass == 0) throw std::invalid_argument("calibrate: " + r.error);
      // The pass before drove the robot out of view: its result stands, judged a divergence.
      out.diverged = true;
      break;
    }
    out.refine = std::move(r);
    from = out.refine.pose;
    ++out.passes;
  }
  refiner_.on_iteration = nullptr;
  out.camera_from_mount = out.refine.pose;
  judge_firmness(out);
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
      r.depth_noise_mm = millimetres_or_unknown(out.refine.view_scores[k].depth_noise);
    } else {  // one capture: the result's own scores
      r.loss = out.refine.loss.total;
      r.mask_iou = out.refine.mask_iou;
      r.depth_inliers = out.refine.depth_inliers;
      r.depth_noise_mm = millimetres_or_unknown(out.refine.depth_noise);
    }
    const Camera cam = scale == 1.0 ? views[k].camera : views[k].camera.scaled(scale);
    const Observation obs = scale == 1.0 ? views[k].observed : views[k].observed.resized(cam);
    const RenderImage img = renderer_->render(cam, posed[k], {out.camera_from_mount})[0];
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

RefinerOptions Calibrator::pass_options(int pass, double robot_distance, const Camera& camera) const {
  RefinerOptions o = options_.refiner;
  // Each pass continues the decay of the one before: rates later_pass_rates^pass of the first's.
  const double rate_scale = std::pow(options_.later_pass_rates, pass);
  o.lr_low *= rate_scale;
  o.lr_high *= rate_scale;
  // The curvature probe (judge_firmness) moves the robot's image by about two of the refiner's pixels at its
  // centre, at most refiner.probe_distance: the render's gradients see a silhouette move that far, not tens of
  // pixels (a camera on the hand sees links a few decimetres away).
  const double pixel = std::max(robot_distance, 0.05) / (camera.fx * o.image_scale);
  o.probe_distance = std::min(o.probe_distance, 2 * pixel);
  return o;
}

void Calibrator::judge_firmness(CalibrationResult& out) const {
  out.plausible = out.refine.plausible && !out.diverged;
  out.confidence = out.diverged ? 0.0 : out.refine.confidence;
  // No covariance (the robot rendered nowhere in the views): nothing is pinned down; position_std stays -1.
  if (!out.refine.curvature.valid || out.refine.covariance.isZero(0)) return;
  // The twist (v, w) about the pivot p moves the camera's origin, relative to the robot, by -(v + p x w).
  const Matrix6d& cov = out.refine.covariance;
  Eigen::Matrix<double, 3, 6> J;
  J << Eigen::Matrix3d::Identity(), skew(out.refine.pivot);
  const Eigen::Matrix3d position_cov = J * cov * J.transpose();
  const Eigen::Matrix3d rotation_cov = cov.bottomRightCorner<3, 3>();
  const auto largest_std = [](const Eigen::Matrix3d& c) {
    return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(c).eigenvalues()[2]));
  };
  out.position_std = largest_std(position_cov);
  out.rotation_std = largest_std(rotation_cov);
  const double ratio = out.position_std / options_.max_position_std;
  out.plausible = out.plausible && ratio <= 1;
  out.confidence = std::min(out.confidence, 1 / (1 + ratio * ratio));
}

std::string easy_handeye_yaml(const Pose& mount_from_camera, const std::string& mount, const std::string& camera,
                              bool eye_on_hand) {
  const auto q = mount_from_camera.quaternion_xyzw();
  std::ostringstream y;
  y.precision(9);
  y << "# diffdope_ros calibration: the camera's pose in the " << (eye_on_hand ? "robot's link " : "robot base frame ")
    << mount << " (easy_handeye's layout, eye on " << (eye_on_hand ? "hand" : "base") << ").\neye_on_hand: "
    << (eye_on_hand ? "true" : "false") << "\n"
    << (eye_on_hand ? "robot_effector_frame: " : "robot_base_frame: ") << mount << "\ntracking_base_frame: " << camera
    << "\ntransformation:\n  x: " << mount_from_camera.t.x() << "\n  y: " << mount_from_camera.t.y()
    << "\n  z: " << mount_from_camera.t.z() << "\n  qx: " << q[0] << "\n  qy: " << q[1] << "\n  qz: " << q[2]
    << "\n  qw: " << q[3] << "\n";
  return y.str();
}

std::string static_transform_launch(const Pose& mount_from_camera, const std::string& mount,
                                    const std::string& camera) {
  const auto q = mount_from_camera.quaternion_xyzw();
  std::ostringstream l;
  l.precision(9);
  l << "<!-- diffdope_ros calibration: the calibrated camera (" << camera << ") in the robot's frame " << mount
    << ".\n     If your camera driver already publishes a parent of " << camera
    << " (e.g. camera_link), publish the\n     transform to that parent instead (compose with the driver's "
    << "camera_link -> optical transform). -->\n<launch>\n  <node pkg=\"tf2_ros\" type=\"static_transform_publisher\" "
    << "name=\"diffdope_camera_calibration\"\n        args=\"" << mount_from_camera.t.x() << " "
    << mount_from_camera.t.y() << " " << mount_from_camera.t.z() << " " << q[0] << " " << q[1] << " " << q[2] << " "
    << q[3] << " " << mount << " " << camera << "\"/>\n</launch>\n";
  return l.str();
}

}  // namespace diffdope
