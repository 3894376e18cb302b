// The Worker's thread (worker.hpp): takes ~refine calls first, else the newest frame; applies reconfigured values
// between jobs; refines streamed frames from their detections and tracks.
#include "ros/refiner/worker.hpp"

#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/input_sync.hpp"  // report_input_error

namespace diffdope_ros {

Worker::Worker(const WorkerOptions& options, std::unique_ptr<diffdope::Refiner> refiner,
               const RefinerSettings& settings, ErrorReporter& errors, const Slots& slots, DetectionInbox& inbox,
               const Publishers& publishers, Handover& handover)
    : options_(options),
      refiner_(std::move(refiner)),
      settings_(settings),
      errors_(errors),
      slots_(slots),
      inbox_(inbox),
      publishers_(publishers),
      handover_(handover) {}

Worker::~Worker() { stop(); }

void Worker::start() { thread_ = std::thread([this] { loop(); }); }

void Worker::stop() {
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    handover_.stop = true;
    for (auto& r : handover_.requests) {
      diffdope_ros::Refine::Response res;
      res.success = false;
      res.message = "the refiner is shutting down";
      r->response.set_value(res);
    }
    handover_.requests.clear();
  }
  handover_.cv.notify_all();
  if (thread_.joinable()) thread_.join();
}

void convert_frame(Frame& frame) {
  frame.observation.rgb = rgb_from_image(*frame.rgb_msg);
  if (frame.depth_msg) frame.observation.depth = depth_from_image(*frame.depth_msg);
  if (frame.mask_msg) frame.labels = labels_from_image(*frame.mask_msg);
  frame.converted = true;
}

void Worker::loop() {
  while (true) {
    std::shared_ptr<Request> job;
    std::shared_ptr<Frame> frame;
    {
      std::unique_lock<std::mutex> lock(handover_.mutex);
      handover_.cv.wait(lock, [this] { return handover_.stop || !handover_.requests.empty() || handover_.frame_pending; });
      if (handover_.stop) return;
      frame = handover_.latest_frame;
      if (!handover_.requests.empty()) {  // service calls first: a caller is waiting
        job = handover_.requests.front();
        handover_.requests.pop_front();
      } else {
        handover_.frame_pending = false;
      }
    }
    applyPendingSettings();
    auto answer_failure = [&job](const std::string& why) {  // never leave a caller waiting
      if (!job) return;
      diffdope_ros::Refine::Response res;
      res.success = false;
      res.message = why;
      try {
        job->response.set_value(res);
      } catch (const std::future_error&) {  // already answered
      }
    };
    if (frame && !frame->converted) {
      try {
        convert_frame(*frame);
      } catch (const std::exception& e) {
        report_input_error(errors_, e);
        answer_failure(std::string("the latest frame is unusable: ") + e.what());
        continue;
      }
    }
    if (job) {  // streaming is paused until the call is answered (diagnostics say so)
      std::lock_guard<std::mutex> lock(handover_.mutex);
      handover_.stats.serving_since = ros::WallTime::now();
    }
    try {
      if (job) {
        const diffdope_ros::Refine::Response res = processRequest(job->request, frame);
        job->response.set_value(res);
        std::lock_guard<std::mutex> lock(handover_.mutex);
        ++(res.success ? handover_.stats.requests_succeeded : handover_.stats.requests_failed);
        if (handover_.latest_frame == frame) handover_.frame_pending = false;  // that frame is done: do not stream it again
      } else {
        processStreaming(frame);
      }
    } catch (const std::exception& e) {  // a bug guard: the node keeps running and says why
      errors_.error("internal", std::string("refinement failed: ") + e.what());
      answer_failure(std::string("refinement failed: ") + e.what());
    } catch (...) {  // not a std::exception: still never take the node down
      errors_.error("internal", "refinement failed with an unknown exception");
      answer_failure("refinement failed with an unknown exception");
    }
    if (job) {
      std::lock_guard<std::mutex> lock(handover_.mutex);
      handover_.stats.serving_since = ros::WallTime();
    }
  }
}

void Worker::applyPendingSettings() {
  std::optional<RuntimeSettings> settings;
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    settings.swap(handover_.pending_settings);
  }
  if (!settings) return;
  try {
    settings->refiner.validate();  // (the refiner takes them per call, with the frame)
    for (auto& slot : slots_)
      if (slot->tracks) slot->tracks->set_options(settings->track);
  } catch (const std::invalid_argument& e) {  // (checked by the callback already: a bug guard)
    errors_.error("reconfigure", std::string("reconfigured values not applied: ") + e.what());
    try {  // back to the values in force (valid: they were accepted before)
      for (auto& slot : slots_)
        if (slot->tracks) slot->tracks->set_options(options_.track);
    } catch (const std::exception&) {
    }
    return;
  }
  options_.refiner = settings->refiner;
  options_.track = settings->track;
  options_.publish_implausible = settings->publish_implausible;
}

std::vector<TargetObject> Worker::targetObjects() const {
  std::vector<TargetObject> objects;
  for (const auto& slot : slots_)
    objects.push_back({slot->config.name, slot->config.max_instances, slot->disabled_reason, slot->tracks.get()});
  return objects;
}

void Worker::processStreaming(const std::shared_ptr<const Frame>& frame) {
  if (!frame) return;
  resetOnTimeJump(*frame);
  absorbDetections(*frame);
  const double stamp = frame->header.stamp.toSec();
  const StreamingTargets targets = streaming_targets(targetObjects(), stamp);
  // An object on a steady track gets the tracking budget (~track_batch_size x ~track_iterations), the others the
  // full one, in the same pass. (What was skipped is logged; only a ~refine call's reply lists it too.)
  if (!targets.seeds.empty()) refineAndPublish(*frame, targets.seeds, options_.refiner, nullptr);
  updateTrackingFlags(stamp);
}

void Worker::updateTrackingFlags(double stamp) {
  for (auto& slot : slots_) {
    int n = 0;
    for (int k = 0; slot->tracks && k < slot->tracks->size(); ++k) n += slot->tracks->track(k).tracking(stamp);
    slot->tracking = n;
  }
}

}  // namespace diffdope_ros
