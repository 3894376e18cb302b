#pragma once
// Which instances of which objects the refiner nodelet refines on a frame, and from which starts: for a streamed
// frame, and for a ~refine call (with the call's checks). Plain C++ over the core's InstanceTracks, so the policy
// is tested without a ROS master; the node adds TF (poses into the camera frame) and publishing.
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "diffdope/instance_tracks.hpp"
#include "diffdope/refiner.hpp"

namespace diffdope_ros {

/// A configured object as the policy sees it; `tracks` is null when the object is disabled (no mesh).
struct TargetObject {
  std::string name;
  int max_instances = 1;
  std::string disabled_reason;
  diffdope::InstanceTracks* tracks = nullptr;
};

/// One instance to refine and its initial poses, best first (the refiner shares its runs among them).
struct TargetSeeds {
  size_t object;
  int instance;
  std::vector<diffdope::Seed> starts;
  bool steady = false;  // a streamed frame's start from a steady track: the tracking budget will do
};

struct StreamingTargets {
  std::vector<TargetSeeds> seeds;
};
/// A streamed frame at `stamp`: every instance with a start (detection, track or prediction). Uses up the
/// detections it takes.
StreamingTargets streaming_targets(const std::vector<TargetObject>& objects, double stamp);

/// What a ~refine call names (Refine.srv, without the poses themselves).
struct RefineRequestNames {
  std::vector<std::string> object_names;  // refine these from their detection or track
  std::vector<std::string> pose_names;    // the object of each initial pose of the call
  int iterations = 0, batch_size = 0;     // 0 = as configured
};

struct CheckedRequest {
  std::string error;                  // empty: the call can be served
  diffdope::RefinerOptions options;   // the configured options with the call's overrides
  std::vector<size_t> pose_object;    // the object of each initial pose
  std::vector<bool> named;            // per object: the call refines it
  bool everything = false;            // the call names nothing: every object with a start
};
/// Checks a call before anything is used up: every name known and enabled (a typo refines nothing), the
/// iteration and run counts within what one call may block the worker for, the resulting options valid.
CheckedRequest check_refine_request(const std::vector<TargetObject>& objects, const RefineRequestNames& request,
                                    const diffdope::RefinerOptions& configured);

struct RequestTargets {
  std::string error;                         // empty: refine `seeds`, then `known` (take_known_starts)
  std::vector<TargetSeeds> seeds;            // the call's own poses, each matched to an instance
  std::vector<std::pair<size_t, int>> known; // other instances the call refines, from a detection or track
};
/// The targets of a checked call at `stamp`; `requested`: the call's poses in the camera frame per object (several
/// of one object are its instances, matched to the tracked ones by proximity, else new ones). Uses nothing up,
/// so that a call refused afterwards (its time budget) costs no detection.
RequestTargets plan_request_targets(const std::vector<TargetObject>& objects, const CheckedRequest& request,
                                    const std::map<size_t, std::vector<diffdope::Pose>>& requested, double stamp);
/// Appends the starts of `known` instances (using up their detections) to `seeds`.
void take_known_starts(const std::vector<TargetObject>& objects, const std::vector<std::pair<size_t, int>>& known,
                       double stamp, std::vector<TargetSeeds>& seeds);

/// "a, b, c"
std::string join_names(const std::vector<std::string>& names);

}  // namespace diffdope_ros
