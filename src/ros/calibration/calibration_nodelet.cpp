// CalibrationNodelet (calibration_nodelet.hpp): parameters, the robot model, and the inputs it keeps for samples.
// The services: calibration_services.cpp. The calibration itself is diffdope::Calibrator; stillness is
// diffdope::JointHistory.
#include "ros/calibration/calibration_nodelet.hpp"

#include <pluginlib/class_list_macros.hpp>
#include <ros/package.h>

#include <cmath>

#include "base/option_range.hpp"
#include "diffdope_ros/conversions.hpp"

namespace diffdope_ros {
namespace {

constexpr size_t kKept = 30;  // messages kept per image topic (a second at 30 Hz)

template <class M>
void keep(std::deque<M>& q, const M& m) {
  q.push_back(m);
  while (q.size() > kKept) q.pop_front();
}

}  // namespace

void CalibrationNodelet::onInit() {
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  base_frame_ = pnh.param<std::string>("robot_base_frame", "");
  camera_frame_ = pnh.param<std::string>("camera_frame", "");
  use_rgb_ = pnh.param("use_rgb", false);
  use_mask_ = pnh.param("use_mask", false);
  publish_tf_ = pnh.param("publish_tf", true);
  max_interval_ = pnh.param("max_interval", 0.02);
  min_configuration_change_ = pnh.param("min_configuration_change", 0.05);
  pnh.getParam("initial_guess", initial_guess_);
  stillness_.max_velocity = pnh.param("max_joint_velocity", stillness_.max_velocity);
  stillness_.window = pnh.param("still_window", stillness_.window);
  stillness_.max_gap = pnh.param("max_joint_gap", stillness_.max_gap);
  options_.passes = pnh.param("passes", options_.passes);
  options_.mask_margin = pnh.param("mask_margin", options_.mask_margin);
  options_.refined_mask_margin = pnh.param("refined_mask_margin", options_.refined_mask_margin);
  options_.max_position_std = pnh.param("max_position_std", options_.max_position_std);
  const std::string mode = pnh.param<std::string>("mode", "eye_to_hand");
  const std::string end_effector = pnh.param<std::string>("end_effector_frame", "");
  const char* ros_home = std::getenv("ROS_HOME");
  const char* home = std::getenv("HOME");
  output_file_ = pnh.param<std::string>(
      "output_file", (ros_home ? std::string(ros_home) : std::string(home ? home : ".") + "/.ros") +
                         "/diffdope_calibration.yaml");
  try {
    const std::string config = pnh.param<std::string>("calibration_config", "");
    if (!config.empty()) options_.refiner = diffdope::RefinerOptions::from_yaml_file(config, options_.refiner);
    options_.validate();
    stillness_.validate();
    const diffdope::OptionRange check{"parameters"};
    check.above("~max_interval", max_interval_, 0, 10, " s");
    check("~min_configuration_change", min_configuration_change_, 0, 10, " rad");
    if (mode == "eye_in_hand") {
      if (end_effector.empty())
        check.fail("~mode eye_in_hand needs ~end_effector_frame (the link the camera rides on)");
      mount_.link = end_effector;
    } else if (mode != "eye_to_hand") {
      check.fail("~mode: '" + mode + "' is not one of eye_to_hand, eye_in_hand");
    }
    if (!initial_guess_.empty() && initial_guess_.size() != 7)
      check.fail("~initial_guess: expected [x, y, z, qx, qy, qz, qw] (the camera in the " +
                 std::string(mount_.eye_in_hand() ? "end effector" : "base") + " frame), got " +
                 std::to_string(initial_guess_.size()) + " values");
    calibrator_ = std::make_unique<diffdope::Calibrator>(options_);
    joints_ = std::make_unique<diffdope::JointHistory>(stillness_);
  } catch (const std::exception& e) {
    robot_error_ = std::string("configuration error: ") + e.what();
    errors_.error("config", robot_error_);
    joints_ = std::make_unique<diffdope::JointHistory>();
  }
  if (calibrator_) loadRobot();

  tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
  static_tf_ = std::make_unique<tf2_ros::StaticTransformBroadcaster>();
  depth_sub_ = nh.subscribe("depth/image_rect", 5, &CalibrationNodelet::onDepth, this);
  info_sub_ = nh.subscribe("depth/camera_info", 5, &CalibrationNodelet::onInfo, this);
  if (use_rgb_) rgb_sub_ = nh.subscribe("rgb/image_rect_color", 5, &CalibrationNodelet::onRgb, this);
  if (use_mask_) mask_sub_ = nh.subscribe("mask", 5, &CalibrationNodelet::onMask, this);
  joints_sub_ = nh.subscribe("joint_states", 200, &CalibrationNodelet::onJoints, this);

  ros::NodeHandle service_nh(pnh);
  service_nh.setCallbackQueue(&service_queue_);
  take_srv_ = service_nh.advertiseService("take_sample", &CalibrationNodelet::onTakeSample, this);
  remove_srv_ = service_nh.advertiseService("remove_sample", &CalibrationNodelet::onRemoveSample, this);
  compute_srv_ = service_nh.advertiseService("compute", &CalibrationNodelet::onCompute, this);
  save_srv_ = service_nh.advertiseService("save", &CalibrationNodelet::onSave, this);
  service_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &service_queue_);
  service_spinner_->start();
  NODELET_INFO_STREAM("diffdope calibration ready: robot "
                      << (robot_ ? "'" + robot_->name() + "' (" + std::to_string(robot_->visuals().size()) + " visuals)"
                                 : "unusable: " + robot_error_)
                      << ", inputs depth" << (use_rgb_ ? "+rgb" : "") << (use_mask_ ? "+mask" : "")
                      << "; services ~take_sample, ~remove_sample, ~compute, ~save");
}

