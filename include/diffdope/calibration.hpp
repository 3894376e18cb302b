#pragma once
// Camera-to-robot calibration from the robot's own meshes (the Diff-DOPE paper's second application): the robot,
// posed by forward kinematics at each capture's joint positions, is rendered from one unknown transform shared
// by every capture, and the refiner's descent (several views, one pose) fits it to the captures' depth (and mask,
// and rgb when the meshes carry the robot's colours). Eye to hand (a static camera watching the robot: camera <-
// base) or eye in hand (a camera riding on a link: camera <- that link; CameraMount). Units: metres, radians;
// OpenCV optical frame (x right, y down, z forward).
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "diffdope/observation.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/robot_model.hpp"

namespace diffdope {

/// One capture: an image set of the robot at known joint positions.
struct CalibrationCapture {
  std::string name;  // for messages and the residual table
  Camera camera;
  /// depth is needed; rgb optional; mask optional (nonzero = the robot). Without a mask the robot's pixels are
  /// derived from depth and the initial guess (CalibrationOptions::mask_margin).
  Observation observed;
  std::map<std::string, double> joint_positions;  // radians / metres by joint name (RobotModel::joint_names())
};

struct CalibrationOptions {
  RefinerOptions refiner = default_refiner();
  /// Descents in a row, each from the one before's result ([1, 10]): the second polishes what the first's
  /// decayed rates left (figures: docs/calibration.md).
  int passes = 2;
  /// Each later pass's learning rates relative to the pass before's: the first pass's decay continued, so the
  /// last settles where the first's rates still step across the minimum; (0, 1], 1 = every pass alike.
  double later_pass_rates = 0.1;
  /// Without a mask, an observed pixel is the robot's when its depth lies within this many metres of the depth
  /// range the robot, rendered at the initial guess, shows within this distance (projected) around it. It must
  /// exceed the initial guess's error (5 cm covers the usual hand-measured guess); (0, 1].
  double mask_margin = 0.08;
  /// Without a mask, each later pass derives the masks again about the pass before's result with this margin
  /// (metres): it must exceed that result's error at the robot plus the depth noise (one pass from 10 cm / 20
  /// degrees off leaves a few millimetres: docs/calibration.md); (0, mask_margin].
  double refined_mask_margin = 0.02;
  /// A result whose camera position is pinned down less firmly than this is not plausible: one standard
  /// deviation (metres) along the least constrained direction, from the loss's curvature at the result
  /// (CalibrationResult::position_std); the confidence is 0.5 there. (0, 1].
  double max_position_std = 0.002;
  /// The refiner's defaults for a robot: no colour term (URDF meshes seldom carry the robot's real colours), no
  /// shape scan (it is for objects); 200 iterations and no Newton steps (the later passes converge); learning rates in [0.0002, 0.006]:
  /// a robot's links are thin for its size, so the mask term's slope per metre is that of a link's width, not
  /// of the robot's diameter, and the objects' rates overshoot (measured: docs/calibration.md).
  static RefinerOptions default_refiner();
  /// Throws std::invalid_argument naming the first value outside its range.
  void validate() const;
};

/// How well the calibrated robot fits one capture (at the refiner's image scale).
struct CaptureResidual {
  std::string name;
  double loss = 0;           // the refiner's loss of this capture at the result
  double mask_iou = -1;      // rendered robot against the (given or derived) mask
  double depth_inliers = -1; // fraction of robot pixels whose depth is within the noise's band of the render
  double depth_noise_mm = -1; // the depth noise measured against the render, millimetres at 1 m (z^2 growth)
  double depth_median_mm = -1;  // median |observed - rendered| depth over robot pixels both see, millimetres
  bool derived_mask = false; // the mask came from depth and the initial guess
};

struct CalibrationResult {
  /// The calibrated transform: camera optical frame <- the frame the camera is fixed in (mount_frame: the
  /// robot's base eye to hand, CameraMount::link eye in hand).
  Pose camera_from_mount;
  Pose initial_camera_from_mount;
  std::string mount_frame;
  std::vector<CaptureResidual> captures;
  /// How firmly the captures pin the camera down: one standard deviation of the camera's position (metres) and
  /// of its rotation (radians), each along its least constrained direction, from the loss's curvature at the
  /// result (pose_curvature.hpp; a single capture leaves a direction weak). -1: not probed
  /// (refiner.probe_distance = 0), the probe left the image, or the robot is rendered nowhere (undetermined).
  double position_std = -1, rotation_std = -1;
  /// A later pass could not start: the pass before left the robot out of view. Its result is returned, not
  /// plausible, confidence 0.
  bool diverged = false;
  /// Every capture passes the refiner's verdict thresholds (mask IoU, depth inliers) and position_std is within
  /// CalibrationOptions::max_position_std.
  bool plausible = false;
  double confidence = 0;          // [0, 1]: the weakest capture's score or the position's, 0.5 at its threshold
  RefineResult refine;            // the last descent's own record (runs, rates, losses)
  int passes = 0;                 // descents run
  double time_ms = 0;
};

/// Where the camera is fixed.
struct CameraMount {
  /// Empty: eye to hand, a static camera watching the robot; the unknown is camera <- base (the URDF's root
  /// link). A link: eye in hand, the camera rides on it (the end effector, or the link its bracket is bolted to);
  /// the unknown is camera <- that link. Each capture's camera <- base then follows from its joints: the robot
  /// is posed in the link's frame, so one transform is shared by every capture as eye to hand. The links fixed
  /// to it (a gripper, the bracket) are left out of the render: they stay at one place in the image whatever
  /// the unknown, so they say nothing of it. A given mask should leave them out too.
  std::string link;
  bool eye_in_hand() const { return !link.empty(); }
  /// Throws std::invalid_argument for a link the robot does not have, or one fixed to its base (a camera there
  /// is eye to hand).
  void check(const RobotModel& robot) const;
  /// The robot's visuals at `joint_positions` in the mount's frame (the base, or the link), less the links fixed
  /// to the link. Throws as check().
  std::vector<MeshPart> posed_robot(const RobotModel& robot,
                                    const std::map<std::string, double>& joint_positions) const;
};

class Calibrator {
 public:
  explicit Calibrator(const CalibrationOptions& options = CalibrationOptions());
  const CalibrationOptions& options() const { return options_; }

