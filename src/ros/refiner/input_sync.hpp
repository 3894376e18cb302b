#pragma once
// The refiner's image inputs: rgb + camera_info (+ depth, + mask), each checked on its own, then synchronized
// into a Frame; counts per input, and the watchdog that says when inputs arrive but never form a set.
#include <diagnostic_updater/DiagnosticStatusWrapper.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>

#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "ros/refiner/checked_input.hpp"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/refiner_settings.hpp"
#include "ros/refiner/frame.hpp"

namespace diffdope_ros {

/// Reports a frame dropped for `e` ("<input> image: problem"), throttled per input.
void report_input_error(ErrorReporter& errors, const std::exception& e);

class InputSync {
 public:
  using FrameCallback = std::function<void(std::shared_ptr<Frame>)>;
  InputSync(const RefinerSettings& settings, ErrorReporter& errors) : settings_(settings), errors_(errors) {}

  /// Subscribes the inputs; `on_frame` gets every synchronized, checked set (on the subscribers' thread). An
  /// image transport that cannot be loaded is reported, and nothing is subscribed (error() says why).
  void start(ros::NodeHandle& nh, ros::NodeHandle& pnh, image_transport::ImageTransport& it, FrameCallback on_frame);
  const std::string& error() const { return error_; }
  /// The watchdog (once a second): an error when rgb arrives but no synchronized set for ~sync_timeout.
  void checkSynchronization();
  /// "input <name>": received, synchronized, malformed, unmatched.
  void addDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat);
  void shutdown();

 private:
  enum { kRgb, kInfo, kDepth, kMask, kInputs };
  void noteArrival(int index, const std_msgs::Header& header);
  void rejectInput(int index, const std::string& reason);
  void onSync2(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info);
  void onSync3(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& third);
  void onSync4(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask);
  void onImages(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask);
  bool used(int index) const;

  const RefinerSettings& settings_;
  ErrorReporter& errors_;
  FrameCallback on_frame_;
  std::string error_;  // set at start when an input cannot be subscribed (an unknown transport)

  image_transport::SubscriberFilter rgb_sub_, depth_sub_, mask_sub_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  // Each input checked on its own before the synchronizer (encoding, size, step; intrinsics).
  CheckedInput<sensor_msgs::Image> rgb_in_, depth_in_, mask_in_;
  CheckedInput<sensor_msgs::CameraInfo> info_in_;
  using Policy2 = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo>;
  using Policy3 = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                                  sensor_msgs::Image>;
  using Policy4 = message_filters::sync_policies::ApproximateTime<sensor_msgs::Image, sensor_msgs::CameraInfo,
                                                                  sensor_msgs::Image, sensor_msgs::Image>;
  std::unique_ptr<message_filters::Synchronizer<Policy2>> sync2_;
  std::unique_ptr<message_filters::Synchronizer<Policy3>> sync3_;
  std::unique_ptr<message_filters::Synchronizer<Policy4>> sync4_;

  // Arrivals (mutex_).
  std::mutex mutex_;
  struct Counts {
    long received = 0, malformed = 0, synchronized = 0;
  } counts_[kInputs];
  ros::WallTime last_arrival_[kInputs];  // wall time of the last message of each input
  ros::Time last_stamp_[kInputs];
  /// The first rgb message after a silence (or ever): the watchdog counts from it or the last synchronized set,
  /// whichever is later, so a pause of the inputs is not counted as a failure to pair them.
  ros::WallTime arrivals_resumed_;
  ros::WallTime last_rejected_;  // the last message dropped as malformed: its own error explains the gap
  std::set<std::string> noted_;  // camera_info warnings already given (each once: they hold for every frame)
  ros::WallTime last_sync_;
};

}  // namespace diffdope_ros
