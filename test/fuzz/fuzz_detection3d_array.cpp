// DOPE's vision_msgs/Detection3DArray as the node receives it: any bytes, decoded or refused with a reason.
#include <stdexcept>

#include "diffdope_ros/detection3d_array.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    diffdope_ros::decode_detection3d_array(data, size);
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