  /// Calibrates from `captures` (at least one; three or more in different configurations constrain every
  /// direction) starting at `initial` (camera <- the mount's frame: the base, or the camera's link eye in hand).
  /// Throws std::invalid_argument on unusable input, naming the capture: no depth, images that do not match the
  /// camera, a joint without a position, the robot outside the image at the initial guess, a mount link the
  /// robot does not have.
  CalibrationResult calibrate(const RobotModel& robot, const std::vector<CalibrationCapture>& captures,
                              const Pose& initial, const CameraMount& mount = {});

  /// Optional progress callback: each iteration of each pass (pass from 0) with the best loss so far.
  std::function<void(int pass, int iteration, int total, double best_loss)> on_iteration;

  /// The robot's pixels in a capture without a mask (CV_32F 0/1): observed depth within `margin` (metres) of the
  /// depth range the robot, rendered at `camera_from_mount`, shows within that distance (projected) around it,
  /// less the surfaces beside it: planes of the depth out of the robot's reach (a table, a box, a wall), followed
  /// into it, except where the robot at the estimate is there at that depth.
  /// `posed_robot`: the robot merged in the mount's frame at the capture's joint positions (CameraMount).
  cv::Mat derive_mask(const Mesh& posed_robot, const Camera& camera, const Observation& observed,
                      const Pose& camera_from_mount, double margin);

 private:
  /// The refiner's options of pass `pass` (from 0): its rates, and the curvature probe's distance for a robot
  /// `robot_distance` metres from `camera`.
  RefinerOptions pass_options(int pass, double robot_distance, const Camera& camera) const;
  /// The verdict: the last descent's, and how firmly the captures pin the camera down (position_std).
  void judge_firmness(CalibrationResult& out) const;
  CalibrationOptions options_;
  Refiner refiner_;
  std::unique_ptr<Renderer> renderer_;  // single renders: derived masks, residuals (CPU)
};

/// The calibration as easy_handeye saves it: eye_on_hand, robot_base_frame (eye on base) or robot_effector_frame
/// (eye on hand: `mount_frame`), tracking_base_frame (the camera) and transformation {x, y, z, qx, qy, qz, qw},
/// the camera's pose in the mount frame.
std::string easy_handeye_yaml(const Pose& mount_from_camera, const std::string& mount_frame,
                              const std::string& camera_frame, bool eye_on_hand = false);
/// A roslaunch file publishing it with tf2_ros's static_transform_publisher (mount frame -> camera).
std::string static_transform_launch(const Pose& mount_from_camera, const std::string& mount_frame,
                                    const std::string& camera_frame);

}  // namespace diffdope
