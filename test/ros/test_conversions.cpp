// Unit tests for the ROS message <-> core type conversions (no ROS master needed). Images are built by hand
// (encoding, width, height, step, data), as a publisher would fill them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope_ros/conversions.hpp"

namespace {

using diffdope_ros::camera_from_info;
using diffdope_ros::depth_from_image;
using diffdope_ros::labels_from_image;
using diffdope_ros::object_mask;
using diffdope_ros::pose_from_msg;
using diffdope_ros::pose_from_transform;
using diffdope_ros::pose_to_msg;
using diffdope_ros::rgb_from_image;
using diffdope_ros::transform_to_msg;

// Runs `f`, expects std::invalid_argument and returns its message ("" and a failure when nothing is thrown).
template <class F>
std::string thrown_message(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected std::invalid_argument, got another exception: " << e.what();
    return e.what();
  }
  ADD_FAILURE() << "expected std::invalid_argument, nothing was thrown";
  return "";
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// ---------------------------------------------------------------------------------------------------------------
// camera_from_info

sensor_msgs::CameraInfo make_info() {
  sensor_msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  // K: the unrectified camera; P: the rectified one (deliberately different values).
  info.K = {500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0};
  info.P = {600.0, 0.0, 330.5, 0.0, 0.0, 610.0, 250.5, 0.0, 0.0, 0.0, 1.0, 0.0};
  return info;
}

TEST(CameraFromInfo, UsesPNotK) {
  std::string warning;
  const diffdope::Camera cam = camera_from_info(make_info(), &warning);
  EXPECT_DOUBLE_EQ(cam.fx, 600.0);
  EXPECT_DOUBLE_EQ(cam.fy, 610.0);
  EXPECT_DOUBLE_EQ(cam.cx, 330.5);
  EXPECT_DOUBLE_EQ(cam.cy, 250.5);
  EXPECT_EQ(cam.width, 640);
  EXPECT_EQ(cam.height, 480);
  EXPECT_TRUE(warning.empty()) << warning;
}

TEST(CameraFromInfo, NullWarningPointerIsFine) {
  const diffdope::Camera cam = camera_from_info(make_info());
  EXPECT_DOUBLE_EQ(cam.fx, 600.0);
}

TEST(CameraFromInfo, FallsBackToKWhenPIsAllZeroAndWarns) {
  sensor_msgs::CameraInfo info = make_info();
  info.P.fill(0.0);
  std::string warning;
  const diffdope::Camera cam = camera_from_info(info, &warning);
  EXPECT_DOUBLE_EQ(cam.fx, 500.0);
  EXPECT_DOUBLE_EQ(cam.fy, 510.0);
  EXPECT_DOUBLE_EQ(cam.cx, 320.0);
  EXPECT_DOUBLE_EQ(cam.cy, 240.0);
  EXPECT_FALSE(warning.empty());
  EXPECT_TRUE(contains(warning, "K")) << warning;
  // Without a warning pointer the fallback still works.
  EXPECT_DOUBLE_EQ(camera_from_info(info).fx, 500.0);
}

TEST(CameraFromInfo, ADistortionIsTakenAsRectifiedWithPAndRefusedWithoutIt) {
  // D describes the raw camera, P the rectified images: with P the images are taken as rectified, and said so.
  sensor_msgs::CameraInfo info = make_info();
  info.distortion_model = "equidistant";
  info.D = {0.1, -0.05, 0.001, 0.0};
  std::string warning;
  EXPECT_DOUBLE_EQ(camera_from_info(info, &warning).fx, 600.0);
  EXPECT_TRUE(contains(warning, "distortion model 'equidistant' with D not zero")) << warning;
  EXPECT_TRUE(contains(warning, "taken as rectified")) << warning;
  // Without P there is no rectified camera: the images are raw, refused with the fix.
  info.P.fill(0.0);
  const std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "not rectified")) << msg;
  EXPECT_TRUE(contains(msg, "image_proc")) << msg;
  // A zero D (plumb_bob, five zeros) is no distortion.
  info = make_info();
  info.distortion_model = "plumb_bob";
  info.D = {0, 0, 0, 0, 0};
  warning.clear();
  camera_from_info(info, &warning);
  EXPECT_TRUE(warning.empty()) << warning;
  info.D[0] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(camera_from_info(info), std::invalid_argument);
}

