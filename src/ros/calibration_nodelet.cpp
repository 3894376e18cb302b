// CalibrationNodelet (calibration_nodelet.hpp): samples, computing, saving and publishing a camera-to-robot
// calibration. The calibration itself is diffdope::Calibrator; stillness is diffdope::JointHistory.
#include "diffdope_ros/calibration_nodelet.hpp"

#include <pluginlib/class_list_macros.hpp>
#include <ros/package.h>

#include <cmath>
#include <filesystem>
#include <fstream>

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

/// The message of `q` nearest `stamp`, if within `max_interval` seconds.
template <class M>
M nearest(const std::deque<M>& q, const ros::Time& stamp, double max_interval) {
  M best;
  for (const M& m : q)
    if (!best || std::abs((m->header.stamp - stamp).toSec()) < std::abs((best->header.stamp - stamp).toSec())) best = m;
  if (best && std::abs((best->header.stamp - stamp).toSec()) <= max_interval) return best;
  return M();
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
    if (!initial_guess_.empty() && initial_guess_.size() != 7)
      check.fail("~initial_guess: expected [x, y, z, qx, qy, qz, qw] (the camera in the base frame), got " +
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
  if (m->position.size() != m->name.size() || (!m->velocity.empty() && m->velocity.size() != m->name.size())) {
    errors_.error("joint_states", "joint_states: " + std::to_string(m->name.size()) + " names but " +
                                      std::to_string(m->position.size()) + " positions / " +
                                      std::to_string(m->velocity.size()) + " velocities: ignored");
    return;
  }
  for (size_t i = 0; i < m->name.size(); ++i) {
    if (!std::isfinite(m->position[i]) || (!m->velocity.empty() && !std::isfinite(m->velocity[i]))) {
      errors_.error("joint_states", "joint_states: joint '" + m->name[i] + "' is not finite: message ignored");
      return;
    }
    r.position[m->name[i]] = m->position[i];
    if (!m->velocity.empty()) r.velocity[m->name[i]] = m->velocity[i];
  }
  std::lock_guard<std::mutex> l(input_mutex_);
  joints_->add(r);
}

// ---- Services ----

bool CalibrationNodelet::onTakeSample(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  const auto fail = [&](const std::string& why) {
    res.success = false;
    res.message = why;
    errors_.warn("take_sample", "~take_sample refused: " + why);
    return true;
  };
  if (!robot_) return fail(robot_error_);
  sensor_msgs::ImageConstPtr depth, rgb, mask;
  sensor_msgs::CameraInfoConstPtr info;
  std::map<std::string, double> q;
  {
    std::lock_guard<std::mutex> l(input_mutex_);
    if (depth_.empty()) return fail("no depth image received on " + depth_sub_.getTopic());
    // The newest image whose stillness window the joint states already cover (at 30 Hz the very newest is a
    // few tens of milliseconds old, less than the window after it that must be seen still).
    depth = depth_.back();
    for (auto it = depth_.rbegin(); it != depth_.rend(); ++it)
      if (joints_->covers((*it)->header.stamp.toSec())) {
        depth = *it;
        break;
      }
    const ros::Time stamp = depth->header.stamp;
    info = nearest(info_, stamp, max_interval_);
    if (!info) return fail("no camera_info on " + info_sub_.getTopic() + " within ~max_interval of the depth image");
    if (use_rgb_ && !(rgb = nearest(rgb_, stamp, max_interval_)))
      return fail("no rgb image on " + rgb_sub_.getTopic() + " within ~max_interval of the depth image");
    if (use_mask_ && !(mask = nearest(mask_, stamp, max_interval_)))
      return fail("no mask on " + mask_sub_.getTopic() + " within ~max_interval of the depth image");
    std::string why;
    const auto still = joints_->still_at(stamp.toSec(), &why);
    if (!still) return fail(why);
    q = *still;
  }
  Sample s;
  s.stamp = depth->header.stamp;
  diffdope::CalibrationCapture& c = s.capture;
  c.name = "sample" + std::to_string(samples_taken_);
  c.joint_positions = q;
  try {
    c.camera = camera_from_info(*info);
    c.observed.depth = depth_from_image(*depth);
    if (rgb) c.observed.rgb = rgb_from_image(*rgb);
    if (mask) {
      const cv::Mat labels = labels_from_image(*mask);
      cv::Mat(labels != 0).convertTo(c.observed.mask, CV_32F, 1.0 / 255.0);
      if (cv::countNonZero(c.observed.mask) == 0) return fail("the mask shows no robot pixel");
    }
    c.observed.validate(c.camera);
    robot_->link_poses(q);  // every joint of the robot has a position
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  const std::string frame = strip_slash(camera_frame_.empty() ? depth->header.frame_id : camera_frame_);
  if (frame.empty()) return fail("the depth image has no frame_id (set ~camera_frame)");
  if (camera_frame_.empty()) camera_frame_ = frame;
  // A sample adds nothing when the robot has not moved since another.
  for (size_t k = 0; k < samples_.size(); ++k) {
    double change = 0;
    for (const std::string& j : robot_->joint_names())
      change = std::max(change, std::abs(q.at(j) - samples_[k].capture.joint_positions.at(j)));
    if (change < min_configuration_change_)
      return fail("the robot is in the configuration of sample " + std::to_string(k) + " (joints within " +
                  format_fixed(min_configuration_change_, 3) + " rad): move it elsewhere first");
  }
  samples_.push_back(std::move(s));
  ++samples_taken_;
  res.success = true;
  res.message = "sample " + std::to_string(samples_.size() - 1) + " taken at t=" +
                format_fixed(samples_.back().stamp.toSec()) + " (" + std::to_string(samples_.size()) + " in all)";
  NODELET_INFO_STREAM(res.message);
  return true;
}

bool CalibrationNodelet::onRemoveSample(RemoveSample::Request& req, RemoveSample::Response& res) {
  const int n = int(samples_.size());
  const int index = req.index == -1 ? n - 1 : req.index;
  if (index < 0 || index >= n) {
    res.success = false;
    res.message = "no sample " + std::to_string(req.index) + " (" + std::to_string(n) + " taken)";
  } else {
    samples_.erase(samples_.begin() + index);
    result_.reset();  // (~save must not write a result of other samples)
    res.success = true;
    res.message = "sample " + std::to_string(index) + " removed";
  }
  res.remaining = int(samples_.size());
  return true;
}

diffdope::Pose CalibrationNodelet::initialGuess(const std::string& camera_frame) {
  if (initial_guess_.size() == 7) {
    const auto& g = initial_guess_;
    return diffdope::Pose::from_quaternion(g[3], g[4], g[5], g[6], Eigen::Vector3d(g[0], g[1], g[2])).inverse();
  }
  try {
    // No waiting: the listener has run since start, and a timeout in simulated time never ends once the clock
    // stops (a bag that has finished).
    const geometry_msgs::TransformStamped t = tf_buffer_->lookupTransform(base_frame_, camera_frame, ros::Time(0));
    return pose_from_transform(t.transform, "TF " + base_frame_ + " -> " + camera_frame).inverse();
  } catch (const tf2::TransformException& e) {
    throw std::runtime_error("no initial guess: set ~initial_guess [x, y, z, qx, qy, qz, qw] (the camera in '" +
                             base_frame_ + "') or publish a rough TF " + base_frame_ + " -> " + camera_frame + " (" +
                             e.what() + ")");
  }
}

bool CalibrationNodelet::onCompute(ComputeCalibration::Request&, ComputeCalibration::Response& res) {
  const auto fail = [&](const std::string& why) {
    res.success = false;
    res.message = why;
    result_.reset();
    errors_.warn("compute", "~compute: " + why);
    return true;
  };
  if (!robot_ || !calibrator_) return fail(robot_error_);
  if (samples_.empty()) return fail("no sample taken (~take_sample, with the robot still, in a few configurations)");
  diffdope::CalibrationResult r;
  diffdope::Pose guess;
  try {
    guess = initialGuess(camera_frame_);
    std::vector<diffdope::CalibrationCapture> captures;
    for (const Sample& s : samples_) captures.push_back(s.capture);
    r = calibrator_->calibrate(*robot_, captures, guess);
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  const diffdope::Pose base_from_camera = r.camera_from_base.inverse();
  res.transform.header.stamp = ros::Time::now();
  res.transform.header.frame_id = base_frame_;
  res.transform.child_frame_id = camera_frame_;
  res.transform.transform = transform_to_msg(base_from_camera);
  for (const diffdope::CaptureResidual& c : r.captures) {
    CaptureResidual m;
    m.name = c.name;
    m.loss = c.loss;
    m.mask_iou = c.mask_iou;
    m.depth_inliers = c.depth_inliers;
    m.depth_median_mm = c.depth_median_mm;
    m.derived_mask = c.derived_mask;
    res.residuals.push_back(m);
  }
  res.plausible = r.plausible;
  res.confidence = r.confidence;
  res.success = true;
  const diffdope::Pose base_from_guess = guess.inverse();
  res.message = "calibrated from " + std::to_string(samples_.size()) + " sample(s) in " +
                format_fixed(r.time_ms / 1e3, 1) + " s: moved " +
                format_fixed(1e3 * (base_from_camera.t - base_from_guess.t).norm(), 1) + " mm from the guess, " +
                (r.plausible ? "plausible" : "NOT plausible (check the residuals)") + ", confidence " +
                format_fixed(r.confidence, 2);
  // An implausible result is returned (and may be saved) but not put on TF, where it would become the next
  // guess and every listener's camera pose.
  if (publish_tf_ && r.plausible) {
    // A camera driver usually publishes camera_link -> optical frame: a second parent for the optical frame would
    // break the tree, so the calibration goes to that parent (base -> camera_link), composed with the driver's.
    geometry_msgs::TransformStamped on_tf = res.transform;
    std::string parent;
    if (tf_buffer_->_getParent(camera_frame_, ros::Time(0), parent) && !parent.empty() && parent != base_frame_) {
      try {
        const geometry_msgs::TransformStamped p = tf_buffer_->lookupTransform(parent, camera_frame_, ros::Time(0));
        const diffdope::Pose parent_from_camera = pose_from_transform(p.transform, "TF " + parent);
        on_tf.child_frame_id = parent;
        on_tf.transform = transform_to_msg(base_from_camera * parent_from_camera.inverse());
      } catch (const std::exception& e) {
        on_tf.child_frame_id.clear();
        res.message += "; not published on TF: " + camera_frame_ + " has the parent " + parent +
                       " whose transform cannot be read (" + e.what() + ")";
      }
    }
    if (!on_tf.child_frame_id.empty()) {
      static_tf_->sendTransform(on_tf);
      res.message += "; published on TF as " + base_frame_ + " -> " + on_tf.child_frame_id;
    }
  } else if (publish_tf_) {
    res.message += "; not published on TF";
  }
  NODELET_INFO_STREAM(res.message);
  result_ = res;
  return true;
}

bool CalibrationNodelet::onSave(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = false;
  if (!result_) {
    res.message = "nothing to save: call ~compute first";
    return true;
  }
  const diffdope::Pose base_from_camera = pose_from_transform(result_->transform.transform, "calibration");
  try {
    const std::filesystem::path path(output_file_);
    if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
    std::ofstream f(output_file_);
    f << diffdope::easy_handeye_yaml(base_from_camera, base_frame_, camera_frame_);
    if (!f) throw std::runtime_error("cannot write");
  } catch (const std::exception& e) {
    res.message = output_file_ + ": " + e.what();
    errors_.error("save", "~save: " + res.message);
    return true;
  }
  res.success = true;
  res.message = "saved to " + output_file_;
  return true;
}

}  // namespace diffdope_ros

PLUGINLIB_EXPORT_CLASS(diffdope_ros::CalibrationNodelet, nodelet::Nodelet)
