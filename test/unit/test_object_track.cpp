// ObjectTrack (object_track.hpp): which initial pose seeds an object's refinement on each frame.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include <optional>

#include "diffdope/object_track.hpp"
#include "diffdope/primitives.hpp"

using namespace diffdope;

namespace {

Pose at(double x) { return Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, 0, 0.6)); }

TrackOptions options(bool tracking = true) {
  TrackOptions o;
  o.tracking = tracking;
  o.max_detection_age = 1.0;
  o.track_timeout = 3.0;
  o.max_failures = 2;
  return o;
}

void expect_seed(const std::optional<Seed>& s, SeedSource source, double x, double stamp) {
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->source, source) << to_string(s->source);
  EXPECT_DOUBLE_EQ(s->pose.t.x(), x);
  EXPECT_DOUBLE_EQ(s->stamp, stamp);
}

}  // namespace

TEST(ObjectTrack, SourceNames) {
  EXPECT_STREQ(to_string(SeedSource::kDetector), "detector");
  EXPECT_STREQ(to_string(SeedSource::kTrack), "track");
  EXPECT_STREQ(to_string(SeedSource::kRequest), "request");
}

TEST(ObjectTrack, NothingBeforeAnyDetection) {
  ObjectTrack t(options());
  EXPECT_FALSE(t.has_fresh_detection(10.0));
  EXPECT_FALSE(t.peek(10.0).has_value());
  EXPECT_FALSE(t.seed_for(10.0).has_value());
  EXPECT_FALSE(t.tracking());
}

TEST(ObjectTrack, FreshDetectionSeedsOnce) {
  ObjectTrack t(options(false));
  t.add_detection(at(0.1), 10.0);
  EXPECT_TRUE(t.has_fresh_detection(10.2));
  expect_seed(t.seed_for(10.2), SeedSource::kDetector, 0.1, 10.0);
  // Consumed: the next frame gets nothing from it.
  EXPECT_FALSE(t.has_fresh_detection(10.3));
  EXPECT_FALSE(t.seed_for(10.3).has_value());
}

TEST(ObjectTrack, DetectionAgeLimitBothWays) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  EXPECT_TRUE(t.has_fresh_detection(11.0));   // exactly max_detection_age
  EXPECT_TRUE(t.has_fresh_detection(9.0));    // an image older than the detection, within the age
  EXPECT_FALSE(t.has_fresh_detection(11.01)); // stale
  EXPECT_FALSE(t.has_fresh_detection(8.99));
  EXPECT_FALSE(t.seed_for(11.5).has_value());
  // A stale detection is ignored, not consumed: an image closer to its stamp may still use it.
  expect_seed(t.seed_for(10.5), SeedSource::kDetector, 0.1, 10.0);
}

TEST(ObjectTrack, NewOptionsJudgeTheNextCall) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  EXPECT_TRUE(t.has_fresh_detection(10.8));
  TrackOptions strict = options();
  strict.max_detection_age = 0.5;
  t.set_options(strict);
  EXPECT_FALSE(t.has_fresh_detection(10.8));  // the kept detection, judged by the new age
  EXPECT_TRUE(t.has_fresh_detection(10.4));
  strict.max_failures = 0;
  EXPECT_THROW(t.set_options(strict), std::invalid_argument);
  EXPECT_EQ(t.options().max_failures, 2);
  EXPECT_DOUBLE_EQ(t.options().max_detection_age, 0.5);
}

TEST(ObjectTrack, PeekDoesNotConsume) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  expect_seed(t.peek(10.1), SeedSource::kDetector, 0.1, 10.0);
  expect_seed(t.peek(10.1), SeedSource::kDetector, 0.1, 10.0);
  EXPECT_TRUE(t.has_fresh_detection(10.1));
  expect_seed(t.seed_for(10.1), SeedSource::kDetector, 0.1, 10.0);
  EXPECT_FALSE(t.peek(10.1).has_value());
  // Peeking a track does not change it either.
  t.report(at(0.2), true, 10.1);
  expect_seed(t.peek(10.2), SeedSource::kTrack, 0.2, 10.1);
  expect_seed(t.peek(10.2), SeedSource::kTrack, 0.2, 10.1);
  EXPECT_TRUE(t.tracking());
}

