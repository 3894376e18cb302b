// Several instances of one object: association of detections by proximity (instance_tracks.hpp).
#include "diffdope/instance_tracks.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>

namespace diffdope {

InstanceTracks::InstanceTracks(int max_instances, const TrackOptions& options, const Eigen::Vector3d& pivot,
                               double gate)
    : options_(options), pivot_(pivot), gate_(gate) {
  if (max_instances < 1 || max_instances > kMaxInstances)
    throw std::invalid_argument("max_instances = " + std::to_string(max_instances) + " is outside [1, " +
                                std::to_string(kMaxInstances) + "]");
  if (!(std::isfinite(gate) && gate > 0)) throw std::invalid_argument("instance gate must be finite and > 0 metres");
  if (!pivot.allFinite()) throw std::invalid_argument("instance pivot is not finite");
  options.validate();
  instances_.reserve(size_t(max_instances));
  for (int i = 0; i < max_instances; ++i) instances_.push_back({ObjectTrack(options, pivot), std::nullopt});
}

double InstanceTracks::horizon() const { return std::max(options_.track_timeout, options_.max_detection_age); }

bool InstanceTracks::seen(int instance, double stamp) const {
  const auto& last = instances_.at(size_t(instance)).last_seen;
  return last && std::abs(stamp - last->stamp) <= horizon();
}

std::vector<int> InstanceTracks::assign(const std::vector<Pose>& poses, double stamp) const {
  const int n = int(poses.size()), m = size();
  std::vector<int> of_pose(size_t(n), -1);
  if (m == 1) {  // one instance: the best detection, as for an object without instances (the detector's ranking)
    if (n > 0) of_pose[0] = 0;
    return of_pose;
  }
  std::vector<bool> claimed(size_t(m), false);
  std::vector<Eigen::Vector3d> centre(static_cast<size_t>(n));
  for (int p = 0; p < n; ++p) centre[size_t(p)] = poses[size_t(p)] * pivot_;
  auto distance = [&](int p, int i) {
    return (centre[size_t(p)] - instances_[size_t(i)].last_seen->pose * pivot_).norm();
  };
  // (1) Nearest pairs within the gate.
  std::vector<std::tuple<double, int, int>> pairs;
  for (int i = 0; i < m; ++i)
    if (seen(i, stamp))
      for (int p = 0; p < n; ++p)
        if (const double d = distance(p, i); d < gate_) pairs.emplace_back(d, p, i);
  std::sort(pairs.begin(), pairs.end());
  for (const auto& [d, p, i] : pairs)
    if (of_pose[size_t(p)] < 0 && !claimed[size_t(i)]) of_pose[size_t(p)] = i, claimed[size_t(i)] = true;
  // (2) New instances in the free ones, lowest index first.
  for (int p = 0; p < n; ++p) {
    if (of_pose[size_t(p)] >= 0) continue;
    for (int i = 0; i < m; ++i)
      if (!claimed[size_t(i)] && !seen(i, stamp)) {
        of_pose[size_t(p)] = i, claimed[size_t(i)] = true;
        break;
      }
  }
  // (3) The nearest seen instance no pose of this message claimed, whatever the distance.
  for (int p = 0; p < n; ++p) {
    if (of_pose[size_t(p)] >= 0) continue;
    int best = -1;
    for (int i = 0; i < m; ++i)
      if (!claimed[size_t(i)] && (best < 0 || distance(p, i) < distance(p, best))) best = i;
    if (best >= 0) of_pose[size_t(p)] = best, claimed[size_t(best)] = true;
  }
  return of_pose;
}

std::vector<int> InstanceTracks::add_detections(const std::vector<Pose>& poses, double stamp) {
  const std::vector<int> of_pose = assign(poses, stamp);
  for (size_t p = 0; p < poses.size(); ++p) {
    if (of_pose[p] < 0) continue;
    Instance& in = instances_[size_t(of_pose[p])];
    in.track.add_detection(poses[p], stamp);
    in.last_seen = Seed{poses[p], SeedSource::kDetector, stamp};
  }
  return of_pose;
}

bool InstanceTracks::report(int instance, const Pose& refined, bool plausible, double stamp) {
  Instance& in = instances_.at(size_t(instance));
  const bool lost = in.track.report(refined, plausible, stamp);
  if (plausible) in.last_seen = Seed{refined, SeedSource::kTrack, stamp};
  if (lost) in.last_seen.reset();
  return lost;
}

void InstanceTracks::set_options(const TrackOptions& options) {
  options.validate();
  for (Instance& in : instances_) in.track.set_options(options);
  options_ = options;
}

void InstanceTracks::reset() {
  for (Instance& in : instances_) {
    in.track.reset();
    in.last_seen.reset();
  }
}

}  // namespace diffdope
