#pragma once
// One synchronized input set, from the input callbacks to the worker.
#include <ros/time.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Header.h>

#include <opencv2/core.hpp>

#include "diffdope/camera.hpp"
#include "diffdope/observation.hpp"

namespace diffdope_ros {

/// The input callback checks the messages (encodings, sizes, camera_info) and hands them over; the worker
/// converts the pixels (convert_frame), so frames it skips cost the callbacks nothing.
struct Frame {
  std_msgs::Header header;  // the RGB image's stamp and optical frame
  diffdope::Camera camera;
  sensor_msgs::ImageConstPtr rgb_msg, depth_msg, mask_msg;  // depth / mask null when not used
  ros::WallTime received;
  // Filled by the worker (the only thread that touches them after the hand-over).
  bool converted = false;
  diffdope::Observation observation;  // rgb (+ depth); masks are per object
  cv::Mat labels;                     // mask / label image, empty without a mask
};

/// Converts the frame's pixels once. Throws std::invalid_argument like the conversions.
void convert_frame(Frame& frame);

}  // namespace diffdope_ros