TEST(ObjectTrack, TrackSeedsAfterPlausibleReport) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  expect_seed(t.seed_for(10.0), SeedSource::kDetector, 0.1, 10.0);
  EXPECT_FALSE(t.report(at(0.15), true, 10.0));
  EXPECT_TRUE(t.tracking());
  expect_seed(t.seed_for(10.1), SeedSource::kTrack, 0.15, 10.0);
  // The track is not consumed: every frame uses the latest plausible pose.
  EXPECT_FALSE(t.report(at(0.16), true, 10.1));
  expect_seed(t.seed_for(10.2), SeedSource::kTrack, 0.16, 10.1);
  expect_seed(t.seed_for(10.2), SeedSource::kTrack, 0.16, 10.1);
}

TEST(ObjectTrack, NoTrackAfterImplausibleReport) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  EXPECT_FALSE(t.report(at(0.5), false, 10.0));  // no track to lose yet
  EXPECT_FALSE(t.tracking());
  EXPECT_EQ(t.failures(), 1);
  EXPECT_FALSE(t.seed_for(10.1).has_value());
}

TEST(ObjectTrack, FreshDetectionBeatsTrack) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.15), true, 10.0);
  t.add_detection(at(0.3), 10.05);  // a detection of an earlier image, arriving late
  expect_seed(t.seed_for(10.2), SeedSource::kDetector, 0.3, 10.05);
  t.report(at(0.31), true, 10.2);
  expect_seed(t.seed_for(10.3), SeedSource::kTrack, 0.31, 10.2);
}

TEST(ObjectTrack, TrackTimesOut) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.15), true, 10.0);
  expect_seed(t.seed_for(13.0), SeedSource::kTrack, 0.15, 10.0);  // exactly track_timeout
  EXPECT_FALSE(t.seed_for(13.01).has_value());
  // A frame much older than the track does not use it either.
  EXPECT_FALSE(t.seed_for(8.9).has_value());
  expect_seed(t.seed_for(9.5), SeedSource::kTrack, 0.15, 10.0);
}

TEST(ObjectTrack, ConsecutiveFailuresLoseTheTrack) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  EXPECT_FALSE(t.report(at(0.1), true, 10.0));
  EXPECT_EQ(t.failures(), 0);

  EXPECT_FALSE(t.report(at(0.9), false, 10.1));  // one failure: the track still seeds
  EXPECT_EQ(t.failures(), 1);
  EXPECT_TRUE(t.tracking());
  expect_seed(t.seed_for(10.2), SeedSource::kTrack, 0.1, 10.0);  // the last plausible pose, not the failed one

  EXPECT_TRUE(t.report(at(0.9), false, 10.2));  // max_failures in a row: lost
  EXPECT_FALSE(t.tracking());
  EXPECT_FALSE(t.seed_for(10.3).has_value());
  EXPECT_FALSE(t.report(at(0.9), false, 10.3));  // nothing left to lose
}

TEST(ObjectTrack, PlausibleReportResetsFailureCount) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.1), true, 10.0);
  EXPECT_FALSE(t.report(at(0.9), false, 10.1));
  EXPECT_EQ(t.failures(), 1);
  EXPECT_FALSE(t.report(at(0.11), true, 10.2));
  EXPECT_EQ(t.failures(), 0);
  EXPECT_FALSE(t.report(at(0.9), false, 10.3));  // 1 again, not 2
  EXPECT_TRUE(t.tracking());
  expect_seed(t.seed_for(10.4), SeedSource::kTrack, 0.11, 10.2);
  EXPECT_TRUE(t.report(at(0.9), false, 10.4));
  EXPECT_FALSE(t.tracking());
}

TEST(ObjectTrack, MaxFailuresOne) {
  TrackOptions o = options();
  o.max_failures = 1;
  ObjectTrack t(o);
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.1), true, 10.0);
  EXPECT_TRUE(t.report(at(0.9), false, 10.1));
  EXPECT_FALSE(t.tracking());
}

