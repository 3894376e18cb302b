// The worker's side of the detection inbox: detector poses into the camera frame at the image stamp (tf2) and
// into the instances' tracks; a clock that jumps back resets the tracks.
#include <tf2/exceptions.h>

#include <algorithm>

#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/worker.hpp"

namespace diffdope_ros {

diffdope::Pose Worker::meshPoseInCamera(const geometry_msgs::PoseStamped& pose, const Slot& slot,
                                                const Frame& frame) {
  const std::string what = "initial pose of '" + slot.config.name + "'";
  diffdope::Pose in_source = pose_from_msg(pose.pose, what);
  diffdope::Pose camera_from_source;  // identity when the pose is already in the camera frame
  const std::string camera = strip_slash(frame.header.frame_id), source = strip_slash(pose.header.frame_id);
  const std::string& fixed_frame = settings_.fixed_frame;
  // With ~fixed_frame, a pose stamped at another time goes through it even from the camera frame itself (a
  // moving camera: DOPE's poses are in the optical frame of an earlier image).
  const bool time_travel =
      !fixed_frame.empty() && !pose.header.stamp.isZero() && pose.header.stamp != frame.header.stamp;
  if (source != camera || time_travel) {
    geometry_msgs::TransformStamped t;
    try {
      // Waits ~tf_timeout in wall time: tf2's own timeout sleeps in ROS time, which stands still while a bag
      // is paused or over (sim time), and the worker would hang there.
      const auto available = [&] {
        const tf2_ros::Buffer& tf = *publishers_.tf_buffer;
        return !time_travel ? tf.canTransform(camera, source, frame.header.stamp)
                            : tf.canTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame);
      };
      const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(settings_.tf_timeout);
      while (!available() && ros::WallTime::now() < deadline && ros::ok()) ros::WallDuration(0.005).sleep();
      if (!time_travel)  // (throws, saying why, when it is still not there)
        t = publishers_.tf_buffer->lookupTransform(camera, source, frame.header.stamp);
      else  // the detection's frame at its own stamp, through a fixed frame to the camera at the image stamp
        t = publishers_.tf_buffer->lookupTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame);
    } catch (const tf2::TransformException& e) {
      throw std::runtime_error(what + ": no transform from '" + source + "' to '" + camera + "' at t=" +
                               format_fixed(frame.header.stamp.toSec()) + ": " + e.what());
    }
    camera_from_source = pose_from_transform(t.transform, what + " (TF)");
  }
  const diffdope::Pose mesh_pose = camera_from_source * in_source * slot.config.model_transform;
  if (!(mesh_pose.t.z() > options_.refiner.render.near_plane))
    throw std::runtime_error(what + ": the object is behind the camera (z = " + format_fixed(mesh_pose.t.z()) +
                             " m in '" + camera + "')");
  return mesh_pose;
}

void Worker::resetOnTimeJump(const Frame& frame) {
  const double stamp = frame.header.stamp.toSec();
  const double back = last_frame_stamp_ - stamp;
  last_frame_stamp_ = std::max(last_frame_stamp_, stamp);
  if (!(back > 1.0)) return;  // frames arrive in order; a small step back is the synchronizer's approximation
  last_frame_stamp_ = stamp;
  for (auto& slot : slots_) {
    if (slot->tracks) slot->tracks->reset();
    slot->tracking = 0;
  }
  errors_.warn("time", "time went back by " + format_fixed(back, 2) + " s (image stamped " + format_fixed(stamp) +
                           "; a looped bag or a restarted clock?): tracks and unused detections reset");
}

void Worker::absorbDetections(const Frame& frame) {
  for (auto& [i, msgs] : inbox_.take()) {
    Slot& s = *slots_[i];
    if (!s.tracks) continue;
    std::vector<diffdope::Pose> poses;
    double stamp = frame.header.stamp.toSec();
    for (const auto& msg : msgs) {
      try {
        poses.push_back(meshPoseInCamera(msg, s, frame));
        if (poses.size() == 1 && !msg.header.stamp.isZero()) stamp = msg.header.stamp.toSec();  // (one message)
      } catch (const std::exception& e) {
        errors_.error("pose/" + s.config.name, std::string("initial pose ignored: ") + e.what());
      }
    }
    const std::vector<int> instance = s.tracks->add_detections(poses, stamp);
    const long extra = long(std::count(instance.begin(), instance.end(), -1));
    if (extra > 0) {
      errors_.warn("instances/" + s.config.name,
                   std::to_string(extra) + " detection(s) of '" + s.config.name + "' beyond its max_instances (" +
                       std::to_string(s.config.max_instances) + ") ignored: every instance already had one");
      std::lock_guard<std::mutex> lock(handover_.mutex);
      handover_.stats.extra_detections += extra;
    }
  }
  // A detection too old for this frame can never be used (frames only get newer): say so, with both stamps
  // (a detector stamping with another clock, e.g. wall time under sim time, shows up here).
  const double image_stamp = frame.header.stamp.toSec();
  // One far ahead of it waits for a later image, and is said so each frame (throttled): none may ever come.
  for (auto& slot : slots_)
    for (int k = 0; slot->tracks && k < slot->tracks->size(); ++k) {
      diffdope::ObjectTrack& track = slot->tracks->track(k);
      const std::string& name = slot->instances[size_t(k)].name;
      if (auto stale = track.take_stale_detection(image_stamp))
        errors_.error("pose/" + slot->config.name,
                      "initial pose of '" + name + "' ignored: stamped " + format_fixed(stale->stamp) +
                          ", more than ~max_detection_age (" + format_fixed(options_.track.max_detection_age, 1) +
                          " s) before the image at " + format_fixed(image_stamp));
      else if (auto ahead = track.detection_ahead(image_stamp))
        errors_.error("pose/" + slot->config.name,
                      "initial pose of '" + name + "' not used yet: stamped " + format_fixed(*ahead) + ", " +
                          format_fixed(*ahead - image_stamp, 1) + " s after the image at " +
                          format_fixed(image_stamp) + " (more than ~max_detection_age, " +
                          format_fixed(options_.track.max_detection_age, 1) +
                          " s); kept for a later image (is the detector on another clock?)");
    }
}

}  // namespace diffdope_ros
