// RefinerNodelet's diagnostics (once a second, from the watchdog): what runs, what each object is doing, the
// inputs' counts, rates and latencies, and every error and warning category.
#include <cmath>

#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/refiner_nodelet.hpp"

namespace diffdope_ros {
namespace {
/// A given mask this far (camera pixels) off depth's edge as a whole is worth a word: what a colour image not
/// registered to depth shows (a pixel or two is an outline's rounding).
constexpr double kMaskShiftToReport = 3.0;
}  // namespace

void RefinerNodelet::onDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  Handover::Stats s;
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    s = handover_.stats;
  }
  const ErrorReporter::Summary e = errors_.summary();
  const std::string& input_error = inputs_.sync.error();
  int enabled = 0;
  for (const auto& slot : slots_) enabled += slot->mesh != nullptr;
  const double span = (s.last_refined - s.first_refined).toSec();
  const double rate = s.frames_refined > 1 && span > 0 ? (s.frames_refined - 1) / span : 0.0;
  const bool recent_error = e.last_error_time > 0 && ros::WallTime::now().toSec() - e.last_error_time < 10.0;
  // The worker serves ~refine calls before frames: while it does, streaming is paused (and says so).
  const bool on_request = mode_ == StreamMode::kOnRequest, serving = !s.serving_since.isZero();
  const std::string serving_for =
      serving ? format_fixed((ros::WallTime::now() - s.serving_since).toSec(), 1) + " s" : "";
  const std::string streaming = on_request ? (serving ? "off (mode on_request); serving a ~refine call for " + serving_for
                                                      : "off (mode on_request)")
                                           : (serving ? "paused for " + serving_for + ": serving a ~refine call"
                                                      : "running");
  if (!input_error.empty()) stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no input subscribed: " + input_error);
  else if (enabled == 0) stat.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "no object can be refined: " + e.last_error);
  else if (recent_error) stat.summary(diagnostic_msgs::DiagnosticStatus::WARN, e.last_error);
  else stat.summary(diagnostic_msgs::DiagnosticStatus::OK, serving && !on_request ? "streaming " + streaming : "refining");
  stat.add("streaming", streaming);
  stat.add("inputs", input_error.empty() ? "subscribed" : "none: " + input_error);
  stat.add("objects enabled", std::to_string(enabled) + " of " + std::to_string(slots_.size()));
  stat.add("backend", s.backend);
  for (const auto& slot : slots_) {
    const int tracked = slot->tracking, n = slot->config.max_instances;
    std::string state = "disabled: " + slot->disabled_reason;
    if (slot->mesh && n == 1) state = tracked ? "tracking" : "waiting for a pose";
    else if (slot->mesh) state = "tracking " + std::to_string(tracked) + " of up to " + std::to_string(n) + " instances";
    stat.add("object " + slot->config.name, state);
  }
  inputs_.sync.addDiagnostics(stat);
  if (inputs_.inbox) inputs_.inbox->addDiagnostics(stat);
  stat.add("frames synchronized", s.frames_synced);
  stat.add("frames refined", s.frames_refined);
  stat.add("frames skipped (worker busy)", s.frames_skipped);
  stat.add("objects refined", s.objects_refined);
  stat.add("implausible results", s.implausible);
  stat.add("undetermined results (not refined, or nothing could judge them)", s.undetermined);
  stat.add("detections beyond max_instances (ignored)", s.extra_detections);
  stat.add("refine rate (frames/s)", format_fixed(rate, 2));
  stat.add("last latency (s)", format_fixed(s.last_latency));
  stat.add("mean latency (s)", format_fixed(s.frames_refined ? s.latency_sum / s.frames_refined : -1.0));
  stat.add("last refine time (ms)", format_fixed(s.last_refine_ms, 1));
  // The sensor as measured on the last results: what a user checks the camera's driver against.
  stat.add("depth noise at 1 m (mm)", s.depth_noise < 0 ? "not measured" : format_fixed(1e3 * s.depth_noise, 1));
  if (s.mask_offset >= 0) {
    const double shift = std::hypot(s.mask_shift[0], s.mask_shift[1]);
    stat.add("given mask vs depth's edge (px)",
             "offset " + format_fixed(s.mask_offset, 2) + " at the refining scale; shift (" +
                 format_fixed(s.mask_shift[0], 0) + ", " + format_fixed(s.mask_shift[1], 0) + ") camera px" +
                 (shift >= kMaskShiftToReport ? ": the masks sit off the depth image as a whole; is the segmenter's "
                                                "image registered to depth (align_depth, depth_registered)?"
                                              : ""));
  }
  stat.add("~refine calls succeeded", s.requests_succeeded);
  stat.add("~refine calls failed or refused", s.requests_failed);
  stat.add("estimated cost (ms per object and evaluation)",
           s.cost_measured ? format_fixed(s.ms_per_evaluation, 3) + " (measured)"
                           : format_fixed(1e3 * diffdope::RefineTimeEstimator::kPriorSecondsPerEvaluation, 3) + " (prior, nothing timed yet)");
  stat.add("last error", e.last_error);
  for (const auto& kv : e.error_counts) stat.add("errors: " + kv.first, kv.second);
  for (const auto& kv : e.warn_counts) stat.add("warnings: " + kv.first, kv.second);
}

}  // namespace diffdope_ros
