#pragma once
// diffdope_ros/CalibrationNodelet: calibrates a static camera to a robot from the robot's own meshes
// (diffdope::Calibrator), the ROS way of easy_handeye: take samples while the robot holds still in a few
// configurations, compute, save the YAML, publish the static TF. Thin by design:
//   - inputs: depth (+ rgb, + mask) and camera_info, each kept briefly (a sample takes the newest depth and the
//     others at its stamp); /joint_states into a JointHistory (stillness around the image stamp);
//     robot_description (URDF) read once at start;
//   - services (own queue and thread: computing takes seconds, the inputs keep flowing): ~take_sample,
//     ~remove_sample, ~compute, ~save;
//   - outputs: the static TF robot base -> camera after ~compute (~publish_tf), the YAML (~output_file).
// Parameters and topics: docs/ros.md.
#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/JointState.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <deque>
#include <memory>
#include <mutex>
#include <optional>

#include "diffdope/calibration.hpp"
#include "diffdope/joint_history.hpp"
#include "diffdope_ros/ComputeCalibration.h"
#include "diffdope_ros/RemoveSample.h"
#include "diffdope_ros/error_reporter.hpp"

namespace diffdope_ros {

class CalibrationNodelet : public nodelet::Nodelet {
 public:
  ~CalibrationNodelet() override;

 private:
  void onInit() override;
  void loadRobot();

  void onDepth(const sensor_msgs::ImageConstPtr& m);
  void onRgb(const sensor_msgs::ImageConstPtr& m);
  void onMask(const sensor_msgs::ImageConstPtr& m);
  void onInfo(const sensor_msgs::CameraInfoConstPtr& m);
  void onJoints(const sensor_msgs::JointStateConstPtr& m);

  bool onTakeSample(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);
  bool onRemoveSample(RemoveSample::Request& req, RemoveSample::Response& res);
  bool onCompute(ComputeCalibration::Request&, ComputeCalibration::Response& res);
  bool onSave(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res);

  /// The initial guess, camera <- mount frame: ~initial_guess, else TF (mount -> camera frame). Throws with the
  /// reason.
  diffdope::Pose initialGuess(const std::string& camera_frame);

  // Parameters (read once).
  std::string base_frame_, camera_frame_, output_file_;
  diffdope::CameraMount mount_;  // ~mode eye_in_hand: the camera rides on ~end_effector_frame
  /// The frame the guess and the result are in: the base, or the end effector eye in hand.
  const std::string& mountFrame() const { return mount_.eye_in_hand() ? mount_.link : base_frame_; }
  bool use_rgb_ = false, use_mask_ = false, publish_tf_ = true;
  double max_interval_ = 0.02;              // s: rgb / mask / camera_info stamp vs the depth's
  double min_configuration_change_ = 0.05;  // rad: a sample must differ from the others by this (some joint)
  std::vector<double> initial_guess_;       // x y z qx qy qz qw of the camera in the mount frame, or empty
  diffdope::CalibrationOptions options_;
  diffdope::StillnessOptions stillness_;

  std::unique_ptr<diffdope::RobotModel> robot_;  // null: robot_description unusable (robot_error_ says why)
  std::string robot_error_;
  std::unique_ptr<diffdope::Calibrator> calibrator_;
  ErrorReporter errors_;

  // Inputs (input_mutex_): the newest messages of each image topic, and the joint history.
  std::mutex input_mutex_;
  std::deque<sensor_msgs::ImageConstPtr> depth_, rgb_, mask_;
  std::deque<sensor_msgs::CameraInfoConstPtr> info_;
  std::unique_ptr<diffdope::JointHistory> joints_;
  ros::Subscriber depth_sub_, rgb_sub_, mask_sub_, info_sub_, joints_sub_;

  // Samples and the result (services only: one service thread).
  struct Sample {
    diffdope::CalibrationCapture capture;
    ros::Time stamp;
  };
  std::vector<Sample> samples_;
  int samples_taken_ = 0;  // names samples uniquely
  std::optional<ComputeCalibration::Response> result_;

  ros::CallbackQueue service_queue_;
  std::unique_ptr<ros::AsyncSpinner> service_spinner_;
  ros::ServiceServer take_srv_, remove_srv_, compute_srv_, save_srv_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<tf2_ros::StaticTransformBroadcaster> static_tf_;
};

}  // namespace diffdope_ros
