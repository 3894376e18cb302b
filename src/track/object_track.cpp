#include "diffdope/object_track.hpp"

#include <algorithm>
#include <cmath>

#include "base/option_range.hpp"
#include "diffdope/option_table.hpp"

namespace diffdope {

const char* to_string(SeedSource s) {
  switch (s) {
    case SeedSource::kDetector: return "detector";
    case SeedSource::kTrack: return "track";
    case SeedSource::kPrediction: return "prediction";
    case SeedSource::kRequest: return "request";
  }
  return "unknown";
}

void ObjectTrack::add_detection(const Pose& pose_in_camera, double stamp) {
  // The newest arrival wins, whatever its stamp: one bogus (e.g. future) stamp must not block later detections.
  detection_ = Seed{pose_in_camera, SeedSource::kDetector, stamp};
}

std::optional<Seed> ObjectTrack::take_stale_detection(double image_stamp) {
  if (!detection_ || image_stamp - detection_->stamp <= options_.max_detection_age) return std::nullopt;
  auto d = detection_;  // older than any image to come can use: it never will be
  detection_.reset();
  return d;
}

std::optional<double> ObjectTrack::detection_ahead(double image_stamp) const {
  if (!detection_ || detection_->stamp - image_stamp <= options_.max_detection_age) return std::nullopt;
  return detection_->stamp;
}

bool ObjectTrack::tracking(double now) const {
  return track_ && now - track_->stamp <= options_.track_timeout;
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

std::vector<Seed> ObjectTrack::seeds_for(double image_stamp) {
  std::vector<Seed> out;
  if (has_fresh_detection(image_stamp)) {
    out.push_back(*detection_);
    detection_.reset();
  }
  if (options_.tracking && track_ && image_stamp - track_->stamp <= options_.track_timeout &&
      image_stamp >= track_->stamp - options_.max_detection_age) {
    out.push_back(*track_);
    if (auto p = predict(image_stamp)) out.push_back(*p);
  }
  return out;
}

bool ObjectTrack::steady(double image_stamp) const {
  if (!track_ || !previous_) return false;
  const double interval = track_->stamp - previous_->stamp, age = image_stamp - track_->stamp;
  return interval > 0 && age >= 0 && age <= 2 * interval;
}

std::optional<Seed> ObjectTrack::predict(double image_stamp) const {
  if (!options_.predict || !track_ || !previous_) return std::nullopt;
  const double dt_last = track_->stamp - previous_->stamp, dt = image_stamp - track_->stamp;
  if (!(dt_last > 1e-6) || dt_last > options_.track_timeout || !(dt > 1e-6)) return std::nullopt;
  const double s = std::min(dt / dt_last, options_.max_extrapolation);
  const Pose& a = previous_->pose;
  const Pose& b = track_->pose;
  // The pivot moves on a straight line; the rotation keeps turning about the same axis at the same rate.
  const Eigen::Vector3d ca = a * pivot_, cb = b * pivot_;
  Eigen::AngleAxisd turn(b.R * a.R.transpose());
  if ((cb - ca).norm() < 1e-4 && turn.angle() < 1e-3) return std::nullopt;  // not moving: the track is the guess
  turn.angle() *= s;
  Seed p;
  p.pose.R = turn.toRotationMatrix() * b.R;
  p.pose.t = cb + s * (cb - ca) - p.pose.R * pivot_;
  p.source = SeedSource::kPrediction;
  p.stamp = image_stamp;
  return p;
}

Pose ObjectTrack::reported_pose(const Pose& refined, const ObjectSymmetry& symmetry) const {
  return symmetry.nearest_equivalent(refined, track_ ? track_->pose.R : ObjectSymmetry::canonical_reference());
}

bool ObjectTrack::report(const Pose& refined, bool plausible, double image_stamp) {
  if (plausible) {
    failures_ = 0;
    if (options_.tracking) {
      // Keep the previous pose for the velocity only when it is recent (else the motion estimate is stale);
      // the same frame refined again (a service call after streaming) keeps the velocity it had.
      if (track_ && image_stamp == track_->stamp) {
      } else if (track_ && image_stamp - track_->stamp <= options_.track_timeout && image_stamp > track_->stamp) {
        previous_ = track_;
      } else {
        previous_.reset();
      }
      track_ = Seed{refined, SeedSource::kTrack, image_stamp};
    }
    return false;
  }
  curvature_.reset();  // (the next plausible frame measures its own)
  ++failures_;
  if (failures_ >= options_.max_failures && track_) {
    track_.reset();
    previous_.reset();
    return true;
  }
  return false;
}

void ObjectTrack::note_curvature(const PoseCurvature& curvature, bool carried, const Pose& reported) {
  if (!curvature.valid) {
    curvature_.reset();
  } else if (!carried) {
    curvature_ = MeasuredCurvature{curvature, reported};
    curvature_frames_ = 1;
  } else {
    ++curvature_frames_;
  }
}

std::optional<MeasuredCurvature> ObjectTrack::carried_curvature() const {
  if (!track_ || !curvature_ || curvature_frames_ >= options_.covariance_frames) return std::nullopt;
  return curvature_;
}

void ObjectTrack::reset() {
  curvature_.reset();
  detection_.reset();
  track_.reset();
  previous_.reset();
  failures_ = 0;
}

StartKind start_kind(const std::vector<Seed>& starts) {
  if (starts.empty()) return StartKind::kTracked;
  if (starts.front().source == SeedSource::kRequest) return StartKind::kFresh;
  for (const Seed& s : starts)
    if (s.source == SeedSource::kTrack || s.source == SeedSource::kPrediction) return StartKind::kTracked;
  return starts.front().source == SeedSource::kDetector ? StartKind::kFresh : StartKind::kTracked;
}

cv::Rect detector_box(const Camera& camera, const Mesh& mesh, const std::vector<Seed>& starts) {
  for (const Seed& start : starts) {
    if (start.source != SeedSource::kDetector) continue;
    const Eigen::AlignedBox2d b = camera.project_bounds(mesh.bbox_corners(start.pose), 1e-3);
    if (b.isEmpty()) return cv::Rect();
    const cv::Rect box(cv::Point(int(std::floor(b.min().x())), int(std::floor(b.min().y()))),
                       cv::Point(int(std::ceil(b.max().x())) + 1, int(std::ceil(b.max().y())) + 1));
    return box & cv::Rect(0, 0, camera.width, camera.height);
  }
  return cv::Rect();
}

RefineBudget tracked_budget(const TrackOptions& t) {
  RefineBudget b;
  // A cap, never a raise: a user who lowers the refiner's own budget lowers the tracked one with it.
  if (t.batch_size > 0) b.batch_size = t.batch_size;
  if (t.iterations > 0) b.iterations = t.iterations;
  // A tracked start is not polished (Refiner::refine_all): not in its time budget. It keeps the Newton steps,
  // which converge what its few iterations leave short (the roll of an elongated object: bench_tracking), at
  // most kTrackedNewtonRounds of them.
  b.polish_iterations = 0;
  b.newton_rounds = kTrackedNewtonRounds;
  return b;
}

RefinerOptions tracked_options(const RefinerOptions& o, const TrackOptions& t) {
  return with_budget(o, tracked_budget(t));
}

const std::vector<OptionSpec<TrackOptions>>& track_option_table() {
  using T = TrackOptions;
  static const std::vector<OptionSpec<T>> rows = {
      option_row("max_detection_age", &T::max_detection_age, 0, 3600, " seconds",
                 "between a detection's stamp and the image stamp"),
      option_row("track_timeout", &T::track_timeout, 0, 3600, " seconds", "a refined pose may seed later frames this long"),
      option_row("max_track_failures", &T::max_failures, 1, 1000, "", "implausible refinements in a row that drop a track"),
      option_row("predict_motion", &T::predict, 0, 0, "", "also seed with the constant-velocity prediction"),
      option_row("max_extrapolation", &T::max_extrapolation, 0, 100, " intervals",
                 "the prediction extrapolates at most this multiple of the last interval"),
      option_row("track_batch_size", &T::batch_size, 0, RefinerOptions::kMaxBatchSize, " (0: the refiner's)",
                 "runs per refinement when every object starts from a steady track"),
      option_row("track_iterations", &T::iterations, 0, RefinerOptions::kMaxIterations, " (0: the refiner's)",
                 "iterations per refinement when every object starts from a steady track"),
      option_row("covariance_frames", &T::covariance_frames, 1, 1000, " frames",
                 "frames of a steady track one probe of the covariance serves (1: probed on every frame)"),
  };
  return rows;
}

void TrackOptions::validate() const { check_option_ranges(track_option_table(), *this, {"tracking options"}); }

}  // namespace diffdope