TEST(ObjectTrack, DetectionAfterLostTrackStartsAgain) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.1), true, 10.0);
  t.report(at(0.9), false, 10.1);
  ASSERT_TRUE(t.report(at(0.9), false, 10.2));
  t.add_detection(at(0.2), 10.3);
  expect_seed(t.seed_for(10.3), SeedSource::kDetector, 0.2, 10.3);
  EXPECT_FALSE(t.report(at(0.21), true, 10.3));
  EXPECT_EQ(t.failures(), 0);
  expect_seed(t.seed_for(10.4), SeedSource::kTrack, 0.21, 10.3);
}

TEST(ObjectTrack, TrackingOffNeverSeedsFromTrack) {
  ObjectTrack t(options(false));
  t.add_detection(at(0.1), 10.0);
  expect_seed(t.seed_for(10.0), SeedSource::kDetector, 0.1, 10.0);
  EXPECT_FALSE(t.report(at(0.15), true, 10.0));
  EXPECT_FALSE(t.tracking());
  EXPECT_FALSE(t.peek(10.1).has_value());
  EXPECT_FALSE(t.seed_for(10.1).has_value());
  // Detections still seed every time one arrives.
  t.add_detection(at(0.2), 10.3);
  expect_seed(t.seed_for(10.3), SeedSource::kDetector, 0.2, 10.3);
  // Failures never report a lost track (there is none).
  EXPECT_FALSE(t.report(at(0.9), false, 10.3));
  EXPECT_FALSE(t.report(at(0.9), false, 10.4));
  EXPECT_FALSE(t.report(at(0.9), false, 10.5));
}

TEST(ObjectTrack, NewestArrivalWinsAndStaleDetectionsAreHandedBack) {
  ObjectTrack t(options());
  t.add_detection(at(0.2), 10.3);
  t.add_detection(at(0.1), 10.0);  // arrives last: it wins (a bogus stamp must not block later detections)
  expect_seed(t.peek(10.0), SeedSource::kDetector, 0.1, 10.0);
  // Too old for the current image and every later one: handed back for reporting, and gone.
  EXPECT_FALSE(t.take_stale_detection(10.5).has_value());  // 0.5 s old: max_detection_age is 1 s
  const auto stale = t.take_stale_detection(100.0);
  ASSERT_TRUE(stale.has_value());
  EXPECT_DOUBLE_EQ(stale->stamp, 10.0);
  EXPECT_FALSE(t.peek(100.0).has_value());
  EXPECT_FALSE(t.take_stale_detection(100.0).has_value());
  // A newer detection does replace an unused older one.
  t.add_detection(at(0.4), 10.6);
  expect_seed(t.seed_for(10.6), SeedSource::kDetector, 0.4, 10.6);
  EXPECT_FALSE(t.has_fresh_detection(10.6));
}

TEST(ObjectTrack, ADetectionFarAheadOfTheImageIsKeptAndSaidSo) {
  // A detector on wall time beside sim-time images: its stamp is 100 s after the image's. It is kept (a later
  // image may use it) and handed to the caller to report, each frame it waits; within max_detection_age it is
  // simply fresh.
  ObjectTrack t(options());
  t.add_detection(at(0.1), 110.0);
  EXPECT_FALSE(t.take_stale_detection(10.0).has_value());
  ASSERT_TRUE(t.detection_ahead(10.0).has_value());
  EXPECT_DOUBLE_EQ(*t.detection_ahead(10.0), 110.0);
  EXPECT_FALSE(t.peek(10.0).has_value());
  EXPECT_FALSE(t.detection_ahead(109.5).has_value());  // 0.5 s ahead: fresh
  expect_seed(t.seed_for(109.5), SeedSource::kDetector, 0.1, 110.0);
  EXPECT_FALSE(t.detection_ahead(10.0).has_value());  // used: nothing waits
}

TEST(ObjectTrack, TrackingFlagTimesOutAndSameFrameKeepsVelocity) {
  ObjectTrack t(options(), Eigen::Vector3d::Zero());
  t.report(at(0.1), true, 10.0);
  t.report(at(0.2), true, 10.1);
  EXPECT_TRUE(t.tracking(10.2));
  EXPECT_FALSE(t.tracking(10.1 + options().track_timeout + 0.01));
  ASSERT_TRUE(t.predict(10.2).has_value());
  t.report(at(0.2), true, 10.1);  // the same frame refined again (service after streaming)
  EXPECT_TRUE(t.predict(10.2).has_value()) << "the velocity was lost";
}