TEST(CameraFromInfo, ZeroFocalLengthThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.P[0] = 0.0;
  std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "focal length")) << msg;

  info = make_info();
  info.P[5] = 0.0;
  msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "focal length")) << msg;
}

TEST(CameraFromInfo, NegativeFocalLengthThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.P[0] = -600.0;
  const std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "focal length")) << msg;
}

TEST(CameraFromInfo, AllZeroPAndKThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.P.fill(0.0);
  info.K.fill(0.0);
  std::string warning;
  const std::string msg = thrown_message([&] { camera_from_info(info, &warning); });
  EXPECT_TRUE(contains(msg, "focal length")) << msg;
}

TEST(CameraFromInfo, ZeroSizeThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.width = 0;
  std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "width")) << msg;

  info = make_info();
  info.height = 0;
  msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "height")) << msg;
}

TEST(CameraFromInfo, BinningThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.binning_x = 2;
  std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "binning")) << msg;

  info = make_info();
  info.binning_y = 2;
  msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "binning")) << msg;

  // 0 and 1 both mean "no binning" (REP 104).
  info = make_info();
  info.binning_x = 1;
  info.binning_y = 1;
  EXPECT_NO_THROW(camera_from_info(info));
}

TEST(CameraFromInfo, RoiThrows) {
  sensor_msgs::CameraInfo info = make_info();
  info.roi.x_offset = 10;
  info.roi.y_offset = 10;
  info.roi.width = 100;
  info.roi.height = 100;
  const std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "ROI")) << msg;
}

