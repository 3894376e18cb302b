// CalibrationNodelet's services (calibration_nodelet.hpp): taking and removing samples, computing, saving and
// publishing a camera-to-robot calibration.
#include <cmath>
#include <filesystem>
#include <fstream>

#include "diffdope_ros/conversions.hpp"
#include "ros/calibration/calibration_nodelet.hpp"

#include "diffdope/input_limits.hpp"

namespace diffdope_ros {
namespace {

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
  if (samples_.size() >= size_t(diffdope::input_limits::kMaxCaptures))
    return fail("already " + std::to_string(samples_.size()) + " samples, the most one calibration takes: compute "
                "or reset first");
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
    const geometry_msgs::TransformStamped t = tf_buffer_->lookupTransform(mountFrame(), camera_frame, ros::Time(0));
    return pose_from_transform(t.transform, "TF " + mountFrame() + " -> " + camera_frame).inverse();
  } catch (const tf2::TransformException& e) {
    throw std::runtime_error("no initial guess: set ~initial_guess [x, y, z, qx, qy, qz, qw] (the camera in '" +
                             mountFrame() + "') or publish a rough TF " + mountFrame() + " -> " + camera_frame + " (" +
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
    r = calibrator_->calibrate(*robot_, captures, guess, mount_);
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  const diffdope::Pose mount_from_camera = r.camera_from_mount.inverse();
  res.transform.header.stamp = ros::Time::now();
  res.transform.header.frame_id = mountFrame();
  res.transform.child_frame_id = camera_frame_;
  res.transform.transform = transform_to_msg(mount_from_camera);
  for (const diffdope::CaptureResidual& c : r.captures) {
    CaptureResidual m;
    m.name = c.name;
    m.loss = c.loss;
    m.mask_iou = c.mask_iou;
    m.depth_inliers = c.depth_inliers;
    m.depth_median_mm = c.depth_median_mm;
    m.depth_noise_mm = c.depth_noise_mm;
    m.derived_mask = c.derived_mask;
    res.residuals.push_back(m);
  }
  res.plausible = r.plausible;
  res.confidence = r.confidence;
  res.position_std = r.position_std;
  res.rotation_std = r.rotation_std;
  res.success = true;
  const diffdope::Pose mount_from_guess = guess.inverse();
  res.message = "calibrated from " + std::to_string(samples_.size()) + " sample(s) in " +
                format_fixed(r.time_ms / 1e3, 1) + " s: moved " +
                format_fixed(1e3 * (mount_from_camera.t - mount_from_guess.t).norm(), 1) + " mm from the guess, " +
                (r.plausible ? "plausible"
                 : r.diverged ? "NOT plausible: a pass drove the robot out of view (diverged)"
                              : "NOT plausible (check the residuals)") +
                ", confidence " +
                format_fixed(r.confidence, 2);
  // An implausible result is returned (and may be saved) but not put on TF, where it would become the next
  // guess and every listener's camera pose.
  if (publish_tf_ && r.plausible) {
    // A camera driver usually publishes camera_link -> optical frame: a second parent for the optical frame would
    // break the tree, so the calibration goes to that parent (base -> camera_link), composed with the driver's.
    geometry_msgs::TransformStamped on_tf = res.transform;
    std::string parent;
    if (tf_buffer_->_getParent(camera_frame_, ros::Time(0), parent) && !parent.empty() && parent != mountFrame()) {
      try {
        const geometry_msgs::TransformStamped p = tf_buffer_->lookupTransform(parent, camera_frame_, ros::Time(0));
        const diffdope::Pose parent_from_camera = pose_from_transform(p.transform, "TF " + parent);
        on_tf.child_frame_id = parent;
        on_tf.transform = transform_to_msg(mount_from_camera * parent_from_camera.inverse());
      } catch (const std::exception& e) {
        on_tf.child_frame_id.clear();
        res.message += "; not published on TF: " + camera_frame_ + " has the parent " + parent +
                       " whose transform cannot be read (" + e.what() + ")";
      }
    }
    if (!on_tf.child_frame_id.empty()) {
      static_tf_->sendTransform(on_tf);
      res.message += "; published on TF as " + mountFrame() + " -> " + on_tf.child_frame_id;
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
  const diffdope::Pose mount_from_camera = pose_from_transform(result_->transform.transform, "calibration");
  try {
    const std::filesystem::path path(output_file_);
    if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
    std::ofstream f(output_file_);
    f << diffdope::easy_handeye_yaml(mount_from_camera, mountFrame(), camera_frame_, mount_.eye_in_hand());
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
