#pragma once
// The refiner nodelet's worker: the one thread that refines. It takes ~refine calls first, else the newest
// frame, from the Handover; it owns the refiner and its copies of the tunable values, and the objects' tracks
// are its alone. What it shares with the nodelet's other threads it gets by reference, each thread-safe or
// read-only.
// Files: worker.cpp (the loop, settings, streaming), detections_to_tracks.cpp, refine_service.cpp
// (processRequest), refine_frame.cpp, publishing.cpp, visualization.cpp.
#include <geometry_msgs/PoseStamped.h>

#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "diffdope/object_track.hpp"
#include "diffdope/refine_time.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope_ros/Refine.h"
#include "diffdope_ros/RefinedPoseArray.h"
#include "diffdope_ros/error_reporter.hpp"
#include "diffdope_ros/refine_targets.hpp"
#include "diffdope_ros/refiner_settings.hpp"
#include "ros/refiner/detection_inbox.hpp"
#include "ros/refiner/frame.hpp"
#include "ros/refiner/handover.hpp"
#include "ros/refiner/publishers.hpp"
#include "ros/refiner/slot.hpp"

namespace diffdope_ros {

/// The tunable values the worker refines with: set-up's launch values, then what reconfigure hands over.
struct WorkerOptions {
  diffdope::RefinerOptions refiner;
  diffdope::TrackOptions track;
  bool publish_implausible = false;
};

class Worker {
 public:
  /// `refiner` is null after a configuration error (nothing is refined). The rest is the nodelet's, which
  /// outlives the worker.
  Worker(const WorkerOptions& options, std::unique_ptr<diffdope::Refiner> refiner, const RefinerSettings& settings,
         ErrorReporter& errors, const Slots& slots, DetectionInbox& inbox, const Publishers& publishers,
         Handover& handover);
  ~Worker();  // stop()
  Worker(const Worker&) = delete;
  Worker& operator=(const Worker&) = delete;

  void start();  // the thread
  /// Ends the thread after its current job; ~refine calls still waiting are answered that the refiner is
  /// shutting down, and later ones find Handover::stop.
  void stop();

 private:
  using SeedList = std::vector<TargetSeeds>;
  using TargetList = std::vector<std::pair<size_t, int>>;  // (slot, instance) per result

  // The loop and its streaming jobs (worker.cpp).
  void loop();
  void applyPendingSettings();  // reconfigured values, if any, into options_ and the tracks
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
  // A ~refine call's job (refine_service.cpp).
  diffdope_ros::Refine::Response processRequest(const diffdope_ros::Refine::Request& req,
                                                const std::shared_ptr<const Frame>& frame);
  // Refinement (refine_frame.cpp) and its outputs (publishing.cpp, visualization.cpp).
  /// `offered` without the starts the refiner would refuse (diffdope::usable_starts(): a prediction thrown
  /// behind the camera or out of the image by a wrong frame), unless that is all of an instance's starts.
  SeedList usableSeeds(const Frame& frame, const SeedList& offered, const diffdope::RefinerOptions& options) const;
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
  using Results = std::vector<diffdope::RefineResult>;
  void publishOverlay(const Frame& frame, const TargetList& targets, const Results& results);
  void publishMarkers(const Frame& frame, const TargetList& targets, const Results& results);

  // The worker's alone: changed only on its thread (options_ only in applyPendingSettings).
  WorkerOptions options_;
  std::unique_ptr<diffdope::Refiner> refiner_;            // null after a configuration error
  std::unique_ptr<diffdope::Renderer> overlay_renderer_;  // for ~overlay, made on its first subscriber
  diffdope::RefineTimeEstimator refine_time_;             // learns from every refinement it times
  double last_frame_stamp_ = 0.0;                         // resetOnTimeJump

  // Shared with the nodelet's other threads.
  const RefinerSettings& settings_;  // launch-time, read-only
  ErrorReporter& errors_;            // thread-safe
  const Slots& slots_;               // set-up's list; the tracks in it are the worker's
  DetectionInbox& inbox_;            // thread-safe: the callbacks fill it, the worker takes from it
  const Publishers& publishers_;     // thread-safe
  Handover& handover_;               // under its mutex

  std::thread thread_;
};

}  // namespace diffdope_ros
