#pragma once
// The standalone nodes (refiner_node, calibration_node): one nodelet in its own process, same parameters and
// topics as in a manager.
#include <nodelet/loader.h>
#include <ros/ros.h>

#include <string>

namespace diffdope_ros {

inline int run_standalone_nodelet(int argc, char** argv, const std::string& node_name, const std::string& type) {
  ros::init(argc, argv, node_name);
  nodelet::Loader loader(false);  // no manager services: this process hosts exactly one nodelet
  nodelet::M_string remappings(ros::names::getRemappings());
  nodelet::V_string my_argv(argv + 1, argv + argc);
  if (!loader.load(ros::this_node::getName(), type, remappings, my_argv)) {
    ROS_FATAL_STREAM("could not load " << type << " (is the package's plugin exported? see nodelet_plugins.xml)");
    return 1;
  }
  ros::spin();
  return 0;
}

}  // namespace diffdope_ros
