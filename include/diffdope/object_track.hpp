#pragma once
// Which initial pose seeds an object's refinement on a frame (ROS-free, so the policy is unit-tested):
// a fresh detection first; else, in tracking mode, the last plausible refined pose while it is recent; else none.
// A refinement that fails the quality check counts against the track; after max_failures in a row it is lost.
#include <optional>
#include <string>

#include "diffdope/pose.hpp"

namespace diffdope {

struct TrackOptions {
  bool tracking = true;              // seed frames without a fresh detection with the last refined pose
  double max_detection_age = 1.0;    // seconds between a detection's stamp and the image stamp (either way)
  double track_timeout = 3.0;        // seconds a refined pose may seed later frames without a new detection
  int max_failures = 2;              // implausible refinements in a row that drop the track
};

enum class SeedSource { kDetector, kTrack, kRequest };
const char* to_string(SeedSource s);

/// An initial pose in the camera frame with where it came from. Times in seconds (ROS stamps as doubles).
struct Seed {
  Pose pose;
  SeedSource source = SeedSource::kDetector;
  double stamp = 0;  // the detection's / refined frame's stamp
};

class ObjectTrack {
 public:
  explicit ObjectTrack(const TrackOptions& options = TrackOptions()) : options_(options) {}

  /// A detection (already in the camera frame) stamped `stamp`. Replaces any unused older detection.
  void add_detection(const Pose& pose_in_camera, double stamp);
  /// Whether a detection not yet used is usable for an image stamped `image_stamp`.
  bool has_fresh_detection(double image_stamp) const;

  /// The seed for a frame stamped `image_stamp`, or nothing. Marks a chosen detection as used.
  std::optional<Seed> seed_for(double image_stamp);
  /// The seed without consuming anything (service calls: "every object with a known pose").
  std::optional<Seed> peek(double image_stamp) const;

  /// The outcome of refining the frame stamped `image_stamp`. Returns true when this loses the track.
  bool report(const Pose& refined, bool plausible, double image_stamp);

  bool tracking() const { return track_.has_value(); }
  int failures() const { return failures_; }
  void reset();

 private:
  TrackOptions options_;
  std::optional<Seed> detection_;  // latest unused detection
  std::optional<Seed> track_;      // last plausible refined pose
  int failures_ = 0;
};

}  // namespace diffdope
