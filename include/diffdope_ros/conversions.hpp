#pragma once
// ROS messages <-> core types. Every function throws std::invalid_argument with a message that names the input
// and the problem (the nodelet reports it and drops that input; nothing is guessed silently).
#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/pose.hpp"

namespace diffdope_ros {

/// Intrinsics of a rectified image from P (REP 104: rectified images use P, not K). Falls back to K only when
/// P is all zero, and then sets `*warning`. Throws on zero focal lengths, non-finite values, a zero size, or
/// binning / ROI settings (not supported: publish full-resolution rectified images).
diffdope::Camera camera_from_info(const sensor_msgs::CameraInfo& info, std::string* warning = nullptr);
/// The other way (rectified, no distortion: plumb_bob with zeros, R identity, P = [K | 0]), for generated bags.
sensor_msgs::CameraInfo camera_info_from_camera(const diffdope::Camera& camera, const std_msgs::Header& header);

/// Encoding and size checks alone (no pixel is touched): what the input callbacks do before handing a frame
/// to the worker, which converts it. Same messages as the conversions below.
void check_rgb_image(const sensor_msgs::Image& image);
void check_depth_image(const sensor_msgs::Image& image);
void check_labels_image(const sensor_msgs::Image& image);

/// Colour image -> CV_32FC3 RGB in [0, 1]. Encodings: rgb8, bgr8, rgba8, bgra8, mono8.
cv::Mat rgb_from_image(const sensor_msgs::Image& image);
/// Depth image (REP 118) -> CV_32FC1 metres, 0 = no reading. Encodings: 16UC1 / mono16 (millimetres), 32FC1 (m).
/// Throws std::invalid_argument for an image without any valid reading.
cv::Mat depth_from_image(const sensor_msgs::Image& image);
/// Mask or label image -> a copy as CV_8UC1 or CV_16UC1. Encodings: mono8, 8UC1, mono16, 16UC1.
cv::Mat labels_from_image(const sensor_msgs::Image& image);
/// One object's mask from a label image: pixels equal to `label`, or every nonzero pixel when label < 0.
/// CV_32FC1 0/1.
cv::Mat object_mask(const cv::Mat& labels, int label);

/// Throws when a component is not finite or the quaternion has (near) zero norm; normalises the quaternion.
diffdope::Pose pose_from_msg(const geometry_msgs::Pose& msg, const std::string& what);
geometry_msgs::Pose pose_to_msg(const diffdope::Pose& pose);
diffdope::Pose pose_from_transform(const geometry_msgs::Transform& msg, const std::string& what);
geometry_msgs::Transform transform_to_msg(const diffdope::Pose& pose);

/// A TF frame name without its leading '/' (tf2 refuses it; old tf and some drivers still write it).
std::string strip_slash(const std::string& frame_id);

/// v with `precision` decimals, for log messages and diagnostics.
std::string format_fixed(double v, int precision = 3);

/// The image transports the node's parameters ask for that image_transport cannot load: one message naming each
/// parameter, its value and what is installed; empty when every one is loadable. `loadable`:
/// ImageTransport::getLoadableTransports() ("image_transport/raw": the transport's name follows the '/');
/// `requested`: (parameter, transport) pairs.
std::string unknown_transports(const std::vector<std::string>& loadable,
                               const std::vector<std::pair<std::string, std::string>>& requested);

}  // namespace diffdope_ros
