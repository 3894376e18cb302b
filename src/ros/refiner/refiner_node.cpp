// Standalone node: runs diffdope_ros/RefinerNodelet in its own process (same parameters and topics).
#include "ros/common/standalone_nodelet.hpp"

int main(int argc, char** argv) {
  return diffdope_ros::run_standalone_nodelet(argc, argv, "diffdope_refiner", "diffdope_ros/RefinerNodelet");
}
