#pragma once
// What the refiner nodelet's callbacks hand its worker, and what the worker reports back for diagnostics.
#include <ros/time.h>

#include <array>
#include <condition_variable>
#include <deque>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "diffdope_ros/Refine.h"
#include "diffdope_ros/runtime_settings.hpp"
#include "ros/refiner/frame.hpp"

namespace diffdope_ros {

/// A ~refine call waiting for the worker's answer.
struct Request {
  diffdope_ros::Refine::Request request;
  std::promise<diffdope_ros::Refine::Response> response;
};

/// Every field under `mutex`.
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
    double ms_per_evaluation = 0;  // the worker's refine-time estimate (copied for diagnostics)
    // The sensor as the last results measured it: depth noise (metres at 1 m; -1: none), and a given mask's
    // shift onto depth's edge (camera pixels) with the outline offset before it (-1: no mask checked).
    double depth_noise = -1, mask_offset = -1;
    std::array<double, 2> mask_shift{{0, 0}};
    bool cost_measured = false;    // ... measured here, not the prior
    ros::WallTime serving_since;   // a ~refine call is being served (streaming paused) since; zero if not
    ros::WallTime first_refined, last_refined;
    std::string backend = "none (configuration error)";  // the refiner's, once made
  } stats;
};

}  // namespace diffdope_ros
