#pragma once
// diffdope_ros/RefinerNodelet: the ROS glue around diffdope::Refiner. Thin by design:
//   - inputs: synchronized RGB (+ depth, + mask) and camera_info; detector poses (per-object PoseStamped topics
//     and an InitialPoseArray topic) transformed with tf2 into the camera optical frame;
//   - a worker thread runs every refinement (streaming frames and service requests), so callbacks, the
//     service and TF never wait on each other;
//   - outputs: TF, per-object PoseStamped, RefinedPoseArray with scores, overlay image, markers, diagnostics.
// Parameters and topics: docs/ros.md.
#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <image_transport/image_transport.h>
#include <topic_tools/shape_shifter.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "diffdope/mesh.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/instance_tracks.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/refine_time.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope_ros/InitialPoseArray.h"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/RefinedPoseArray.h"
#include "diffdope_ros/checked_input.hpp"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/runtime_settings.hpp"

namespace diffdope_ros {

class RefinerNodelet : public nodelet::Nodelet {
 public:
  RefinerNodelet() = default;
  ~RefinerNodelet() override;  // explicit teardown order: worker, timers, filters, synchronizers

 private:
  using Mode = StreamMode;

  /// One synchronized input set. The callback checks it (encodings, sizes, camera_info) and hands the messages
  /// over; the worker converts the pixels (convertFrame), so frames it skips cost the callbacks nothing.
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
    /// The poses of the latest detector message for this object (raw, any frame; several = several instances).
    std::optional<std::vector<geometry_msgs::PoseStamped>> pending_detections;
    ros::Subscriber detection_sub;
    std::atomic<int> tracking{0};  // instances whose track is alive (diagnostics; the tracks are the worker's)
  };

  /// A unit of worker work: the next streaming frame, or a service request waiting for its response.
  struct Request {
    diffdope_ros::Refine::Request request;
    std::promise<diffdope_ros::Refine::Response> response;
  };

  void onInit() override;
  void loadParameters();
  void loadObjects();
  void setupInputs();

