#pragma once
// Camera-to-robot calibration from the robot's own meshes (the Diff-DOPE paper's second application): the robot,
// posed by forward kinematics at each capture's joint positions, is rendered from one unknown transform
// camera <- base shared by every capture, and the refiner's descent (several views, one pose) fits it to the
// captures' depth (and mask, and rgb when the meshes carry the robot's colours). Eye-to-hand: a static camera
// watching the robot. Units: metres, radians; OpenCV optical frame (x right, y down, z forward).
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
  /// decayed rates left (generated arm, 10 cm / 20 degrees off: median 3.7 mm / 0.17 degrees of the camera's
  /// position after one pass of 300 iterations, 0.3 mm / 0.02 degrees after two; docs/calibration.md).
  int passes = 2;
  /// Without a mask, an observed pixel is the robot's when its depth lies within this many metres of the depth
  /// range the robot, rendered at the initial guess, shows within this distance (projected) around it. It must
  /// exceed the initial guess's error (5 cm covers the usual hand-measured guess); (0, 1].
  double mask_margin = 0.08;
  /// The refiner's defaults for a robot: no colour term (URDF meshes seldom carry the robot's real colours), no
  /// shape scan or curvature probe (they are for objects); 200 iterations; learning rates in [0.0002, 0.006]:
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
  double depth_inliers = -1; // fraction of robot pixels whose depth is within inlier_threshold of the render
  double depth_median_mm = -1;  // median |observed - rendered| depth over robot pixels both see, millimetres
  bool derived_mask = false; // the mask came from depth and the initial guess
};

struct CalibrationResult {
  Pose camera_from_base;          // the calibrated transform: base frame -> camera optical frame
  Pose initial_camera_from_base;
  std::vector<CaptureResidual> captures;
  bool plausible = false;         // every capture passes the refiner's verdict thresholds (mask IoU, depth inliers)
  double confidence = 0;          // [0, 1], the weakest capture's (verdict.hpp)
  RefineResult refine;            // the last descent's own record (runs, rates, losses)
  int passes = 0;                 // descents run
  double time_ms = 0;
};

class Calibrator {
 public:
  explicit Calibrator(const CalibrationOptions& options = CalibrationOptions());
  const CalibrationOptions& options() const { return options_; }

  /// Calibrates from `captures` (at least one; three or more in different configurations constrain every
  /// direction) starting at `initial` (camera <- base). Throws std::invalid_argument on unusable input, naming the
  /// capture: no depth, images that do not match the camera, a joint without a position, the robot outside the
  /// image at the initial guess.
  CalibrationResult calibrate(const RobotModel& robot, const std::vector<CalibrationCapture>& captures,
                              const Pose& initial);

  /// Optional progress callback: each iteration of each pass (pass from 0) with the best loss so far.
  std::function<void(int pass, int iteration, int total, double best_loss)> on_iteration;

  /// The robot's pixels in a capture without a mask (CV_32F 0/1): see CalibrationOptions::mask_margin.
  /// `posed_robot`: the robot merged in its base frame at the capture's joint positions.
  cv::Mat derive_mask(const Mesh& posed_robot, const Camera& camera, const Observation& observed,
                      const Pose& camera_from_base);

 private:
  CalibrationOptions options_;
  Refiner refiner_;
  std::unique_ptr<Renderer> renderer_;  // single renders: derived masks, residuals (CPU)
};

/// The calibration as easy_handeye saves it (eye on base): eye_on_hand, robot_base_frame, tracking_base_frame
/// and transformation {x, y, z, qx, qy, qz, qw}, the camera's pose in the base frame.
std::string easy_handeye_yaml(const Pose& base_from_camera, const std::string& base_frame,
                              const std::string& camera_frame);
/// A roslaunch file publishing it with tf2_ros's static_transform_publisher.
std::string static_transform_launch(const Pose& base_from_camera, const std::string& base_frame,
                                    const std::string& camera_frame);

}  // namespace diffdope
