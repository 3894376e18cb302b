#pragma once
// Which initial pose seeds an object's refinement on a frame (ROS-free, so the policy is unit-tested):
// a fresh detection first; else, in tracking mode, the last plausible refined pose while it is recent; else none.
// A refinement that fails the quality check counts against the track; after max_failures in a row it is lost.
#include <optional>
#include <string>
#include <vector>

#include "diffdope/refine_tuning.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/symmetry.hpp"

namespace diffdope {

struct TrackOptions {
  bool tracking = true;              // seed frames without a fresh detection with the last refined pose
  double max_detection_age = 1.0;    // seconds between a detection's stamp and the image stamp (either way)
  double track_timeout = 3.0;        // seconds a refined pose may seed later frames without a new detection
  int max_failures = 2;              // implausible refinements in a row that drop the track
  /// Also seed with the track extrapolated at constant velocity (from the last two refined poses) when the object
  /// moves: between refined frames a moving object can turn further than the refiner's basin.
  bool predict = true;
  double max_extrapolation = 2.0;    // extrapolate at most this multiple of the last interval
  /// Budget of a refinement whose targets all start from steady tracks (tracked_options()): B runs and iterations
  /// (0: the refiner's own). A track is a frame from the truth, so an eighth of a detection's budget does, the
  /// Newton steps converging what the descent leaves short (bench_tracking, dev_real's tracking level;
  /// docs/benchmarks.md).
  int batch_size = 4;                // [0, RefinerOptions::kMaxBatchSize]
  int iterations = 10;               // [0, RefinerOptions::kMaxIterations]
  /// Frames of a steady track that one probe of the loss's curvature (the covariance) serves, the one it was
  /// measured on included; the others carry it with the pose (ObjectTrack::carried_curvature(),
  /// carry_pose_curvature()). 1: probed on every frame.
  int covariance_frames = 5;         // [1, 1000]
  /// Ranges: ages and timeouts [0, 3600] s, max_failures [1, 1000], max_extrapolation [0, 100]. Throws
  /// std::invalid_argument naming the first field outside its range (names as the node's parameters).
  void validate() const;
};

enum class SeedSource { kDetector, kTrack, kPrediction, kRequest };
const char* to_string(SeedSource s);

/// An initial pose in the camera frame with where it came from. Times in seconds (ROS stamps as doubles).
struct Seed {
  Pose pose;
  SeedSource source = SeedSource::kDetector;
  double stamp = 0;  // the detection's / refined frame's stamp
};

/// The kind of a refinement from `starts` (ObjectTrack::seeds_for(), best first; ObjectTarget::start_kind).
/// kFresh, the full refinement: from a caller's pose, or from a detection when no live track is among the starts.
/// kTracked otherwise: a live track is right or nearly so (the verdict accepted it), and a fresh detection beside
/// it is one more start for the loss to weigh.
StartKind start_kind(const std::vector<Seed>& starts);

/// A detector's box for a refinement from `starts` (ObjectTarget::box): the object's box projected at the first
/// detection among them (DOPE's projected cuboid: its keypoints are the detector's 2D evidence), within the
/// image; empty when no start is a detection (a track's own pose is no detector's evidence) or the object reaches
/// the camera plane.
cv::Rect detector_box(const Camera& camera, const Mesh& mesh, const std::vector<Seed>& starts);


/// The budget of an object that starts from a steady track (start_kind() kTracked and ObjectTrack::steady()):
/// runs and iterations capped at TrackOptions' (where those are set), no polish, and at most kTrackedNewtonRounds
/// Newton rounds (ObjectTarget::budget).
RefineBudget tracked_budget(const TrackOptions& t);
/// The refiner options for a frame whose targets all start from steady tracks: with_budget(o, tracked_budget(t)).
RefinerOptions tracked_options(const RefinerOptions& o, const TrackOptions& t);

class ObjectTrack {
 public:
  /// `pivot`: the point (model frame, e.g. the mesh centre) whose motion is extrapolated linearly; rotation is
  /// extrapolated about it.
  explicit ObjectTrack(const TrackOptions& options = TrackOptions(),
                       const Eigen::Vector3d& pivot = Eigen::Vector3d::Zero())
      : options_((options.validate(), options)), pivot_(pivot) {}

