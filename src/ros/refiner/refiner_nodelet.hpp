#pragma once
// diffdope_ros/RefinerNodelet: the ROS glue around diffdope::Refiner. Thin by design:
//   - inputs: synchronized RGB (+ depth, + mask) and camera_info (InputSync); detector poses (DetectionInbox),
//     transformed with tf2 into the camera optical frame by the worker;
//   - a worker thread runs every refinement (streaming frames and ~refine calls), so callbacks, the service and
//     TF never wait on each other; which instances it refines from which starts: refine_targets.hpp;
//   - outputs: TF, per-object PoseStamped, RefinedPoseArray with scores, overlay image, markers, diagnostics.
// Files: refiner_nodelet.cpp (set-up, hand-over), reconfigure.cpp, worker.cpp, detections_to_tracks.cpp,
// refine_service.cpp, refine_frame.cpp, publishing.cpp, visualization.cpp, diagnostics.cpp.
// Parameters and topics: docs/ros.md.
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <geometry_msgs/PoseStamped.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "diffdope/instance_tracks.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/refine_time.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/RefinedPoseArray.h"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/refine_targets.hpp"
#include "diffdope_ros/refiner_settings.hpp"
#include "diffdope_ros/runtime_settings.hpp"
#include "ros/refiner/detection_inbox.hpp"
#include "ros/refiner/frame.hpp"
#include "ros/refiner/input_sync.hpp"

namespace diffdope_ros {

class RefinerNodelet : public nodelet::Nodelet {
 public:
  RefinerNodelet() = default;
  ~RefinerNodelet() override;  // explicit teardown order: reconfigure, worker, timers, inputs

 private:
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
    std::atomic<int> tracking{0};  // instances whose track is alive (diagnostics; the tracks are the worker's)
  };
  /// A ~refine call waiting for the worker's answer.
  struct Request {
    diffdope_ros::Refine::Request request;
    std::promise<diffdope_ros::Refine::Response> response;
  };
  using SeedList = std::vector<TargetSeeds>;
  using TargetList = std::vector<std::pair<size_t, int>>;  // (slot, instance) per result

