// Standalone node: runs diffdope_ros/CalibrationNodelet in its own process (same parameters and topics).
#include <nodelet/loader.h>
#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "diffdope_calibration");
  nodelet::Loader loader(false);  // no manager services: this process hosts exactly one nodelet
  nodelet::M_string remappings(ros::names::getRemappings());
  nodelet::V_string my_argv(argv + 1, argv + argc);
  if (!loader.load(ros::this_node::getName(), "diffdope_ros/CalibrationNodelet", remappings, my_argv)) {
    ROS_FATAL("could not load diffdope_ros/CalibrationNodelet (is the package's plugin exported? see nodelet_plugins.xml)");
    return 1;
  }
  ros::spin();
  return 0;
}