void CalibrationNodelet::loadRobot() {
  ros::NodeHandle& pnh = getPrivateNodeHandle();
  const std::string param = pnh.param<std::string>("robot_description_param", "robot_description");
  std::string key, urdf;
  if (!pnh.searchParam(param, key) || !pnh.getParam(key, urdf) || urdf.empty()) {
    robot_error_ = "no URDF in the parameter '" + param + "' (set robot_description, e.g. <param name=\"robot_description\" "
                   "textfile=\"robot.urdf\"/>)";
    errors_.error("robot", robot_error_);
    return;
  }
  const diffdope::PackageResolver resolver = [](const std::string& pkg) {
    const std::string path = ros::package::getPath(pkg);
    if (path.empty()) throw std::runtime_error("package '" + pkg + "' not found (ROS_PACKAGE_PATH)");
    return path;
  };
  try {
    // Relative mesh paths (rare in a robot_description: package:// is the rule) are taken from ~mesh_base_dir.
    const std::string base_dir = pnh.param<std::string>("mesh_base_dir", ".");
    robot_ = std::make_unique<diffdope::RobotModel>(
        diffdope::RobotModel::parse_urdf(urdf, base_dir, "parameter " + key, resolver));
    if (base_frame_.empty()) base_frame_ = robot_->root_link();
    {
      const std::vector<std::string> names = robot_->joint_names();
      std::lock_guard<std::mutex> l(input_mutex_);
      joints_->keep_only(std::set<std::string>(names.begin(), names.end()));
    }
    try {
      mount_.check(*robot_);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(std::string("~end_effector_frame: ") + e.what());
    }
  } catch (const std::exception& e) {
    robot_error_ = std::string("robot description unusable: ") + e.what();
    errors_.error("robot", robot_error_);
  }
}

CalibrationNodelet::~CalibrationNodelet() {
  if (service_spinner_) service_spinner_->stop();
  take_srv_.shutdown(), remove_srv_.shutdown(), compute_srv_.shutdown(), save_srv_.shutdown();
  depth_sub_.shutdown(), rgb_sub_.shutdown(), mask_sub_.shutdown(), info_sub_.shutdown(), joints_sub_.shutdown();
}

// ---- Inputs ----

void CalibrationNodelet::onDepth(const sensor_msgs::ImageConstPtr& m) {
  std::lock_guard<std::mutex> l(input_mutex_);
  keep(depth_, m);
}
void CalibrationNodelet::onRgb(const sensor_msgs::ImageConstPtr& m) {
  std::lock_guard<std::mutex> l(input_mutex_);
  keep(rgb_, m);
}
void CalibrationNodelet::onMask(const sensor_msgs::ImageConstPtr& m) {
  std::lock_guard<std::mutex> l(input_mutex_);
  keep(mask_, m);
}
void CalibrationNodelet::onInfo(const sensor_msgs::CameraInfoConstPtr& m) {
  std::lock_guard<std::mutex> l(input_mutex_);
  keep(info_, m);
}

void CalibrationNodelet::onJoints(const sensor_msgs::JointStateConstPtr& m) {
  diffdope::JointReading r;
  r.stamp = m->header.stamp.toSec();
  // A message that cannot be used is logged, and the history keeps its reason for ~take_sample's reply.
  const auto reject = [&](const std::string& why) {
    errors_.error("joint_states", "joint_states: " + why + ": message ignored");
    std::lock_guard<std::mutex> l(input_mutex_);
    joints_->note_rejected(r.stamp, why);
  };
  if (m->position.size() != m->name.size() || (!m->velocity.empty() && m->velocity.size() != m->name.size()))
    return reject(std::to_string(m->name.size()) + " names but " + std::to_string(m->position.size()) +
                  " positions / " + std::to_string(m->velocity.size()) + " velocities");
  for (size_t i = 0; i < m->name.size(); ++i) {
    if (!std::isfinite(m->position[i]) || (!m->velocity.empty() && !std::isfinite(m->velocity[i])))
      return reject("joint '" + m->name[i] + "' is not finite");
    r.position[m->name[i]] = m->position[i];
    if (!m->velocity.empty()) r.velocity[m->name[i]] = m->velocity[i];
  }
  std::lock_guard<std::mutex> l(input_mutex_);
  joints_->add(r);
}

}  // namespace diffdope_ros

PLUGINLIB_EXPORT_CLASS(diffdope_ros::CalibrationNodelet, nodelet::Nodelet)
