// The Worker's outputs for one refinement: the tracks' outcome, per-instance poses (with covariance), TF, the
// RefinedPoseArray with every score, statistics, and the visual outputs while someone subscribes.
#include <geometry_msgs/PoseWithCovarianceStamped.h>

#include <algorithm>

#include "diffdope/pose_curvature.hpp"
#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/worker.hpp"

namespace diffdope_ros {
namespace {

diffdope_ros::RefinedPose refined_pose_msg(const diffdope::RefineResult& r, const diffdope::Seed& seed,
                                           const diffdope::Pose& refined, const diffdope::Pose& inv_model) {
  diffdope_ros::RefinedPose p;
  p.pose.pose = pose_to_msg(refined * inv_model);
  if (r.curvature.valid) {  // the covariance the loss's curvature gives (pose_curvature.hpp), at the frame's origin
    const diffdope::Matrix6d cov = diffdope::covariance_at_origin(r.covariance, r.pivot, (refined * inv_model).t);
    for (int a = 0; a < 6; ++a)
      for (int b = 0; b < 6; ++b) p.covariance[size_t(6 * a + b)] = cov(a, b);
  }
  p.initial_pose = pose_to_msg(seed.pose * inv_model);
  p.source = diffdope::to_string(seed.source);
  p.mask_iou = r.mask_iou;
  p.depth_inliers = r.depth_inliers;
  p.depth_noise = r.depth_noise;
  p.loss = r.loss.total;
  p.initial_loss = r.initial_loss;
  p.converged = r.converged;
  p.print_significance = r.print.significance();
  p.rival_print_significance = r.rival_print;
  p.plausible = r.plausible;
  p.confidence = r.confidence;
  p.judged = r.judged;
  switch (diffdope::verdict_state(r)) {
    case diffdope::VerdictState::kPlausible: p.verdict = diffdope_ros::RefinedPose::PLAUSIBLE; break;
    case diffdope::VerdictState::kImplausible: p.verdict = diffdope_ros::RefinedPose::IMPLAUSIBLE; break;
    case diffdope::VerdictState::kUndetermined: p.verdict = diffdope_ros::RefinedPose::UNDETERMINED; break;
  }
  p.error = diffdope::undetermined_reason(r);
  p.terms = diffdope::used_terms(r.loss_used);
  p.given_mask_replaced = r.given_mask_replaced;
  p.given_mask_offset = r.given_mask_offset;
  p.given_mask_shift = {r.given_mask_shift[0], r.given_mask_shift[1]};
  p.retried = r.retried;
  p.iterations = r.iterations;
  p.time_ms = r.time_ms;
  return p;
}

}  // namespace

std::vector<diffdope_ros::RefinedPose> Worker::publishResults(
    const Frame& frame, const SeedList& seeds, const TargetList& target_of, const std::vector<size_t>& seeds_of,
    const std::vector<diffdope::RefineResult>& results, std::vector<std::string>* skipped, ros::WallTime start) {
  std::vector<diffdope_ros::RefinedPose> out;
  std::vector<geometry_msgs::TransformStamped> transforms;
  int implausible = 0, undetermined = 0, not_refined = 0;
  for (size_t n = 0; n < results.size(); ++n) {
    const auto [i, k] = target_of[n];
    Slot& s = *slots_[i];
    Instance& in = s.instances[size_t(k)];
    const diffdope::RefineResult& r = results[n];
    const std::vector<diffdope::Seed>& starts = seeds[seeds_of[n]].starts;
    const diffdope::Pose inv_model = s.config.model_transform.inverse();
    const auto message = [&](const diffdope::Seed& seed, const diffdope::Pose& pose) {
      diffdope_ros::RefinedPose p = refined_pose_msg(r, seed, pose, inv_model);
      p.name = s.config.name;
      p.instance = k;
      p.pose.header = frame.header;
      return p;
    };
    const diffdope::VerdictState verdict = diffdope::verdict_state(r);
    undetermined += verdict == diffdope::VerdictState::kUndetermined;
    if (!r.error.empty()) {  // in ~refined_poses with its reason, and nowhere else
      errors_.error("refine_" + in.name, "object '" + in.name + "' not refined: " + r.error);
      if (skipped) skipped->push_back(in.name + " (" + r.error + ")");
      if (s.tracks->report(k, starts.front().pose, false, frame.header.stamp.toSec())) reportLostTrack(s, k);
      out.push_back(message(starts.front(), r.pose));
      ++not_refined;
      continue;
    }
    const diffdope::Seed& seed = starts[std::min<size_t>(size_t(r.start), starts.size() - 1)];
    // No spin / flip of a symmetric object between frames.
    const diffdope::Pose refined = s.tracks->track(k).reported_pose(r.pose, s.mesh->symmetry);
    if (s.tracks->report(k, refined, r.plausible, frame.header.stamp.toSec())) reportLostTrack(s, k);
    s.tracks->note_curvature(k, r.curvature, r.curvature_carried, refined);
    implausible += verdict == diffdope::VerdictState::kImplausible;
    diffdope_ros::RefinedPose p = message(seed, refined);
    out.push_back(p);
    if (!r.plausible && !options_.publish_implausible) continue;  // scores still go out in ~refined_poses
    in.pose_pub.publish(p.pose);
    if (r.curvature.valid) {  // the pose with its covariance
      geometry_msgs::PoseWithCovarianceStamped c;
      c.header = p.pose.header;
      c.pose.pose = p.pose.pose;
      c.pose.covariance = p.covariance;
      in.cov_pub.publish(c);
    }
    if (in.last_tf_stamp == frame.header.stamp) continue;  // already on TF for this image: listeners keep the first
    in.last_tf_stamp = frame.header.stamp;
    geometry_msgs::TransformStamped t;
    t.header = frame.header;
    t.child_frame_id = settings_.frame_prefix + in.name;
    t.transform = transform_to_msg(refined * inv_model);
    transforms.push_back(t);
  }
  if (settings_.publish_tf && !transforms.empty()) publishers_.tf_broadcaster->sendTransform(transforms);
  const double latency = (ros::Time::now() - frame.header.stamp).toSec();
  diffdope_ros::RefinedPoseArray array;
  array.header = frame.header;
  array.poses = out;
  array.latency = latency;
  array.processing_time = (ros::WallTime::now() - frame.received).toSec();
  publishers_.refined.publish(array);
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    const ros::WallTime now = ros::WallTime::now();
    if (handover_.stats.frames_refined == 0) handover_.stats.first_refined = now;
    handover_.stats.last_refined = now;
    ++handover_.stats.frames_refined;
    handover_.stats.objects_refined += long(out.size()) - not_refined;
    handover_.stats.implausible += implausible;
    handover_.stats.undetermined += undetermined;
    handover_.stats.last_latency = latency;
    handover_.stats.latency_sum += latency;
    handover_.stats.last_refine_ms = (now - start).toSec() * 1e3;
    handover_.stats.ms_per_evaluation = 1e3 * refine_time_.seconds_per_evaluation();
    handover_.stats.cost_measured = refine_time_.observations() > 0;
    for (const diffdope_ros::RefinedPose& p : out) {
      if (p.depth_noise >= 0) handover_.stats.depth_noise = p.depth_noise;
      if (p.given_mask_offset >= 0) {
        handover_.stats.mask_offset = p.given_mask_offset;
        handover_.stats.mask_shift = {p.given_mask_shift[0], p.given_mask_shift[1]};
      }
    }
  }
  try {  // visualisation must never cost the refinement its result
    if (publishers_.overlay.getNumSubscribers() > 0) publishOverlay(frame, target_of, results);
    if (publishers_.markers.getNumSubscribers() > 0) publishMarkers(frame, target_of, results);
  } catch (const std::exception& e) {
    errors_.error("visualisation", std::string("overlay/markers not published: ") + e.what());
  }
  return out;
}

void Worker::reportLostTrack(const Slot& s, int instance) {
  const std::string& name = s.instances[size_t(instance)].name;
  errors_.warn("lost_" + name, "lost track of '" + name + "' (" + std::to_string(options_.track.max_failures) +
                                   " implausible refinements in a row); waiting for a detection");
}

}  // namespace diffdope_ros