  // Set-up and hand-over (refiner_nodelet.cpp).
  void onInit() override;
  void loadObjects();
  void onFrame(std::shared_ptr<Frame> frame);  // a synchronized set: the newest one is the worker's next
  void onWatchdog(const ros::WallTimerEvent&);
  // Runtime tuning (reconfigure.cpp): validates the new values (a refused set reverts `config`), hands them over.
  void setupReconfigure();
  void onReconfigure(RefinerConfig& config, uint32_t level);
  // The worker thread (worker.cpp).
  void workerLoop();
  void applyPendingSettings();  // reconfigured values, if any, into the worker's copies and the tracks
  void processStreaming(const std::shared_ptr<const Frame>& frame);
  std::vector<TargetObject> targetObjects() const;
  void updateTrackingFlags(double stamp);  // Slot::tracking for diagnostics
  // Detections into the tracks (detections_to_tracks.cpp).
  /// A frame much older than the last one processed (a looped bag, a restarted clock): tracks belong to the
  /// other timeline and are dropped, with one warning.
  void resetOnTimeJump(const Frame& frame);
  void absorbDetections(const Frame& frame);
  /// A detector / caller pose into the camera frame at the image stamp, as the mesh's pose. Throws
  /// std::runtime_error (TF failure, NaN, behind the camera).
  diffdope::Pose meshPoseInCamera(const geometry_msgs::PoseStamped& pose, const Slot& slot, const Frame& frame);
  // ~refine (refine_service.cpp): queued for the worker, answered by it.
  bool onRefineService(diffdope_ros::Refine::Request& req, diffdope_ros::Refine::Response& res);
  diffdope_ros::Refine::Response processRequest(const diffdope_ros::Refine::Request& req,
                                                const std::shared_ptr<const Frame>& frame);
  // Refinement (refine_frame.cpp) and its outputs (publishing.cpp, visualization.cpp).
  /// Refines and publishes; objects that could not be refined are named (with the reason) in `skipped`.
  std::vector<diffdope_ros::RefinedPose> refineAndPublish(const Frame& frame, const SeedList& seeds,
                                                          const diffdope::RefinerOptions& options,
                                                          std::vector<std::string>* skipped);
  std::vector<diffdope_ros::RefinedPose> publishResults(const Frame& frame, const SeedList& seeds,
                                                        const TargetList& target_of,
                                                        const std::vector<size_t>& seeds_of,
                                                        const std::vector<diffdope::RefineResult>& results,
                                                        std::vector<std::string>* skipped, ros::WallTime start);
  void reportLostTrack(const Slot& slot, int instance);
  void publishOverlay(const Frame& frame, const TargetList& targets, const std::vector<diffdope::RefineResult>& results);
  void publishMarkers(const Frame& frame, const TargetList& targets, const std::vector<diffdope::RefineResult>& results);
  void onDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat);  // diagnostics.cpp

  // Read by every thread, written only in onInit: the launch-time ~parameters and the objects (whose tracks are
  // the worker's; Slot::tracking is atomic). errors_ and mode_ are thread-safe.
  RefinerSettings settings_;
  ErrorReporter errors_;
  std::atomic<StreamMode> mode_{StreamMode::kTracking};
  std::vector<std::unique_ptr<Slot>> slots_;

  /// The worker thread's alone (after onInit): what refines, and its copies of the tunable settings, changed only
  /// in applyPendingSettings().
  struct WorkerOwned {
    diffdope::RefinerOptions refiner_options;
    diffdope::TrackOptions track_options;
    bool publish_implausible = false;
    std::unique_ptr<diffdope::Refiner> refiner;            // null after a configuration error
    std::unique_ptr<diffdope::Renderer> overlay_renderer;  // for ~overlay
    diffdope::RefineTimeEstimator refine_time;             // learns from every refinement it times
    double last_frame_stamp = 0.0;                         // resetOnTimeJump
  } work_;

  /// The reconfigure callback's (under `mutex`, the server's): the last accepted values. The worker gets them
  /// through Handover::pending_settings.
  struct ReconfigureOwned {
    boost::recursive_mutex mutex;
    std::unique_ptr<dynamic_reconfigure::Server<RefinerConfig>> server;
    RuntimeSettings settings;
    RefinerConfig applied_config;
  } reconfigure_;

  /// The subscriptions, the service and the watchdog (set up in onInit, torn down first).
  struct Inputs {
    Inputs(const RefinerSettings& settings, ErrorReporter& errors) : sync(settings, errors) {}
    std::unique_ptr<image_transport::ImageTransport> it;
    InputSync sync;
    std::unique_ptr<DetectionInbox> inbox;
    ros::ServiceServer refine_service;
    // The service has its own queue and thread: a call waiting for the worker holds none of the manager's
    // threads (which run this nodelet's inputs and every other nodelet in the manager).
    ros::CallbackQueue service_queue;
    std::unique_ptr<ros::AsyncSpinner> service_spinner;
    ros::WallTimer watchdog;
  } inputs_{settings_, errors_};

  /// The publishers (ROS publishers are thread-safe; tf_buffer is read by the worker).
  struct Outputs {
    std::unique_ptr<tf2_ros::Buffer> tf_buffer;
    std::unique_ptr<tf2_ros::TransformListener> tf_listener;
    std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster;
    ros::Publisher refined, markers, ready;
    image_transport::Publisher overlay;
    std::unique_ptr<diagnostic_updater::Updater> diagnostics;
  } outputs_;

  /// What the callbacks hand the worker and the worker reports back: every field under `mutex`.
  struct Handover {
    std::mutex mutex;
    std::condition_variable cv;
    std::shared_ptr<Frame> latest_frame;  // newest synchronized frame (kept for service calls)
    bool frame_pending = false;           // latest_frame not yet processed by streaming
    std::deque<std::shared_ptr<Request>> requests;
    std::optional<RuntimeSettings> pending_settings;  // reconfigured values the worker takes at its next job
    bool stop = false;
    struct Stats {
      long frames_synced = 0, frames_skipped = 0, frames_refined = 0, objects_refined = 0, implausible = 0,
           undetermined = 0;
      long extra_detections = 0;  // detections of an object beyond its max_instances
      long requests_succeeded = 0, requests_failed = 0;  // ~refine calls answered (Refine::Response::success)
      double last_latency = -1, latency_sum = 0, last_refine_ms = 0;
      double ms_per_evaluation = 0;  // work_.refine_time's current cost (copied for diagnostics)
      bool cost_measured = false;    // ... measured here, not the prior
      ros::WallTime serving_since;   // a ~refine call is being served (streaming paused) since; zero if not
      ros::WallTime first_refined, last_refined;
      std::string backend = "none (configuration error)";  // the refiner's, once made
    } stats;
  } handover_;

  std::thread worker_;
};

}  // namespace diffdope_ros