TEST(CameraFromInfo, NonFiniteThrows) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();

  sensor_msgs::CameraInfo info = make_info();
  info.P[2] = nan;
  std::string msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "non-finite")) << msg;

  info = make_info();
  info.P[0] = inf;
  msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "non-finite")) << msg;

  // NaN in K is rejected too (even though P would be used).
  info = make_info();
  info.K[4] = nan;
  msg = thrown_message([&] { camera_from_info(info); });
  EXPECT_TRUE(contains(msg, "non-finite")) << msg;

  // NaN focal length in K with P all zero.
  info = make_info();
  info.P.fill(0.0);
  info.K[0] = nan;
  EXPECT_THROW(camera_from_info(info), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// Image helpers

sensor_msgs::Image make_image(const std::string& encoding, uint32_t width, uint32_t height, uint32_t step,
                              std::vector<uint8_t> data) {
  sensor_msgs::Image im;
  im.encoding = encoding;
  im.width = width;
  im.height = height;
  im.step = step;
  im.is_bigendian = 0;
  im.data = std::move(data);
  return im;
}

// Every pixel set to the same bytes.
sensor_msgs::Image uniform_image(const std::string& encoding, uint32_t width, uint32_t height,
                                 const std::vector<uint8_t>& pixel) {
  std::vector<uint8_t> data;
  for (uint32_t i = 0; i < width * height; ++i) data.insert(data.end(), pixel.begin(), pixel.end());
  return make_image(encoding, width, height, uint32_t(width * pixel.size()), data);
}

template <class T>
sensor_msgs::Image typed_image(const std::string& encoding, uint32_t width, uint32_t height,
                               const std::vector<T>& values) {
  std::vector<uint8_t> data(values.size() * sizeof(T));
  std::memcpy(data.data(), values.data(), data.size());
  return make_image(encoding, width, height, uint32_t(width * sizeof(T)), data);
}

void expect_rgb(const cv::Mat& m, int y, int x, float r, float g, float b, float tol = 1e-6f) {
  const cv::Vec3f v = m.at<cv::Vec3f>(y, x);
  EXPECT_NEAR(v[0], r, tol) << "R at (" << y << "," << x << ")";
  EXPECT_NEAR(v[1], g, tol) << "G at (" << y << "," << x << ")";
  EXPECT_NEAR(v[2], b, tol) << "B at (" << y << "," << x << ")";
}

void expect_in_unit_range(const cv::Mat& m) {
  double lo = 0, hi = 0;
  cv::minMaxLoc(m.reshape(1), &lo, &hi);
  EXPECT_GE(lo, 0.0);
  EXPECT_LE(hi, 1.0);
}

// ---------------------------------------------------------------------------------------------------------------
// rgb_from_image

TEST(RgbFromImage, Rgb8AndBgr8GiveTheSameColour) {
  // An orange-ish colour with three different channel values: R=255, G=128, B=0.
  const cv::Mat from_rgb = rgb_from_image(uniform_image("rgb8", 4, 3, {255, 128, 0}));
  const cv::Mat from_bgr = rgb_from_image(uniform_image("bgr8", 4, 3, {0, 128, 255}));
  for (const cv::Mat* m : {&from_rgb, &from_bgr}) {
    ASSERT_EQ(m->type(), CV_32FC3);
    ASSERT_EQ(m->cols, 4);
    ASSERT_EQ(m->rows, 3);
    expect_rgb(*m, 0, 0, 1.0f, 128.f / 255.f, 0.0f);
    expect_rgb(*m, 2, 3, 1.0f, 128.f / 255.f, 0.0f);
    expect_in_unit_range(*m);
  }
  EXPECT_EQ(cv::norm(from_rgb, from_bgr, cv::NORM_INF), 0.0);
}

TEST(RgbFromImage, PixelLayoutRowMajor) {
  // 2x2 rgb8 image with distinct pixels: pixel (row, col) gets R = 10*row + col + 1.
  std::vector<uint8_t> data = {1, 0, 0, 2, 0, 0, 11, 0, 0, 12, 0, 0};
  const cv::Mat m = rgb_from_image(make_image("rgb8", 2, 2, 6, data));
  ASSERT_EQ(m.type(), CV_32FC3);
  expect_rgb(m, 0, 0, 1.f / 255.f, 0, 0);
  expect_rgb(m, 0, 1, 2.f / 255.f, 0, 0);
  expect_rgb(m, 1, 0, 11.f / 255.f, 0, 0);
  expect_rgb(m, 1, 1, 12.f / 255.f, 0, 0);
}

TEST(RgbFromImage, PaddedStep) {
  // width 2, rgb8 needs 6 bytes a row; step 8 has two padding bytes a row that must be skipped.
  std::vector<uint8_t> data = {10, 20, 30, 40, 50, 60, 99, 99,  //
                               70, 80, 90, 100, 110, 120, 99, 99};
  const cv::Mat m = rgb_from_image(make_image("rgb8", 2, 2, 8, data));
  ASSERT_EQ(m.type(), CV_32FC3);
  expect_rgb(m, 0, 1, 40.f / 255.f, 50.f / 255.f, 60.f / 255.f);
  expect_rgb(m, 1, 0, 70.f / 255.f, 80.f / 255.f, 90.f / 255.f);
  expect_rgb(m, 1, 1, 100.f / 255.f, 110.f / 255.f, 120.f / 255.f);
}

TEST(RgbFromImage, Rgba8AndBgra8DropAlpha) {
  const cv::Mat from_rgba = rgb_from_image(uniform_image("rgba8", 3, 2, {255, 128, 0, 7}));
  const cv::Mat from_bgra = rgb_from_image(uniform_image("bgra8", 3, 2, {0, 128, 255, 200}));
  for (const cv::Mat* m : {&from_rgba, &from_bgra}) {
    ASSERT_EQ(m->type(), CV_32FC3);
    ASSERT_EQ(m->cols, 3);
    ASSERT_EQ(m->rows, 2);
    expect_rgb(*m, 1, 2, 1.0f, 128.f / 255.f, 0.0f);
    expect_in_unit_range(*m);
  }
}

TEST(RgbFromImage, Mono8GivesThreeEqualChannels) {
  std::vector<uint8_t> data = {0, 51, 255, 102};
  const cv::Mat m = rgb_from_image(make_image("mono8", 2, 2, 2, data));
  ASSERT_EQ(m.type(), CV_32FC3);
  expect_rgb(m, 0, 0, 0.f, 0.f, 0.f);
  expect_rgb(m, 0, 1, 0.2f, 0.2f, 0.2f);
  expect_rgb(m, 1, 0, 1.f, 1.f, 1.f);
  expect_rgb(m, 1, 1, 0.4f, 0.4f, 0.4f);
  expect_in_unit_range(m);
}

TEST(RgbFromImage, FullWhiteIsExactlyOne) {
  const cv::Mat m = rgb_from_image(uniform_image("rgb8", 2, 2, {255, 255, 255}));
  expect_rgb(m, 1, 1, 1.f, 1.f, 1.f, 0.f);
}

TEST(RgbFromImage, UnsupportedEncodingThrowsNamingIt) {
  for (const std::string enc : {"32FC1", "16UC3", "foo"}) {
    // The data is sized so that only the encoding is wrong.
    const size_t bpp = enc == "32FC1" ? 4 : enc == "16UC3" ? 6 : 3;
    const sensor_msgs::Image im = make_image(enc, 2, 2, uint32_t(2 * bpp), std::vector<uint8_t>(4 * bpp, 0));
    const std::string msg = thrown_message([&] { rgb_from_image(im); });
    EXPECT_TRUE(contains(msg, "'" + enc + "'")) << enc << ": " << msg;
  }
}

TEST(RgbFromImage, ShortDataThrows) {
  sensor_msgs::Image im = uniform_image("rgb8", 4, 3, {1, 2, 3});
  im.data.pop_back();  // one byte short of step * height
  const std::string msg = thrown_message([&] { rgb_from_image(im); });
  EXPECT_TRUE(contains(msg, "data size")) << msg;

  // step * height larger than the data (a step that claims padding that is not there).
  im = uniform_image("rgb8", 4, 3, {1, 2, 3});
  im.step = 16;
  EXPECT_THROW(rgb_from_image(im), std::invalid_argument);
}

TEST(RgbFromImage, ZeroSizeThrows) {
  const std::string msg = thrown_message([&] { rgb_from_image(make_image("rgb8", 0, 0, 0, {})); });
  EXPECT_TRUE(contains(msg, "empty")) << msg;
  EXPECT_THROW(rgb_from_image(make_image("rgb8", 0, 2, 0, {})), std::invalid_argument);
  EXPECT_THROW(rgb_from_image(make_image("rgb8", 2, 0, 6, {})), std::invalid_argument);
}

TEST(RgbFromImage, StepSmallerThanRowThrows) {
  // width 4 rgb8 needs 12 bytes a row; a step of 3 with matching data size must still be rejected.
  const sensor_msgs::Image im = make_image("rgb8", 4, 2, 3, std::vector<uint8_t>(6, 1));
  EXPECT_THROW(rgb_from_image(im), std::invalid_argument);
  const sensor_msgs::Image d = make_image("16UC1", 4, 2, 4, std::vector<uint8_t>(8, 1));
  EXPECT_THROW(depth_from_image(d), std::invalid_argument);
  const sensor_msgs::Image l = make_image("mono8", 4, 2, 2, std::vector<uint8_t>(4, 1));
  EXPECT_THROW(labels_from_image(l), std::invalid_argument);
}

TEST(RgbFromImage, ZeroStepThrows) {
  sensor_msgs::Image im = uniform_image("rgb8", 2, 2, {1, 2, 3});
  im.step = 0;
  EXPECT_THROW(rgb_from_image(im), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// depth_from_image

TEST(DepthFromImage, MillimetresToMetres) {
  for (const std::string enc : {"16UC1", "mono16"}) {
    const std::vector<uint16_t> mm = {1500, 0, 1, 65535, 250, 3000};
    const cv::Mat d = depth_from_image(typed_image(enc, 3, 2, mm));
    ASSERT_EQ(d.type(), CV_32FC1) << enc;
    ASSERT_EQ(d.cols, 3) << enc;
    ASSERT_EQ(d.rows, 2) << enc;
    EXPECT_NEAR(d.at<float>(0, 0), 1.5f, 1e-6f) << enc;
    EXPECT_EQ(d.at<float>(0, 1), 0.0f) << enc;  // 0 = no reading stays 0
    EXPECT_NEAR(d.at<float>(0, 2), 0.001f, 1e-7f) << enc;
    EXPECT_NEAR(d.at<float>(1, 0), 65.535f, 1e-4f) << enc;
    EXPECT_NEAR(d.at<float>(1, 1), 0.25f, 1e-6f) << enc;
    EXPECT_NEAR(d.at<float>(1, 2), 3.0f, 1e-6f) << enc;
  }
}

TEST(DepthFromImage, MetresPassThroughAndInvalidBecomesZero) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<float> m = {1.25f, nan, -0.5f, inf, -inf, 0.0f, 0.731f, 10.0f};
  const cv::Mat d = depth_from_image(typed_image("32FC1", 4, 2, m));
  ASSERT_EQ(d.type(), CV_32FC1);
  EXPECT_EQ(d.at<float>(0, 0), 1.25f);
  EXPECT_EQ(d.at<float>(0, 1), 0.0f);  // NaN
  EXPECT_EQ(d.at<float>(0, 2), 0.0f);  // negative
  EXPECT_EQ(d.at<float>(0, 3), 0.0f);  // +inf
  EXPECT_EQ(d.at<float>(1, 0), 0.0f);  // -inf
  EXPECT_EQ(d.at<float>(1, 1), 0.0f);
  EXPECT_EQ(d.at<float>(1, 2), 0.731f);
  EXPECT_EQ(d.at<float>(1, 3), 10.0f);
  EXPECT_TRUE(cv::checkRange(d));  // no NaN/inf left anywhere
}

TEST(DepthFromImage, AnImageWithoutAnyValidReadingThrows) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  for (const float v : {0.0f, nan, inf, -1.0f}) {
    const std::string msg = thrown_message([&] { depth_from_image(typed_image("32FC1", 2, 2, std::vector<float>(4, v))); });
    EXPECT_TRUE(contains(msg, "no valid reading")) << v << ": " << msg;
  }
  EXPECT_THROW(depth_from_image(typed_image<uint16_t>("16UC1", 2, 2, {0, 0, 0, 0})), std::invalid_argument);
  EXPECT_NO_THROW(depth_from_image(typed_image<uint16_t>("16UC1", 2, 2, {0, 0, 0, 700})));
}

TEST(DepthFromImage, UnsupportedEncodingThrowsNamingIt) {
  for (const std::string enc : {"8UC1", "rgb8"}) {
    const size_t bpp = enc == "rgb8" ? 3 : 1;
    const sensor_msgs::Image im = make_image(enc, 2, 2, uint32_t(2 * bpp), std::vector<uint8_t>(4 * bpp, 1));
    const std::string msg = thrown_message([&] { depth_from_image(im); });
    EXPECT_TRUE(contains(msg, "'" + enc + "'")) << enc << ": " << msg;
  }
}

TEST(DepthFromImage, ShortDataAndZeroSizeThrow) {
  sensor_msgs::Image im = typed_image<uint16_t>("16UC1", 2, 2, {1, 2, 3, 4});
  im.data.resize(6);
  EXPECT_THROW(depth_from_image(im), std::invalid_argument);
  EXPECT_THROW(depth_from_image(make_image("16UC1", 0, 0, 0, {})), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// labels_from_image + object_mask

void expect_mask(const cv::Mat& mask, const std::vector<float>& expected) {
  ASSERT_EQ(mask.type(), CV_32FC1);
  ASSERT_EQ(size_t(mask.total()), expected.size());
  for (int y = 0; y < mask.rows; ++y)
    for (int x = 0; x < mask.cols; ++x)
      EXPECT_EQ(mask.at<float>(y, x), expected[size_t(y * mask.cols + x)]) << "at (" << y << "," << x << ")";
}

TEST(LabelsAndMask, Mono8Labels) {
  const std::vector<uint8_t> data = {0, 1, 2, 1, 0, 3};
  for (const std::string enc : {"mono8", "8UC1"}) {
    const cv::Mat labels = labels_from_image(make_image(enc, 3, 2, 3, data));
    ASSERT_EQ(labels.type(), CV_8UC1) << enc;
    ASSERT_EQ(labels.cols, 3);
    ASSERT_EQ(labels.rows, 2);
    EXPECT_EQ(labels.at<uint8_t>(1, 2), 3);
    expect_mask(object_mask(labels, 1), {0, 1, 0, 1, 0, 0});
    expect_mask(object_mask(labels, 2), {0, 0, 1, 0, 0, 0});
    expect_mask(object_mask(labels, 3), {0, 0, 0, 0, 0, 1});
    expect_mask(object_mask(labels, 0), {1, 0, 0, 0, 1, 0});  // label 0 is a real label when asked for
    expect_mask(object_mask(labels, 7), {0, 0, 0, 0, 0, 0});  // absent label -> empty mask
    expect_mask(object_mask(labels, -1), {0, 1, 1, 1, 0, 1});  // every nonzero
  }
}

TEST(LabelsAndMask, SixteenBitLabels) {
  const std::vector<uint16_t> values = {0, 1000, 300, 1000, 0, 65535};
  for (const std::string enc : {"16UC1", "mono16"}) {
    const cv::Mat labels = labels_from_image(typed_image(enc, 3, 2, values));
    ASSERT_EQ(labels.type(), CV_16UC1) << enc;
    EXPECT_EQ(labels.at<uint16_t>(0, 1), 1000);
    expect_mask(object_mask(labels, 1000), {0, 1, 0, 1, 0, 0});
    expect_mask(object_mask(labels, 300), {0, 0, 1, 0, 0, 0});
    expect_mask(object_mask(labels, 65535), {0, 0, 0, 0, 0, 1});
    // 300 & 0xff == 44: no truncation to 8 bits may match anything here.
    expect_mask(object_mask(labels, 44), {0, 0, 0, 0, 0, 0});
    expect_mask(object_mask(labels, -1), {0, 1, 1, 1, 0, 1});
  }
}

TEST(LabelsAndMask, LabelOutOfRangeOfEightBitsMatchesNothing) {
  const cv::Mat labels = labels_from_image(make_image("mono8", 3, 1, 3, {255, 44, 0}));
  expect_mask(object_mask(labels, 300), {0, 0, 0});  // neither saturated to 255 nor wrapped to 44
  expect_mask(object_mask(labels, 255), {1, 0, 0});
}

TEST(LabelsAndMask, PaddedStep) {
  const cv::Mat labels = labels_from_image(make_image("mono8", 2, 2, 4, {5, 0, 9, 9, 0, 5, 9, 9}));
  ASSERT_EQ(labels.cols, 2);
  expect_mask(object_mask(labels, 5), {1, 0, 0, 1});
  expect_mask(object_mask(labels, -1), {1, 0, 0, 1});
}

TEST(LabelsAndMask, LabelsAreACopy) {
  sensor_msgs::Image im = make_image("mono8", 2, 1, 2, {1, 2});
  const cv::Mat labels = labels_from_image(im);
  im.data[0] = 9;
  EXPECT_EQ(labels.at<uint8_t>(0, 0), 1);
}

TEST(LabelsAndMask, UnsupportedEncodingAndBadSizeThrow) {
  for (const std::string enc : {"rgb8", "32FC1", "bgr8"}) {
    const size_t bpp = enc == "32FC1" ? 4 : 3;
    const sensor_msgs::Image im = make_image(enc, 2, 2, uint32_t(2 * bpp), std::vector<uint8_t>(4 * bpp, 1));
    const std::string msg = thrown_message([&] { labels_from_image(im); });
    EXPECT_TRUE(contains(msg, "'" + enc + "'")) << enc << ": " << msg;
  }
  sensor_msgs::Image im = make_image("mono8", 2, 2, 2, {1, 2, 3});
  EXPECT_THROW(labels_from_image(im), std::invalid_argument);
  EXPECT_THROW(labels_from_image(make_image("mono8", 0, 0, 0, {})), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------------------------
// Poses

geometry_msgs::Pose make_pose_msg(double x, double y, double z, double qx, double qy, double qz, double qw) {
  geometry_msgs::Pose m;
  m.position.x = x;
  m.position.y = y;
  m.position.z = z;
  m.orientation.x = qx;
  m.orientation.y = qy;
  m.orientation.z = qz;
  m.orientation.w = qw;
  return m;
}

diffdope::Pose sample_pose() {
  const Eigen::Quaterniond q = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()));
  return diffdope::Pose(q.toRotationMatrix(), Eigen::Vector3d(0.12, -0.034, 0.87));
}

void expect_pose_near(const diffdope::Pose& a, const diffdope::Pose& b, double tol) {
  EXPECT_LE((a.R - b.R).cwiseAbs().maxCoeff(), tol) << "R\n" << a.R << "\nvs\n" << b.R;
  EXPECT_LE((a.t - b.t).cwiseAbs().maxCoeff(), tol) << "t " << a.t.transpose() << " vs " << b.t.transpose();
}

TEST(Poses, FromMsgMatchesQuaternion) {
  // 90 degrees about z: (x, y, z, w) = (0, 0, sin 45, cos 45).
  const double s = std::sqrt(0.5);
  const diffdope::Pose p = pose_from_msg(make_pose_msg(1, 2, 3, 0, 0, s, s), "test");
  EXPECT_NEAR(p.t.x(), 1, 1e-15);
  EXPECT_NEAR(p.t.y(), 2, 1e-15);
  EXPECT_NEAR(p.t.z(), 3, 1e-15);
  const Eigen::Vector3d x_axis = p.R * Eigen::Vector3d::UnitX();
  EXPECT_LE((x_axis - Eigen::Vector3d::UnitY()).norm(), 1e-12);  // x -> y
  EXPECT_TRUE(p.is_valid(1e-12));
}

TEST(Poses, MsgRoundTrip) {
  const diffdope::Pose p = sample_pose();
  const geometry_msgs::Pose m = pose_to_msg(p);
  EXPECT_NEAR(m.orientation.x * m.orientation.x + m.orientation.y * m.orientation.y +
                  m.orientation.z * m.orientation.z + m.orientation.w * m.orientation.w,
              1.0, 1e-12);
  expect_pose_near(pose_from_msg(m, "round trip"), p, 1e-12);

  // msg -> pose -> msg gives the same message (up to the quaternion's sign).
  const geometry_msgs::Pose m2 = pose_to_msg(pose_from_msg(m, "round trip"));
  const double sign = (m.orientation.w * m2.orientation.w + m.orientation.x * m2.orientation.x +
                       m.orientation.y * m2.orientation.y + m.orientation.z * m2.orientation.z) < 0 ? -1.0 : 1.0;
  EXPECT_NEAR(m2.position.x, m.position.x, 1e-12);
  EXPECT_NEAR(m2.position.y, m.position.y, 1e-12);
  EXPECT_NEAR(m2.position.z, m.position.z, 1e-12);
  EXPECT_NEAR(sign * m2.orientation.x, m.orientation.x, 1e-12);
  EXPECT_NEAR(sign * m2.orientation.y, m.orientation.y, 1e-12);
  EXPECT_NEAR(sign * m2.orientation.z, m.orientation.z, 1e-12);
  EXPECT_NEAR(sign * m2.orientation.w, m.orientation.w, 1e-12);
}

TEST(Poses, TransformRoundTrip) {
  const diffdope::Pose p = sample_pose();
  const geometry_msgs::Transform t = transform_to_msg(p);
  EXPECT_DOUBLE_EQ(t.translation.x, p.t.x());
  EXPECT_DOUBLE_EQ(t.translation.y, p.t.y());
  EXPECT_DOUBLE_EQ(t.translation.z, p.t.z());
  expect_pose_near(pose_from_transform(t, "tf"), p, 1e-12);
  // The transform carries the same rotation as the pose message.
  const geometry_msgs::Pose m = pose_to_msg(p);
  EXPECT_DOUBLE_EQ(t.rotation.x, m.orientation.x);
  EXPECT_DOUBLE_EQ(t.rotation.y, m.orientation.y);
  EXPECT_DOUBLE_EQ(t.rotation.z, m.orientation.z);
  EXPECT_DOUBLE_EQ(t.rotation.w, m.orientation.w);
}

TEST(Poses, IdentityRoundTrip) {
  const diffdope::Pose id;
  const geometry_msgs::Pose m = pose_to_msg(id);
  EXPECT_NEAR(std::abs(m.orientation.w), 1.0, 1e-15);
  expect_pose_near(pose_from_msg(m, "identity"), id, 1e-15);
}

TEST(Poses, NonNormalisedQuaternionIsNormalised) {
  const diffdope::Pose p = sample_pose();
  geometry_msgs::Pose m = pose_to_msg(p);
  m.orientation.x *= 3.5;
  m.orientation.y *= 3.5;
  m.orientation.z *= 3.5;
  m.orientation.w *= 3.5;
  const diffdope::Pose q = pose_from_msg(m, "scaled");
  EXPECT_TRUE(q.is_valid(1e-12));
  expect_pose_near(q, p, 1e-12);

  // Small but not degenerate norm too.
  m = pose_to_msg(p);
  m.orientation.x *= 1e-3;
  m.orientation.y *= 1e-3;
  m.orientation.z *= 1e-3;
  m.orientation.w *= 1e-3;
  expect_pose_near(pose_from_msg(m, "small"), p, 1e-12);

  geometry_msgs::Transform t = transform_to_msg(p);
  t.rotation.x *= 0.2;
  t.rotation.y *= 0.2;
  t.rotation.z *= 0.2;
  t.rotation.w *= 0.2;
  expect_pose_near(pose_from_transform(t, "scaled tf"), p, 1e-12);
}

TEST(Poses, NonFiniteComponentThrowsNamingWhat) {
  const double bad_values[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()};
  for (double bad : bad_values) {
    for (int i = 0; i < 7; ++i) {
      double v[7] = {0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0};
      v[i] = bad;
      const geometry_msgs::Pose m = make_pose_msg(v[0], v[1], v[2], v[3], v[4], v[5], v[6]);
      const std::string what = "object_" + std::to_string(i);
      const std::string msg = thrown_message([&] { pose_from_msg(m, what); });
      EXPECT_TRUE(contains(msg, what)) << "component " << i << ": " << msg;

      geometry_msgs::Transform t;
      t.translation.x = v[0];
      t.translation.y = v[1];
      t.translation.z = v[2];
      t.rotation = m.orientation;
      const std::string tmsg = thrown_message([&] { pose_from_transform(t, what + "_tf"); });
      EXPECT_TRUE(contains(tmsg, what + "_tf")) << "component " << i << ": " << tmsg;
    }
  }
}

TEST(Poses, ZeroQuaternionThrowsNamingWhat) {
  const geometry_msgs::Pose m = make_pose_msg(1, 2, 3, 0, 0, 0, 0);
  const std::string msg = thrown_message([&] { pose_from_msg(m, "detection of mug"); });
  EXPECT_TRUE(contains(msg, "detection of mug")) << msg;
  EXPECT_TRUE(contains(msg, "zero quaternion")) << msg;

  // A default-constructed message (all zeros, as a careless publisher sends) is rejected too.
  EXPECT_THROW(pose_from_msg(geometry_msgs::Pose(), "default"), std::invalid_argument);
  const std::string tmsg = thrown_message([&] { pose_from_transform(geometry_msgs::Transform(), "tf lookup"); });
  EXPECT_TRUE(contains(tmsg, "tf lookup")) << tmsg;

  // Near zero norm is rejected as well.
  EXPECT_THROW(pose_from_msg(make_pose_msg(0, 0, 0, 1e-9, 0, 0, 1e-9), "tiny"), std::invalid_argument);
}

}  // namespace

TEST(Frames, LeadingSlashIsStripped) {
  EXPECT_EQ(diffdope_ros::strip_slash("/camera_optical"), "camera_optical");
  EXPECT_EQ(diffdope_ros::strip_slash("camera_optical"), "camera_optical");
  EXPECT_EQ(diffdope_ros::strip_slash(""), "");
  EXPECT_EQ(diffdope_ros::strip_slash("/"), "");
}

// catkin_add_gtest links gtest but not gtest_main: the one main() of diffdope_ros_unit_tests lives here.
int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}

TEST(Transports, UnknownOnesAreNamedWithWhatIsInstalled) {
  const std::vector<std::string> loadable{"image_transport/raw", "compressed_image_transport/compressed"};
  EXPECT_EQ(diffdope_ros::unknown_transports(loadable, {{"image_transport", "compressed"},
                                                        {"depth_image_transport", "raw"}}),
            "");
  const std::string e = diffdope_ros::unknown_transports(
      loadable, {{"image_transport", "raw"}, {"depth_image_transport", "compressedDepth"}, {"mask_image_transport", "x"}});
  EXPECT_NE(e.find("~depth_image_transport: 'compressedDepth' is not an installed image transport"), std::string::npos) << e;
  EXPECT_NE(e.find("~mask_image_transport: 'x'"), std::string::npos) << e;
  EXPECT_EQ(e.find("~image_transport"), std::string::npos) << e;
  EXPECT_NE(e.find("(installed: raw, compressed)"), std::string::npos) << e;
  EXPECT_NE(diffdope_ros::unknown_transports({}, {{"image_transport", "raw"}}).find("installed: none"), std::string::npos);
}

TEST(Conversions, CameraInfoRoundTrip) {
  const diffdope::Camera cam(600, 610, 319.5, 239.5, 640, 480);
  std_msgs::Header h;
  h.frame_id = "optical";
  const sensor_msgs::CameraInfo ci = diffdope_ros::camera_info_from_camera(cam, h);
  EXPECT_EQ(ci.header.frame_id, "optical");
  std::string warning;
  const diffdope::Camera back = diffdope_ros::camera_from_info(ci, &warning);
  EXPECT_TRUE(warning.empty()) << warning;
  EXPECT_DOUBLE_EQ(back.fx, 600);
  EXPECT_DOUBLE_EQ(back.fy, 610);
  EXPECT_DOUBLE_EQ(back.cx, 319.5);
  EXPECT_DOUBLE_EQ(back.cy, 239.5);
  EXPECT_EQ(back.width, 640);
  EXPECT_EQ(back.height, 480);
}
