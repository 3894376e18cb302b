#pragma once
// The configured objects as the refiner nodelet keeps them: set-up makes the list (RefinerNodelet::loadObjects);
// the worker refines and tracks them; the diagnostics read them.
#include <ros/ros.h>

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "diffdope/instance_tracks.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/object_config.hpp"

namespace diffdope_ros {

/// One instance of a configured object: its name on TF and topics (the object's name, or <name>_<k> when the
/// object may have several instances) and its outputs.
struct Instance {
  std::string name;
  ros::Publisher pose_pub;
  ros::Publisher cov_pub;   // ~refined_cov/<name>: the same pose with its covariance
  ros::Time last_tf_stamp;  // tf2 rejects a second transform at the same stamp (service on the same frame)
};

/// A configured object: its mesh (null when it failed to load: the object is disabled), its instances' tracks
/// and outputs.
struct Slot {
  diffdope::ObjectConfig config;
  std::unique_ptr<diffdope::Mesh> mesh;
  std::string disabled_reason;
  std::unique_ptr<diffdope::InstanceTracks> tracks;  // the worker's; null when disabled
  std::vector<Instance> instances;                   // config.max_instances of them
  std::atomic<int> tracking{0};  // instances whose track is alive (diagnostics; the tracks are the worker's)
};

/// The list is set-up's, and every thread reads it; what each thread may change inside a slot: the comments above.
using Slots = std::vector<std::unique_ptr<Slot>>;

}  // namespace diffdope_ros