TEST(ObjectTrack, ResetForgetsEverything) {
  ObjectTrack t(options());
  t.add_detection(at(0.1), 10.0);
  ASSERT_TRUE(t.seed_for(10.0).has_value());
  t.report(at(0.1), true, 10.0);
  t.report(at(0.9), false, 10.1);
  t.add_detection(at(0.2), 10.2);
  t.reset();
  EXPECT_FALSE(t.tracking());
  EXPECT_EQ(t.failures(), 0);
  EXPECT_FALSE(t.has_fresh_detection(10.2));
  EXPECT_FALSE(t.seed_for(10.2).has_value());
}

TEST(ObjectTrack, SeedsForGivesDetectionAndTrackTogether) {
  diffdope::TrackOptions o;
  o.tracking = true;
  diffdope::ObjectTrack track(o);
  EXPECT_TRUE(track.seeds_for(10.0).empty());
  diffdope::Pose tracked, detected;
  tracked.t = Eigen::Vector3d(0, 0, 0.5);
  detected.t = Eigen::Vector3d(0.01, 0, 0.5);
  track.report(tracked, true, 10.0);
  track.add_detection(detected, 10.05);
  auto seeds = track.seeds_for(10.1);
  ASSERT_EQ(seeds.size(), 2u);
  EXPECT_EQ(seeds[0].source, diffdope::SeedSource::kDetector);
  EXPECT_EQ(seeds[1].source, diffdope::SeedSource::kTrack);
  // The detection was consumed; the track stays.
  seeds = track.seeds_for(10.2);
  ASSERT_EQ(seeds.size(), 1u);
  EXPECT_EQ(seeds[0].source, diffdope::SeedSource::kTrack);
  // Without tracking only detections seed.
  o.tracking = false;
  diffdope::ObjectTrack plain(o);
  plain.report(tracked, true, 10.0);
  EXPECT_TRUE(plain.seeds_for(10.1).empty());
}

TEST(ObjectTrack, PredictsAtConstantVelocityAboutThePivot) {
  diffdope::TrackOptions o;
  o.tracking = true;
  const Eigen::Vector3d pivot(0.0, 0.0, 0.05);  // model-frame centre, off the origin
  diffdope::ObjectTrack track(o, pivot);
  // The object turns 5 deg about z through the pivot and its pivot moves 1 cm in x per 0.1 s.
  auto pose_at = [&](double k) {
    diffdope::Pose p;
    p.R = Eigen::AngleAxisd(k * 5.0 * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Vector3d centre(0.01 * k, 0.0, 0.6);
    p.t = centre - p.R * pivot;
    return p;
  };
  track.report(pose_at(0), true, 10.0);
  EXPECT_FALSE(track.predict(10.3).has_value());  // one pose: no velocity yet
  track.report(pose_at(1), true, 10.1);
  const auto p = track.predict(10.3);  // two intervals later
  ASSERT_TRUE(p.has_value());
  EXPECT_EQ(p->source, diffdope::SeedSource::kPrediction);
  const diffdope::Pose expected = pose_at(3);
  EXPECT_LT((p->pose.t - expected.t).norm(), 1e-9);
  EXPECT_LT(diffdope::rotation_angle(p->pose.R, expected.R), 1e-9);
  // seeds_for offers the track and the prediction.
  const auto seeds = track.seeds_for(10.3);
  ASSERT_EQ(seeds.size(), 2u);
  EXPECT_EQ(seeds[0].source, diffdope::SeedSource::kTrack);
  EXPECT_EQ(seeds[1].source, diffdope::SeedSource::kPrediction);
  // Extrapolation is capped (max_extrapolation intervals).
  const auto far = track.predict(11.0);
  ASSERT_TRUE(far.has_value());
  EXPECT_LT((far->pose * pivot - pose_at(3) * pivot).norm(), 1e-9);
  // A still object gives no prediction (the track is the guess).
  diffdope::ObjectTrack still(o, pivot);
  still.report(pose_at(1), true, 10.0);
  still.report(pose_at(1), true, 10.1);
  EXPECT_FALSE(still.predict(10.2).has_value());
  // predict = false turns it off.
  o.predict = false;
  diffdope::ObjectTrack off(o, pivot);
  off.report(pose_at(0), true, 10.0);
  off.report(pose_at(1), true, 10.1);
  EXPECT_FALSE(off.predict(10.2).has_value());
}

TEST(ObjectTrack, ASymmetricObjectIsReportedWithoutSpinOrFlip) {
  // A can (symmetric about its z axis) whose detector reports it turned arbitrarily about the axis: without a
  // track the reported pose is the canonical one, then every frame the one nearest the track.
  ObjectSymmetry can;
  can.continuous.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero()});
  const auto about_z = [](double deg) {
    return Pose(Eigen::AngleAxisd(deg * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix(), Eigen::Vector3d::Zero());
  };
  const Pose base(Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, 0.3, 0).normalized()).toRotationMatrix(),
                  Eigen::Vector3d(0, 0, 0.6));
  ObjectTrack track;
  const Pose first = track.reported_pose(base * about_z(77), can);
  EXPECT_LT(rotation_angle(first.R, track.reported_pose(base * about_z(-150), can).R), 1e-6);  // canonical
  track.report(first, true, 1.0);
  for (int k = 1; k <= 5; ++k) {
    // The object turns 2 degrees a frame about another axis; the detector's turn about z jumps around.
    const Pose moved = Pose(Eigen::AngleAxisd(k * 2 * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                            Eigen::Vector3d::Zero()) * base;
    const Pose reported = track.reported_pose(moved * about_z(k * 97), can);
    EXPECT_LT(rotation_angle(reported.R, track.reported_pose(moved, can).R), 1e-6);
    EXPECT_LT(rotation_angle(reported.R, first.R) * 180 / M_PI, 2.0 * k + 0.5) << k;  // no spin
    track.report(reported, true, 1.0 + k);
  }
}

