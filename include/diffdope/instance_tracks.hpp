#pragma once
// Several instances of one object (two identical boxes on a table): each instance has its own ObjectTrack and a
// stable index while it is seen, and the detections of a frame are associated with the instances by proximity.
// ROS-free, so the association policy is unit-tested; the node names instance k's TF frame and topics
// <name>_<k> when an object may have more than one instance.
#include <optional>
#include <vector>

#include "diffdope/object_track.hpp"

namespace diffdope {

class InstanceTracks {
 public:
  static constexpr int kMaxInstances = 32;

  /// `max_instances` in [1, kMaxInstances]; `pivot`: the model-frame point (the mesh centre) whose distance
  /// decides the association; `gate` (metres, > 0): a detection nearer than this to an instance's last known
  /// centre is that instance's (the node passes the mesh diameter: two instances cannot be closer than that
  /// without touching). Throws std::invalid_argument on a value outside its range.
  InstanceTracks(int max_instances, const TrackOptions& options, const Eigen::Vector3d& pivot, double gate);

  int size() const { return int(instances_.size()); }
  ObjectTrack& track(int instance) { return instances_.at(size_t(instance)).track; }
  const ObjectTrack& track(int instance) const { return instances_.at(size_t(instance)).track; }
  /// Whether the instance was seen (detected or refined plausibly) within the horizon of `stamp` (the larger
  /// of track_timeout and max_detection_age): an instance that is not is free for a new one.
  bool seen(int instance, double stamp) const;

  /// Which instance each pose of one detector message belongs to (all the object's detections at one stamp,
  /// best first). With one instance, the first (best) pose, wherever it is: as for an object without
  /// instances, and the refiner's loss decides between it and the track. With several: (1) nearest pairs first,
  /// each pose to an unclaimed seen instance within `gate`; (2) the others, in order, to free instances, lowest
  /// index first; (3) what is left, in order, to the nearest unclaimed seen instance whatever the distance.
  /// -1 when every instance already has a pose of this message (more detections than max_instances: the caller
  /// reports them).
  std::vector<int> assign(const std::vector<Pose>& poses, double stamp) const;
  /// assign(), then each assigned pose becomes its instance's detection. Returns assign()'s answer.
  std::vector<int> add_detections(const std::vector<Pose>& poses, double stamp);
  /// The instance's refinement outcome (ObjectTrack::report); a plausible pose is its last known position.
  /// Returns true when this loses the instance's track (the instance is then free).
  bool report(int instance, const Pose& refined, bool plausible, double stamp);
  /// After report(): the instance's ObjectTrack::note_curvature().
  void note_curvature(int instance, const PoseCurvature& curvature, bool carried, const Pose& reported) {
    instances_.at(size_t(instance)).track.note_curvature(curvature, carried, reported);
  }

  void set_options(const TrackOptions& options);
  void reset();

 private:
  struct Instance {
    ObjectTrack track;
    std::optional<Seed> last_seen;  // latest detection or plausible refined pose (association and freeing)
  };
  double horizon() const;
  TrackOptions options_;
  Eigen::Vector3d pivot_;
  double gate_;
  std::vector<Instance> instances_;
};

}  // namespace diffdope
