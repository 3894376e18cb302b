#include "diffdope_ros/conversions.hpp"

#include <algorithm>

#include <cv_bridge/cv_bridge.h>
#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>

#include "diffdope/observation.hpp"

namespace diffdope_ros {
namespace enc = sensor_msgs::image_encodings;

namespace {

void check_size(const sensor_msgs::Image& image, const char* what) {
  if (image.width == 0 || image.height == 0)
    throw std::invalid_argument(std::string(what) + " image is empty (" + std::to_string(image.width) + "x" +
                                std::to_string(image.height) + ")");
  const size_t need = size_t(image.step) * image.height;
  if (image.data.size() < need || image.step == 0)
    throw std::invalid_argument(std::string(what) + " image: data size " + std::to_string(image.data.size()) +
                                " does not match step " + std::to_string(image.step) + " x height " +
                                std::to_string(image.height));
}

cv::Mat share(const sensor_msgs::Image& image, const char* what) {
  try {
    // toCvCopy on a borrowed message is what cv_bridge offers for a const reference; the copy is one frame.
    return cv_bridge::toCvCopy(image, image.encoding)->image;
  } catch (const cv_bridge::Exception& e) {
    throw std::invalid_argument(std::string(what) + " image: " + e.what());
  }
}

}  // namespace

sensor_msgs::CameraInfo camera_info_from_camera(const diffdope::Camera& cam, const std_msgs::Header& header) {
  sensor_msgs::CameraInfo ci;
  ci.header = header;
  ci.width = uint32_t(cam.width);
  ci.height = uint32_t(cam.height);
  ci.distortion_model = "plumb_bob";
  ci.D.assign(5, 0.0);
  ci.K = {cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1};
  ci.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ci.P = {cam.fx, 0, cam.cx, 0, 0, cam.fy, cam.cy, 0, 0, 0, 1, 0};
  return ci;
}

diffdope::Camera camera_from_info(const sensor_msgs::CameraInfo& info, std::string* warning) {
  if (info.width == 0 || info.height == 0)
    throw std::invalid_argument("camera_info: width/height are zero (" + std::to_string(info.width) + "x" +
                                std::to_string(info.height) + ")");
  if (info.binning_x > 1 || info.binning_y > 1 || info.roi.width != 0 || info.roi.height != 0)
    throw std::invalid_argument("camera_info: binning/ROI are not supported (publish full-resolution rectified images)");
  for (double v : info.P)
    if (!std::isfinite(v)) throw std::invalid_argument("camera_info: P has a non-finite value");
  for (double v : info.K)
    if (!std::isfinite(v)) throw std::invalid_argument("camera_info: K has a non-finite value");
  bool distorted = false;
  for (double v : info.D) {
    if (!std::isfinite(v)) throw std::invalid_argument("camera_info: D has a non-finite value");
    distorted = distorted || v != 0;
  }
  const std::string model = "distortion model '" + info.distortion_model + "' with D not zero";
  double fx = info.P[0], fy = info.P[5], cx = info.P[2], cy = info.P[6];
  if (fx == 0 && fy == 0 && cx == 0 && cy == 0) {
    // No rectified projection: with a distortion the images can only be raw, and raw images give wrong poses.
    if (distorted)
      throw std::invalid_argument("camera_info: " + model + " and P all zero: the images are not rectified; "
                                  "rectify them (image_proc) and subscribe to image_rect_color / image_rect");
    fx = info.K[0], fy = info.K[4], cx = info.K[2], cy = info.K[5];
    if (fx != 0 && warning)
      *warning = "camera_info: P is all zero, using K (the images are assumed rectified)";
  } else if (distorted && warning) {
    // ROS's convention: D describes the raw camera, P the rectified images (image_proc's image_rect): the usual
    // case, but raw images with this camera_info would give wrong poses, so it is said once.
    *warning = "camera_info: " + model + ": the images are taken as rectified (projected with P, as image_proc's "
               "image_rect_color); raw images must be rectified first";
  }
  if (!(fx > 0) || !(fy > 0))
    throw std::invalid_argument("camera_info: focal length is zero or negative in P and K (fx=" +
                                std::to_string(fx) + ", fy=" + std::to_string(fy) + ")");
  return diffdope::Camera(fx, fy, cx, cy, int(info.width), int(info.height));
}

void check_rgb_image(const sensor_msgs::Image& image) {
  const std::string& e = image.encoding;
  if (e != enc::RGB8 && e != enc::BGR8 && e != enc::RGBA8 && e != enc::BGRA8 && e != enc::MONO8)
    throw std::invalid_argument("rgb image: unsupported encoding '" + e + "' (rgb8, bgr8, rgba8, bgra8, mono8)");
  check_size(image, "rgb");
}

void check_depth_image(const sensor_msgs::Image& image) {
  const std::string& e = image.encoding;
  if (e != enc::TYPE_16UC1 && e != enc::MONO16 && e != enc::TYPE_32FC1)
    throw std::invalid_argument("depth image: unsupported encoding '" + e + "' (16UC1 millimetres, 32FC1 metres)");
  check_size(image, "depth");
}

void check_labels_image(const sensor_msgs::Image& image) {
  const std::string& e = image.encoding;
  if (e != enc::MONO8 && e != enc::TYPE_8UC1 && e != enc::MONO16 && e != enc::TYPE_16UC1)
    throw std::invalid_argument("mask image: unsupported encoding '" + e + "' (mono8/8UC1, or mono16/16UC1 labels)");
  check_size(image, "mask");
}

cv::Mat rgb_from_image(const sensor_msgs::Image& image) {
  check_rgb_image(image);
  const std::string& e = image.encoding;
  cv::Mat m = share(image, "rgb");
  if (e == enc::RGBA8) cv::cvtColor(m, m, cv::COLOR_RGBA2RGB);
  if (e == enc::BGRA8) cv::cvtColor(m, m, cv::COLOR_BGRA2BGR);
  return diffdope::to_rgb_float(m, e == enc::BGR8 || e == enc::BGRA8, "rgb image");
}

cv::Mat depth_from_image(const sensor_msgs::Image& image) {
  check_depth_image(image);
  // REP 118: uint16 depth is millimetres, float depth metres.
  const double metres_per_unit = image.encoding == enc::TYPE_32FC1 ? 1.0 : 0.001;
  cv::Mat depth = diffdope::to_depth_metres(share(image, "depth"), metres_per_unit, "depth image");
  // A frame whose depth says nothing (a camera's laser off, a driver's blank first frame) is not refined as if
  // the object had no depth there: it is dropped, and said so.
  if (cv::countNonZero(depth > 0.f) == 0)
    throw std::invalid_argument("depth image has no valid reading (every pixel zero, NaN, infinite or negative)");
  return depth;
}

cv::Mat labels_from_image(const sensor_msgs::Image& image) {
  check_labels_image(image);
  return share(image, "mask");
}

cv::Mat object_mask(const cv::Mat& labels, int label) {
  cv::Mat m8 = label < 0 ? (labels != 0) : (labels == label);
  cv::Mat out;
  m8.convertTo(out, CV_32F, 1.0 / 255.0);
  return out;
}

diffdope::Pose pose_from_msg(const geometry_msgs::Pose& m, const std::string& what) {
  const double v[7] = {m.position.x, m.position.y, m.position.z, m.orientation.x, m.orientation.y,
                       m.orientation.z, m.orientation.w};
  for (double x : v)
    if (!std::isfinite(x)) throw std::invalid_argument(what + ": pose has a NaN or infinite component");
  const double n = std::sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]);
  if (n < 1e-6) throw std::invalid_argument(what + ": pose orientation is a zero quaternion");
  return diffdope::Pose::from_quaternion(v[3], v[4], v[5], v[6], Eigen::Vector3d(v[0], v[1], v[2]));
}