  // Input callbacks (nodelet's single-threaded queue): convert, validate, hand over. Never refine here.
  void onImages(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
                const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask);
  void onSync2(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info);
  void onSync3(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& third);
  void onSync4(const sensor_msgs::ImageConstPtr& rgb, const sensor_msgs::CameraInfoConstPtr& info,
               const sensor_msgs::ImageConstPtr& depth, const sensor_msgs::ImageConstPtr& mask);
  void onDetection(const geometry_msgs::PoseStampedConstPtr& msg, size_t slot);
  void onInitialPoses(const diffdope_ros::InitialPoseArrayConstPtr& msg);
  /// DOPE's vision_msgs/Detection3DArray, read as a ShapeShifter (detection3d_array.hpp).
  void onDetectionArray(const topic_tools::ShapeShifter::ConstPtr& msg);
  void subscribeDetectionArray();
  std::atomic<bool> resubscribe_detections_{false};  // a publisher of another type was seen
  /// Checks and keeps one detector message's poses of an object (one per instance it saw).
  void storeDetections(const std::vector<geometry_msgs::PoseStamped>& poses, size_t slot, const std::string& origin);
  bool onRefineService(diffdope_ros::Refine::Request& req, diffdope_ros::Refine::Response& res);
  /// dynamic_reconfigure: validates the new values (a refused set reverts `config`) and hands them to the worker.
  void onReconfigure(RefinerConfig& config, uint32_t level);
  void setupReconfigure();
  void onWatchdog(const ros::WallTimerEvent&);
  void onDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat);

  // Worker thread.
  void workerLoop();
  /// Takes reconfigured settings, if any, into the refiner, the tracks and the publishing choices.
  void applyPendingSettings();
  /// Converts the frame's pixels once. Throws std::invalid_argument like the conversions.
  void convertFrame(Frame& frame);
  void reportInputError(const std::exception& e);
  void processStreaming(const std::shared_ptr<const Frame>& frame);
  diffdope_ros::Refine::Response processRequest(const diffdope_ros::Refine::Request& req,
                                                const std::shared_ptr<const Frame>& frame);
  /// Transforms a detector / caller pose into the camera frame at the image stamp and returns the mesh pose.
  /// Throws std::runtime_error (TF failure, NaN, behind the camera).
  diffdope::Pose meshPoseInCamera(const geometry_msgs::PoseStamped& pose, const Slot& slot, const Frame& frame);
  void absorbDetections(const Frame& frame);
  /// A frame much older than the last one processed (a looped bag, a restarted clock): tracks and unused
  /// detections belong to the other timeline and are dropped, with one warning. Worker thread only.
  void resetOnTimeJump(const Frame& frame);
  double last_frame_stamp_ = 0.0;  // worker thread only
  /// What a frame refines: object (slot index) and instance, with its initial poses (the refiner shares the
  /// runs among them and the loss decides).
  struct TargetSeeds {
    size_t slot;
    int instance;
    std::vector<diffdope::Seed> starts;
  };
  using SeedList = std::vector<TargetSeeds>;
  using TargetList = std::vector<std::pair<size_t, int>>;  // (slot, instance) per result
  /// Refines and publishes; objects that could not be refined are named (with the reason) in `skipped`.
  std::vector<diffdope_ros::RefinedPose> refineAndPublish(const Frame& frame, const SeedList& seeds,
                                                          const diffdope::RefinerOptions& options,
                                                          std::vector<std::string>* skipped);
  void updateTrackingFlags(double stamp);  // Slot::tracking for diagnostics
  void reportLostTrack(const Slot& slot, int instance);
  void publishOverlay(const Frame& frame, const TargetList& targets, const std::vector<diffdope::RefineResult>& results);
  void publishMarkers(const Frame& frame, const TargetList& targets, const std::vector<diffdope::RefineResult>& results);

  // Parameters. The worker's copies (refiner_options_, track_options_, publish_implausible_) change only in
  // applyPendingSettings(); mode_ is read by the input callbacks too.
  std::atomic<Mode> mode_{Mode::kTracking};
  bool use_depth_ = true, use_mask_ = false, publish_tf_ = true, publish_implausible_ = false;
  int queue_size_ = 10;
  std::string parameter_error_;  // a parameter outside its range (loadParameters): no object is refined
  double max_interval_ = 0.1, sync_timeout_ = 3.0, tf_timeout_ = 0.1;
  /// ~max_request_time: a ~refine call estimated to take longer is refused (it would stop streaming that long).
  double max_request_time_ = 10.0;
  diffdope::RefineTimeEstimator refine_time_;  // the worker's: learns from every refinement it times
  std::string frame_prefix_, fixed_frame_, detection_prefix_;
  std::string detections_topic_;               // ~detections_topic: DOPE's Detection3DArray ("" = off)
  std::map<std::string, int64_t> class_ids_;   // ~class_ids: object name -> DOPE class id
  diffdope::TrackOptions track_options_;
  diffdope::RefinerOptions refiner_options_;
  std::unique_ptr<diffdope::Refiner> refiner_;  // the worker's (null after a configuration error)
  std::unique_ptr<diffdope::Renderer> overlay_renderer_;  // the worker's, for ~overlay

  // Runtime tuning (cfg/Refiner.cfg). The callback thread owns runtime_settings_ / applied_config_ (the last
  // accepted values); the worker takes pending_settings_ (work_mutex_) at its next job.
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<RefinerConfig>> reconfigure_server_;
  RuntimeSettings runtime_settings_;
  RefinerConfig applied_config_;
  std::optional<RuntimeSettings> pending_settings_;

  ErrorReporter errors_;
  std::vector<std::unique_ptr<Slot>> slots_;
  std::mutex detections_mutex_;  // Slot::pending_detections

  // Inputs.
  std::unique_ptr<image_transport::ImageTransport> it_;
  std::string input_error_;  // set at start when an input cannot be subscribed (an unknown transport)
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
  ros::Subscriber initial_poses_sub_, detection_array_sub_;
  struct DetectionArrayCounts {
    long received = 0, used = 0, malformed = 0, unknown_class = 0;
  } detection_array_counts_;  // under arrival_mutex_
  ros::ServiceServer refine_srv_;
  // The service has its own queue and thread: a call waiting for the worker holds none of the manager's
  // threads (which run this nodelet's inputs and every other nodelet in the manager).
  ros::CallbackQueue service_queue_;
  std::unique_ptr<ros::AsyncSpinner> service_spinner_;
  ros::WallTime first_arrival_;  // first rgb message (the sync watchdog before any synchronized set)
  ros::WallTimer watchdog_timer_;

  // Outputs.
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  ros::Publisher refined_pub_, markers_pub_;
  image_transport::Publisher overlay_pub_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;

  // Hand-over between callbacks and the worker.
  std::mutex work_mutex_;
  std::condition_variable work_cv_;
  std::shared_ptr<Frame> latest_frame_;  // newest synchronized frame (kept for service calls)
  bool frame_pending_ = false;                 // latest_frame_ not yet processed by streaming
  std::deque<std::shared_ptr<Request>> requests_;
  bool stop_ = false;
  std::thread worker_;

  // Statistics (work_mutex_).
  struct Stats {
    long frames_synced = 0, frames_skipped = 0, frames_refined = 0, objects_refined = 0, implausible = 0;
    long extra_detections = 0;  // detections of an object beyond its max_instances
    long requests_succeeded = 0, requests_failed = 0;  // ~refine calls answered (Refine::Response::success)
    double last_latency = -1, latency_sum = 0, last_refine_ms = 0;
    double ms_per_evaluation = 0;       // refine_time_'s current cost (copied for diagnostics)
    bool cost_measured = false;         // ... measured here, not the prior
    ros::WallTime serving_since;        // a ~refine call is being served (streaming paused) since; zero if not
    ros::WallTime first_refined, last_refined;
  } stats_;
  ros::WallTime last_arrival_[4];  // rgb, info, depth, mask (wall time of the last message of each)
  struct InputCounts {
    long received = 0, malformed = 0, synchronized = 0;
  } input_counts_[4];              // (arrival_mutex_)
  ros::Time last_stamp_[4];
  ros::WallTime last_sync_;
  std::mutex arrival_mutex_;
  void noteArrival(int index, const std_msgs::Header& header);
  void rejectInput(int index, const std::string& reason);
};

}  // namespace diffdope_ros