  /// A detection (already in the camera frame) stamped `stamp`. Replaces any unused one (newest arrival wins).
  void add_detection(const Pose& pose_in_camera, double stamp);
  /// Removes and returns the unused detection if it is older than any image stamped `image_stamp` or later can
  /// use (the caller reports it: a detector stamping with another clock must not be ignored silently).
  std::optional<Seed> take_stale_detection(double image_stamp);
  /// Whether a detection not yet used is usable for an image stamped `image_stamp`.
  bool has_fresh_detection(double image_stamp) const;
  /// The stamp of the unused detection when it is ahead of `image_stamp` by more than max_detection_age: kept for
  /// a later image, but none may ever come (a detector on wall time beside sim-time images); the caller reports it.
  std::optional<double> detection_ahead(double image_stamp) const;

  /// The seed for a frame stamped `image_stamp`, or nothing. Marks a chosen detection as used.
  std::optional<Seed> seed_for(double image_stamp);
  /// The seed without consuming anything (service calls: "every object with a known pose").
  std::optional<Seed> peek(double image_stamp) const;
  /// Every usable seed, best guess first: a fresh detection (consumed) and, in tracking mode, the recent track
  /// and its constant-velocity prediction (when the last two refined frames show motion).
  /// The refiner starts runs from each and the loss decides (a detection re-anchors a drifting track; a track
  /// is kept when the detection is worse). Empty when there is none.
  std::vector<Seed> seeds_for(double image_stamp);

  /// The outcome of refining the frame stamped `image_stamp`. Returns true when this loses the track.
  bool report(const Pose& refined, bool plausible, double image_stamp);

  /// After report(): the curvature the refinement measured (RefineResult::curvature; `carried`:
  /// RefineResult::curvature_carried) at `reported`, the pose given to report(). A measured one is kept for
  /// carried_curvature(), a carried one counts a frame of the kept one's use, an invalid one drops it.
  void note_curvature(const PoseCurvature& curvature, bool carried, const Pose& reported);
  /// The curvature to carry to the next frame: the kept one, while the track is live and it has served fewer
  /// than TrackOptions::covariance_frames frames; else nothing (the next frame probes it).
  std::optional<MeasuredCurvature> carried_curvature() const;

  /// The pose to report for `refined` (call before report()), of an object with declared `symmetry`: of its
  /// equivalent poses, the one nearest the track's last pose, so a tracked symmetric object does not spin or flip
  /// between frames even when a fresh detection does; without a track, the canonical one (symmetry.hpp).
  Pose reported_pose(const Pose& refined, const ObjectSymmetry& symmetry) const;

  /// New options from the next call on (runtime tuning); the track and any unused detection are kept, and
  /// judged by the new ages. Validates them (throws std::invalid_argument, leaving the old ones).
  void set_options(const TrackOptions& options) { options_ = (options.validate(), options); }
  const TrackOptions& options() const { return options_; }

  bool tracking() const { return track_.has_value(); }
  /// Whether the track can still seed a frame stamped `now` (not timed out).
  bool tracking(double now) const;
  int failures() const { return failures_; }
  void reset();

  /// Whether the track is steady for a frame stamped `image_stamp`: refined on at least two frames, the last no
  /// longer ago than twice the interval between them. A steady track is near the truth, so the frame may be
  /// refined on TrackOptions' budget (tracked_options()); after a stall (a slow first detection, a busy node) the
  /// object may have moved further than usual and gets the full budget.
  bool steady(double image_stamp) const;
  /// The constant-velocity extrapolation of the track to `image_stamp`, if the track is moving.
  std::optional<Seed> predict(double image_stamp) const;

 private:
  TrackOptions options_;
  std::optional<Seed> detection_;  // latest unused detection
  std::optional<Seed> track_;      // last plausible refined pose
  std::optional<Seed> previous_;   // the one before (constant-velocity prediction)
  Eigen::Vector3d pivot_;
  int failures_ = 0;
  std::optional<MeasuredCurvature> curvature_;  // the last measured (note_curvature())
  int curvature_frames_ = 0;                    // frames it has served
};

}  // namespace diffdope
