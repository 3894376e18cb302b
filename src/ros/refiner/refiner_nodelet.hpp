#pragma once
// diffdope_ros/RefinerNodelet: the ROS glue around diffdope::Refiner. Thin by design:
//   - inputs: synchronized RGB (+ depth, + mask) and camera_info (InputSync); detector poses (DetectionInbox),
//     transformed with tf2 into the camera optical frame by the worker;
//   - a worker thread (Worker, worker.hpp) runs every refinement (streaming frames and ~refine calls), so
//     callbacks, the service and TF never wait on each other; which instances it refines from which starts:
//     refine_targets.hpp;
//   - outputs: TF, per-object PoseStamped, RefinedPoseArray with scores, overlay image, markers, diagnostics.
// The nodelet sets up, owns what its threads share (settings, objects: slot.hpp, Publishers, the Handover) and
// runs the callbacks. Files: refiner_nodelet.cpp (set-up, hand-over, teardown), reconfigure.cpp,
// refine_service.cpp (the ~refine callback), diagnostics.cpp; the worker's: worker.hpp.
// Parameters and topics: docs/ros.md.
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <atomic>
#include <memory>

#include "diffdope/refiner.hpp"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/refiner_settings.hpp"
#include "diffdope_ros/runtime_settings.hpp"
#include "ros/refiner/detection_inbox.hpp"
#include "ros/refiner/frame.hpp"
#include "ros/refiner/handover.hpp"
#include "ros/refiner/input_sync.hpp"
#include "ros/refiner/publishers.hpp"
#include "ros/refiner/slot.hpp"
#include "ros/refiner/worker.hpp"

namespace diffdope_ros {

class RefinerNodelet : public nodelet::Nodelet {
 public:
  ~RefinerNodelet() override;  // explicit teardown order: reconfigure, worker, timers, inputs

 private:
  // Set-up and hand-over (refiner_nodelet.cpp).
  void onInit() override;
  /// The objects into slots_; `options` gets the configured refiner and track options. Returns the refiner (null
  /// after a configuration error, which is reported).
  std::unique_ptr<diffdope::Refiner> loadObjects(WorkerOptions& options);
  void onFrame(std::shared_ptr<Frame> frame);  // a synchronized set: the newest one is the worker's next
  void onWatchdog(const ros::WallTimerEvent&);
  // Runtime tuning (reconfigure.cpp): validates the new values (a refused set reverts `config`), hands them over.
  void setupReconfigure(const WorkerOptions& launch);
  void onReconfigure(RefinerConfig& config, uint32_t level);
  // ~refine (refine_service.cpp): queued for the worker, answered by it.
  bool onRefineService(diffdope_ros::Refine::Request& req, diffdope_ros::Refine::Response& res);
  void onDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat);  // diagnostics.cpp

  // Read by every thread, written only in onInit: the launch-time ~parameters and the objects (slot.hpp says what
  // each thread may change in them). errors_ and mode_ are thread-safe.
  RefinerSettings settings_;
  ErrorReporter errors_;
  std::atomic<StreamMode> mode_{StreamMode::kTracking};
  Slots slots_;

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

  Publishers publishers_;
  /// What the callbacks hand the worker and the worker reports back.
  Handover handover_;
  /// Made in onInit once the refiner and the inbox exist. Declared last: it holds references to the members
  /// above, and goes before them.
  std::unique_ptr<Worker> worker_;
};

}  // namespace diffdope_ros
