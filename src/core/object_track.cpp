#include "diffdope/object_track.hpp"

#include <cmath>

namespace diffdope {

const char* to_string(SeedSource s) {
  switch (s) {
    case SeedSource::kDetector: return "detector";
    case SeedSource::kTrack: return "track";
    case SeedSource::kRequest: return "request";
  }
  return "unknown";
}

void ObjectTrack::add_detection(const Pose& pose_in_camera, double stamp) {
  if (detection_ && detection_->stamp > stamp) return;  // an older detection arriving late
  detection_ = Seed{pose_in_camera, SeedSource::kDetector, stamp};
}

bool ObjectTrack::has_fresh_detection(double image_stamp) const {
  return detection_ && std::abs(image_stamp - detection_->stamp) <= options_.max_detection_age;
}

std::optional<Seed> ObjectTrack::peek(double image_stamp) const {
  if (has_fresh_detection(image_stamp)) return detection_;
  if (options_.tracking && track_ && image_stamp - track_->stamp <= options_.track_timeout &&
      image_stamp >= track_->stamp - options_.max_detection_age)
    return track_;
  return std::nullopt;
}

std::optional<Seed> ObjectTrack::seed_for(double image_stamp) {
  auto s = peek(image_stamp);
  if (s && s->source == SeedSource::kDetector) detection_.reset();
  return s;
}

bool ObjectTrack::report(const Pose& refined, bool plausible, double image_stamp) {
  if (plausible) {
    failures_ = 0;
    if (options_.tracking) track_ = Seed{refined, SeedSource::kTrack, image_stamp};
    return false;
  }
  ++failures_;
  if (failures_ >= options_.max_failures && track_) {
    track_.reset();
    return true;
  }
  return false;
}

void ObjectTrack::reset() {
  detection_.reset();
  track_.reset();
  failures_ = 0;
}

}  // namespace diffdope
