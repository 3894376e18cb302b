#pragma once
// The refiner nodelet's outputs besides the per-instance ones (slot.hpp). Set-up makes them; the worker publishes
// the refinements on them and reads TF through tf_buffer (ROS publishers and tf2's buffer are thread-safe).
#include <diagnostic_updater/diagnostic_updater.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <memory>

namespace diffdope_ros {

struct Publishers {
  std::unique_ptr<tf2_ros::Buffer> tf_buffer;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster;
  ros::Publisher refined, markers, ready;
  image_transport::Publisher overlay;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics;  // the nodelet's (its watchdog updates it)
};

}  // namespace diffdope_ros