TEST(ObjectTrack, OnlyACallersPoseOrADetectionWithoutALiveTrackExplores) {
  const Seed detection{at(0), SeedSource::kDetector, 1.0}, track{at(0.01), SeedSource::kTrack, 0.9},
      prediction{at(0.02), SeedSource::kPrediction, 0.9}, request{at(0), SeedSource::kRequest, 1.0};
  EXPECT_EQ(start_kind({}), StartKind::kTracked);
  EXPECT_EQ(start_kind({detection}), StartKind::kFresh);
  EXPECT_EQ(start_kind({request}), StartKind::kFresh);
  EXPECT_EQ(start_kind({request, track}), StartKind::kFresh);  // a caller asked: the full refinement
  EXPECT_EQ(start_kind({detection, track, prediction}), StartKind::kTracked);  // one more start of a live track
  EXPECT_EQ(start_kind({track}), StartKind::kTracked);
  EXPECT_EQ(start_kind({track, prediction}), StartKind::kTracked);
}

TEST(ObjectTrack, LiveTracksGetTheTrackingBudget) {
  RefinerOptions o;
  o.batch_size = 32;
  o.iterations = 60;
  TrackOptions t;
  const RefinerOptions tracked = tracked_options(o, t);
  EXPECT_EQ(tracked.batch_size, t.batch_size);
  EXPECT_EQ(tracked.iterations, t.iterations);
  EXPECT_LT(planned_evaluations(tracked), planned_evaluations(o) / 4) << planned_evaluations(tracked) << " " << planned_evaluations(o);
  EXPECT_DOUBLE_EQ(tracked.lr_high, o.lr_high);  // nothing else changes
  t.batch_size = 0;  // 0: the refiner's own
  t.iterations = 0;
  EXPECT_EQ(tracked_options(o, t).batch_size, 32);
  EXPECT_EQ(tracked_options(o, t).iterations, 60);
  // A cap: a refiner already cheaper than the tracking budget stays as it is.
  t = TrackOptions();
  o.batch_size = t.batch_size - 1;
  o.iterations = t.iterations - 2;
  EXPECT_EQ(tracked_options(o, t).batch_size, t.batch_size - 1);
  EXPECT_EQ(tracked_options(o, t).iterations, t.iterations - 2);
}