geometry_msgs::Pose pose_to_msg(const diffdope::Pose& p) {
  geometry_msgs::Pose m;
  m.position.x = p.t.x();
  m.position.y = p.t.y();
  m.position.z = p.t.z();
  const auto q = p.quaternion_xyzw();
  m.orientation.x = q[0];
  m.orientation.y = q[1];
  m.orientation.z = q[2];
  m.orientation.w = q[3];
  return m;
}

diffdope::Pose pose_from_transform(const geometry_msgs::Transform& t, const std::string& what) {
  geometry_msgs::Pose p;
  p.position.x = t.translation.x;
  p.position.y = t.translation.y;
  p.position.z = t.translation.z;
  p.orientation = t.rotation;
  return pose_from_msg(p, what);
}

geometry_msgs::Transform transform_to_msg(const diffdope::Pose& pose) {
  const geometry_msgs::Pose p = pose_to_msg(pose);
  geometry_msgs::Transform t;
  t.translation.x = p.position.x;
  t.translation.y = p.position.y;
  t.translation.z = p.position.z;
  t.rotation = p.orientation;
  return t;
}

std::string strip_slash(const std::string& frame_id) {
  return !frame_id.empty() && frame_id[0] == '/' ? frame_id.substr(1) : frame_id;
}

std::string format_fixed(double v, int precision) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(precision);
  s << v;
  return s.str();
}

std::string unknown_transports(const std::vector<std::string>& loadable,
                               const std::vector<std::pair<std::string, std::string>>& requested) {
  std::vector<std::string> names;
  for (const std::string& l : loadable) names.push_back(l.substr(l.rfind('/') + 1));
  std::string installed;
  for (const std::string& n : names) installed += (installed.empty() ? "" : ", ") + n;
  std::string out;
  for (const auto& [param, transport] : requested) {
    if (std::find(names.begin(), names.end(), transport) != names.end()) continue;
    out += (out.empty() ? "" : "; ") + std::string("~") + param + ": '" + transport + "' is not an installed image transport";
  }
  if (!out.empty()) out += " (installed: " + (installed.empty() ? std::string("none") : installed) + ")";
  return out;
}

}  // namespace diffdope_ros