TEST(ObjectTrack, ATrackIsSteadyWhenRefinedTwiceAndNotStalled) {
  ObjectTrack t;
  EXPECT_FALSE(t.steady(1.0));
  t.add_detection(at(0), 1.0);
  t.seeds_for(1.0);
  t.report(at(0), true, 1.0);
  EXPECT_FALSE(t.steady(1.1));  // one refined frame: no interval to judge by
  t.report(at(0.001), true, 1.1);
  EXPECT_TRUE(t.steady(1.2));
  EXPECT_TRUE(t.steady(1.29));  // up to twice the last interval
  EXPECT_FALSE(t.steady(1.5));  // stalled: the object may have moved further than usual
  t.report(at(0.002), true, 1.6);  // a refinement after the stall: steady at the new, slower pace
  EXPECT_TRUE(t.steady(1.7));
  t.report(at(0.0), false, 1.7);
  t.report(at(0.0), false, 1.8);  // lost
  EXPECT_FALSE(t.steady(1.9));
}

// ~mask_source box: the detection's projected model box, clipped to the image; nothing from a track's own pose.
TEST(ObjectTrack, ADetectorsBoxIsTheObjectsBoxProjectedAtTheDetection) {
  const Camera cam(400, 400, 159.5, 119.5, 320, 240);
  const Mesh cube = make_box(Eigen::Vector3d(0.1, 0.1, 0.1), make_flat_texture(Eigen::Vector3f(0.5f, 0.5f, 0.5f)));
  const Pose ahead(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 1.0) - cube.center());
  const Pose track_pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.3, 0, 1.0) - cube.center());
  const cv::Rect box = detector_box(cam, cube, {Seed{track_pose, SeedSource::kTrack}, Seed{ahead, SeedSource::kDetector}});
  // The near face (z = 0.95) spans 0.1 m: 42 px about the centre.
  EXPECT_NEAR(box.x + 0.5 * box.width, 160, 1.5);
  EXPECT_NEAR(box.width, 400 * 0.1 / 0.95, 2.5);
  EXPECT_TRUE(detector_box(cam, cube, {Seed{track_pose, SeedSource::kTrack}}).empty());
  const Pose aside(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.38, 0, 1.0) - cube.center());
  const cv::Rect clipped = detector_box(cam, cube, {Seed{aside, SeedSource::kDetector}});
  EXPECT_EQ(clipped.x + clipped.width, 320);  // within the image
}

TEST(ObjectTrack, AMeasuredCurvatureServesCovarianceFramesThenIsProbedAgain) {
  TrackOptions o = options();
  o.covariance_frames = 3;
  ObjectTrack t(o);
  PoseCurvature measured;
  measured.valid = true;
  measured.hessian = 2 * Matrix6d::Identity();
  const auto frame = [&](double stamp, const PoseCurvature& c, bool carried) {
    EXPECT_FALSE(t.report(at(stamp - 10.0), true, stamp));
    t.note_curvature(c, carried, at(stamp - 10.0));
  };
  EXPECT_FALSE(t.carried_curvature());  // nothing measured yet
  t.add_detection(at(0.1), 10.0);
  frame(10.0, measured, false);
  ASSERT_TRUE(t.carried_curvature());
  EXPECT_EQ(t.carried_curvature()->curvature.hessian, measured.hessian);
  EXPECT_EQ(t.carried_curvature()->pose.t, at(0.0).t);  // the pose it was measured at
  frame(10.1, measured, true);  // the second frame it serves
  EXPECT_TRUE(t.carried_curvature());
  frame(10.2, measured, true);  // the third: the next frame probes again
  EXPECT_FALSE(t.carried_curvature());
  frame(10.3, measured, false);
  EXPECT_NEAR(t.carried_curvature()->pose.t.x(), 0.3, 1e-9);
  // An implausible frame, an invalid curvature or a reset drops it.
  EXPECT_FALSE(t.report(at(0.2), false, 10.4));
  EXPECT_FALSE(t.carried_curvature());
  frame(10.5, measured, false);
  frame(10.6, PoseCurvature(), false);
  EXPECT_FALSE(t.carried_curvature());
  frame(10.7, measured, false);
  t.reset();
  EXPECT_FALSE(t.carried_curvature());
  // covariance_frames 1: probed on every frame.
  o.covariance_frames = 1;
  ObjectTrack every(o);
  every.add_detection(at(0.1), 10.0);
  EXPECT_FALSE(every.report(at(0.1), true, 10.0));
  every.note_curvature(measured, false, at(0.1));
  EXPECT_FALSE(every.carried_curvature());
}
