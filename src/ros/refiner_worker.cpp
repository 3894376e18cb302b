// RefinerNodelet's worker thread: which objects a frame refines and from which starts, the refinement, and
// publishing (TF, poses, scores). Set-up and callbacks: refiner_nodelet.cpp; overlay and markers:
// refiner_visualization.cpp.
#include <tf2/exceptions.h>

#include <algorithm>
#include <geometry_msgs/PoseWithCovarianceStamped.h>

#include "diffdope_ros/conversions.hpp"
#include "diffdope_ros/refiner_nodelet.hpp"

namespace diffdope_ros {

void RefinerNodelet::workerLoop() {
  while (true) {
    std::shared_ptr<Request> job;
    std::shared_ptr<Frame> frame;
    {
      std::unique_lock<std::mutex> lock(work_mutex_);
      work_cv_.wait(lock, [this] { return stop_ || !requests_.empty() || frame_pending_; });
      if (stop_) return;
      frame = latest_frame_;
      if (!requests_.empty()) {  // service calls first: a caller is waiting
        job = requests_.front();
        requests_.pop_front();
      } else {
        frame_pending_ = false;
      }
    }
    applyPendingSettings();
    auto answer_failure = [&job](const std::string& why) {  // never leave a caller waiting
      if (!job) return;
      diffdope_ros::Refine::Response res;
      res.success = false;
      res.message = why;
      try {
        job->response.set_value(res);
      } catch (const std::future_error&) {  // already answered
      }
    };
    if (frame && !frame->converted) {
      try {
        convertFrame(*frame);
      } catch (const std::exception& e) {
        reportInputError(e);
        answer_failure(std::string("the latest frame is unusable: ") + e.what());
        continue;
      }
    }
    if (job) {  // streaming is paused until the call is answered (diagnostics say so)
      std::lock_guard<std::mutex> lock(work_mutex_);
      stats_.serving_since = ros::WallTime::now();
    }
    try {
      if (job) {
        const diffdope_ros::Refine::Response res = processRequest(job->request, frame);
        job->response.set_value(res);
        std::lock_guard<std::mutex> lock(work_mutex_);
        ++(res.success ? stats_.requests_succeeded : stats_.requests_failed);
        if (latest_frame_ == frame) frame_pending_ = false;  // that frame is done: do not stream it again
      } else {
        processStreaming(frame);
      }
    } catch (const std::exception& e) {  // a bug guard: the node keeps running and says why
      errors_.error("internal", std::string("refinement failed: ") + e.what());
      answer_failure(std::string("refinement failed: ") + e.what());
    } catch (...) {  // not a std::exception: still never take the node down
      errors_.error("internal", "refinement failed with an unknown exception");
      answer_failure("refinement failed with an unknown exception");
    }
    if (job) {
      std::lock_guard<std::mutex> lock(work_mutex_);
      stats_.serving_since = ros::WallTime();
    }
  }
}

void RefinerNodelet::applyPendingSettings() {
  std::optional<RuntimeSettings> settings;
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    settings.swap(pending_settings_);
  }
  if (!settings) return;
  try {
    if (refiner_) refiner_->set_options(settings->refiner);  // the same renderer: meshes stay cached
    for (auto& slot : slots_) slot->track.set_options(settings->track);
  } catch (const std::invalid_argument& e) {  // (checked by the callback already: a bug guard)
    errors_.error("reconfigure", std::string("reconfigured values not applied: ") + e.what());
    if (refiner_) refiner_->set_options(refiner_options_);
    for (auto& slot : slots_) slot->track.set_options(track_options_);
    return;
  }
  refiner_options_ = settings->refiner;
  track_options_ = settings->track;
  publish_implausible_ = settings->publish_implausible;
}

void RefinerNodelet::convertFrame(Frame& frame) {
  frame.observation.rgb = rgb_from_image(*frame.rgb_msg);
  if (frame.depth_msg) frame.observation.depth = depth_from_image(*frame.depth_msg);
  if (frame.mask_msg) frame.labels = labels_from_image(*frame.mask_msg);
  frame.converted = true;
}

diffdope::Pose RefinerNodelet::meshPoseInCamera(const geometry_msgs::PoseStamped& pose, const Slot& slot,
                                                const Frame& frame) {
  const std::string what = "initial pose of '" + slot.config.name + "'";
  diffdope::Pose in_source = pose_from_msg(pose.pose, what);
  diffdope::Pose camera_from_source;  // identity when the pose is already in the camera frame
  const std::string camera = strip_slash(frame.header.frame_id), source = strip_slash(pose.header.frame_id);
  // With ~fixed_frame, a pose stamped at another time goes through it even from the camera frame itself (a
  // moving camera: DOPE's poses are in the optical frame of an earlier image).
  const bool time_travel =
      !fixed_frame_.empty() && !pose.header.stamp.isZero() && pose.header.stamp != frame.header.stamp;
  if (source != camera || time_travel) {
    geometry_msgs::TransformStamped t;
    try {
      const ros::Duration timeout(tf_timeout_);
      if (!time_travel)
        t = tf_buffer_->lookupTransform(camera, source, frame.header.stamp, timeout);
      else  // the detection's frame at its own stamp, through a fixed frame to the camera at the image stamp
        t = tf_buffer_->lookupTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame_, timeout);
    } catch (const tf2::TransformException& e) {
      throw std::runtime_error(what + ": no transform from '" + source + "' to '" + camera + "' at t=" +
                               format_fixed(frame.header.stamp.toSec()) + ": " + e.what());
    }
    camera_from_source = pose_from_transform(t.transform, what + " (TF)");
  }
  const diffdope::Pose mesh_pose = camera_from_source * in_source * slot.config.model_transform;
  if (!(mesh_pose.t.z() > refiner_options_.render.near_plane))
    throw std::runtime_error(what + ": the object is behind the camera (z = " + format_fixed(mesh_pose.t.z()) +
                             " m in '" + camera + "')");
  return mesh_pose;
}

void RefinerNodelet::resetOnTimeJump(const Frame& frame) {
  const double stamp = frame.header.stamp.toSec();
  const double back = last_frame_stamp_ - stamp;
  last_frame_stamp_ = std::max(last_frame_stamp_, stamp);
  if (!(back > 1.0)) return;  // frames arrive in order; a small step back is the synchronizer's approximation
  last_frame_stamp_ = stamp;
  for (auto& slot : slots_) {
    slot->track.reset();
    slot->tracking = false;
  }
  errors_.warn("time", "time went back by " + format_fixed(back, 2) + " s (image stamped " + format_fixed(stamp) +
                           "; a looped bag or a restarted clock?): tracks and unused detections reset");
}

void RefinerNodelet::absorbDetections(const Frame& frame) {
  std::vector<std::pair<size_t, geometry_msgs::PoseStamped>> pending;
  {
    std::lock_guard<std::mutex> lock(detections_mutex_);
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->pending_detection) {
        pending.emplace_back(i, *slots_[i]->pending_detection);
        slots_[i]->pending_detection.reset();
      }
  }
  for (auto& [i, msg] : pending) {
    Slot& s = *slots_[i];
    if (!s.mesh) continue;
    try {
      const double stamp = msg.header.stamp.isZero() ? frame.header.stamp.toSec() : msg.header.stamp.toSec();
      s.track.add_detection(meshPoseInCamera(msg, s, frame), stamp);
    } catch (const std::exception& e) {
      errors_.error("pose/" + s.config.name, std::string("initial pose ignored: ") + e.what());
    }
  }
  // A detection too old for this frame can never be used (frames only get newer): say so, with both stamps
  // (a detector stamping with another clock, e.g. wall time under sim time, shows up here).
  const double image_stamp = frame.header.stamp.toSec();
  for (auto& slot : slots_)
    if (auto stale = slot->track.take_stale_detection(image_stamp))
      errors_.error("pose/" + slot->config.name,
                    "initial pose of '" + slot->config.name + "' ignored: stamped " + format_fixed(stale->stamp) +
                        ", more than ~max_detection_age (" + format_fixed(track_options_.max_detection_age, 1) +
                        " s) before the image at " + format_fixed(image_stamp));
}

void RefinerNodelet::updateTrackingFlags(double stamp) {
  for (auto& slot : slots_) slot->tracking = slot->mesh && slot->track.tracking(stamp);
}

void RefinerNodelet::processStreaming(const std::shared_ptr<const Frame>& frame) {
  if (!frame) return;
  resetOnTimeJump(*frame);
  absorbDetections(*frame);
  SeedList seeds;
  const double stamp = frame->header.stamp.toSec();
  for (size_t i = 0; i < slots_.size(); ++i) {
    if (!slots_[i]->mesh) continue;
    auto starts = slots_[i]->track.seeds_for(stamp);
    if (!starts.empty()) seeds.emplace_back(i, std::move(starts));
  }
  std::vector<std::string> skipped;
  if (!seeds.empty()) refineAndPublish(*frame, seeds, refiner_options_, &skipped);
  updateTrackingFlags(stamp);
}

diffdope_ros::Refine::Response RefinerNodelet::processRequest(const diffdope_ros::Refine::Request& req,
                                                              const std::shared_ptr<const Frame>& frame) {
  diffdope_ros::Refine::Response res;
  auto fail = [&](const std::string& why) {
    res.success = false;
    res.message = why;
    errors_.warn("service", "~refine: " + why);
    return res;
  };
  auto find = [&](const std::string& name) -> long {
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->config.name == name) return long(i);
    return -1;
  };
  // Check every name first: a request with a typo refines nothing.
  std::vector<std::string> unknown, disabled;
  for (const auto& n : req.object_names) {
    const long i = find(n);
    if (i < 0) unknown.push_back(n);
    else if (!slots_[i]->mesh) disabled.push_back(n + " (" + slots_[i]->disabled_reason + ")");
  }
  for (const auto& p : req.initial_poses) {
    const long i = find(p.name);
    if (i < 0) unknown.push_back(p.name);
    else if (!slots_[i]->mesh) disabled.push_back(p.name + " (" + slots_[i]->disabled_reason + ")");
  }
  auto join = [](const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
    return s;
  };
  if (!unknown.empty()) return fail("unknown object name(s): " + join(unknown) + " (not in the objects config)");
  if (!disabled.empty()) return fail("object(s) disabled: " + join(disabled));
  if (req.iterations < 0 || req.batch_size < 0) return fail("iterations and batch_size must be >= 0 (0 = configured)");
  if (req.iterations > 1000 || req.batch_size > 256)
    return fail("iterations <= 1000 and batch_size <= 256 per call (the worker would be blocked for too long)");
  diffdope::RefinerOptions options = refiner_options_;
  if (req.iterations > 0) options.iterations = req.iterations;
  if (req.batch_size > 0) options.batch_size = req.batch_size;
  try {
    options.validate();
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  if (!frame) return fail("no synchronized frame received yet (check the input topics)");

  resetOnTimeJump(*frame);
  absorbDetections(*frame);
  const double stamp = frame->header.stamp.toSec();
  SeedList seeds;
  std::vector<bool> chosen(slots_.size(), false);
  for (const auto& p : req.initial_poses) {
    const size_t i = size_t(find(p.name));
    if (chosen[i]) return fail("object '" + p.name + "' has two initial poses in the request");
    try {
      seeds.emplace_back(i, std::vector<diffdope::Seed>{diffdope::Seed{
                                meshPoseInCamera(p.pose, *slots_[i], *frame), diffdope::SeedSource::kRequest, stamp}});
    } catch (const std::exception& e) {
      return fail(e.what());
    }
    chosen[i] = true;
  }
  // Check that every named object has a start before taking any detection (a failed request uses none up).
  std::vector<std::string> missing;
  for (const auto& n : req.object_names) {
    const size_t i = size_t(find(n));
    if (!chosen[i] && !slots_[i]->track.peek(stamp)) missing.push_back(n);
  }
  if (!missing.empty())
    return fail("no initial pose for " + join(missing) + " (no recent detection or track); pass initial_poses");
  // The time budget, before any detection is used up: every object the request will refine has a start by now.
  std::vector<bool> refined = chosen;
  for (const auto& n : req.object_names) refined[size_t(find(n))] = true;
  if (req.object_names.empty() && req.initial_poses.empty())
    for (size_t i = 0; i < slots_.size(); ++i) refined[i] = slots_[i]->mesh && slots_[i]->track.peek(stamp);
  const int objects = int(std::count(refined.begin(), refined.end(), true));
  if (const std::string why = diffdope::check_request_time(options, objects, refine_time_, max_request_time_);
      !why.empty())
    return fail(why);
  if (req.object_names.empty() && req.initial_poses.empty()) {
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->mesh)
        if (auto starts = slots_[i]->track.seeds_for(stamp); !starts.empty()) {
          seeds.emplace_back(i, std::move(starts));
          chosen[i] = true;
        }
    if (seeds.empty()) return fail("no object has a known pose (no recent detection or track); pass initial_poses");
  } else {
    for (const auto& n : req.object_names) {
      const size_t i = size_t(find(n));
      if (chosen[i]) continue;
      if (auto starts = slots_[i]->track.seeds_for(stamp); !starts.empty()) {
        seeds.emplace_back(i, std::move(starts));
        chosen[i] = true;
      }
    }
  }
  std::vector<std::string> skipped;
  res.results = refineAndPublish(*frame, seeds, options, &skipped);
  updateTrackingFlags(stamp);
  int ok = 0;
  for (const auto& r : res.results) ok += r.plausible;
  res.success = skipped.empty();  // every requested object has a result (plausible or not)
  res.message = "refined " + std::to_string(res.results.size()) + " object(s) on the frame at t=" + format_fixed(stamp) +
                ", " + std::to_string(ok) + " plausible";
  if (!skipped.empty()) res.message += "; not refined: " + join(skipped);
  return res;
}

std::vector<diffdope_ros::RefinedPose> RefinerNodelet::refineAndPublish(
    const Frame& frame, const SeedList& seeds, const diffdope::RefinerOptions& options,
    std::vector<std::string>* skipped) {
  const ros::WallTime start = ros::WallTime::now();
  std::vector<diffdope::ObjectTarget> targets;
  std::vector<size_t> slot_of, seeds_of;
  std::vector<diffdope_ros::RefinedPose> out;
  for (size_t n = 0; n < seeds.size(); ++n) {
    const auto& [i, starts] = seeds[n];
    Slot& s = *slots_[i];
    diffdope::ObjectTarget t;
    t.mesh = s.mesh.get();
    t.initial = starts.front().pose;
    for (size_t j = 1; j < starts.size(); ++j) t.alternatives.push_back(starts[j].pose);
    // The shape scan looks for a turn silhouette and depth cannot see: worth it from a detection or a caller's
    // pose; a track that is already right would only risk flipping between frames on a weakly printed object.
    t.explore = starts.front().source == diffdope::SeedSource::kDetector ||
                starts.front().source == diffdope::SeedSource::kRequest;
    if (!frame.labels.empty()) {
      t.mask = object_mask(frame.labels, s.config.mask_label);
      if (cv::countNonZero(t.mask) == 0) {
        // The segmentation says the object is not visible: refining against an empty mask would push it away.
        errors_.warn("empty_mask_" + s.config.name, "object '" + s.config.name + "' has no pixels in the mask (label " +
                                                        std::to_string(s.config.mask_label) + "): not refined");
        if (s.track.report(t.initial, false, frame.header.stamp.toSec())) reportLostTrack(s);
        if (skipped) skipped->push_back(s.config.name + " (no pixels with its label in the mask)");
        continue;
      }
    }
    targets.push_back(t);
    slot_of.push_back(i);
    seeds_of.push_back(n);
  }
  if (targets.empty()) {
    return out;
  }
  // Per-call overrides (service) run on the node's refiner too (its meshes stay cached), then it is set back.
  struct CallOptions {
    diffdope::Refiner& refiner;
    const diffdope::RefinerOptions saved;
    ~CallOptions() { refiner.set_options(saved); }  // (valid: they were in force)
  } call{*refiner_, refiner_->options()};
  refiner_->set_options(options);
  const ros::WallTime refine_start = ros::WallTime::now();
  std::vector<diffdope::RefineResult> results = refiner_->refine_all(frame.camera, frame.observation, targets);
  refine_time_.observe(double(diffdope::planned_evaluations(options)) * double(targets.size()),
                       (ros::WallTime::now() - refine_start).toSec());

  diffdope_ros::RefinedPoseArray array;
  array.header = frame.header;
  std::vector<geometry_msgs::TransformStamped> transforms;
  int implausible = 0;
  for (size_t k = 0; k < results.size(); ++k) {
    Slot& s = *slots_[slot_of[k]];
    const diffdope::RefineResult& r = results[k];
    const std::vector<diffdope::Seed>& starts = seeds[seeds_of[k]].second;
    if (!r.error.empty()) {
      errors_.error("refine_" + s.config.name, "object '" + s.config.name + "' not refined: " + r.error);
      if (skipped) skipped->push_back(s.config.name + " (" + r.error + ")");
      if (s.track.report(starts.front().pose, false, frame.header.stamp.toSec())) reportLostTrack(s);
      continue;
    }
    const diffdope::Seed& seed = starts[std::min<size_t>(size_t(r.start), starts.size() - 1)];
    const diffdope::Pose refined = s.track.reported_pose(r.pose, s.mesh->symmetry);  // no spin / flip (symmetry)
    if (s.track.report(refined, r.plausible, frame.header.stamp.toSec())) reportLostTrack(s);
    implausible += !r.plausible;
    const diffdope::Pose inv_model = s.config.model_transform.inverse();
    diffdope_ros::RefinedPose p;
    p.name = s.config.name;
    p.pose.header = frame.header;
    p.pose.pose = pose_to_msg(refined * inv_model);
    p.initial_pose = pose_to_msg(seed.pose * inv_model);
    p.source = diffdope::to_string(seed.source);
    p.mask_iou = r.mask_iou;
    p.depth_inliers = r.depth_inliers;
    p.loss = r.loss.total;
    p.initial_loss = r.initial_loss;
    p.converged = r.converged;
    p.plausible = r.plausible;
    p.confidence = r.confidence;
    p.iterations = r.iterations;
    p.time_ms = r.time_ms;
    out.push_back(p);
    if (!r.plausible && !publish_implausible_) continue;  // scores still go out in ~refined_poses
    s.pose_pub.publish(p.pose);
    if (r.curvature.valid) {  // the pose with the covariance the loss's curvature gives (pose_curvature.hpp)
      geometry_msgs::PoseWithCovarianceStamped c;
      c.header = p.pose.header;
      c.pose.pose = p.pose.pose;
      const diffdope::Matrix6d cov =
          diffdope::covariance_at_origin(r.covariance, r.pivot, (refined * inv_model).t);
      for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 6; ++j) c.pose.covariance[size_t(6 * i + j)] = cov(i, j);
      s.cov_pub.publish(c);
    }
    if (s.last_tf_stamp == frame.header.stamp) continue;  // already on TF for this image: listeners keep the first
    s.last_tf_stamp = frame.header.stamp;
    geometry_msgs::TransformStamped t;
    t.header = frame.header;
    t.child_frame_id = frame_prefix_ + s.config.name;
    t.transform = transform_to_msg(refined * inv_model);
    transforms.push_back(t);
  }
  if (publish_tf_ && !transforms.empty()) tf_broadcaster_->sendTransform(transforms);
  const double latency = (ros::Time::now() - frame.header.stamp).toSec();
  array.poses = out;
  array.latency = latency;
  array.processing_time = (ros::WallTime::now() - frame.received).toSec();
  refined_pub_.publish(array);
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    const ros::WallTime now = ros::WallTime::now();
    if (stats_.frames_refined == 0) stats_.first_refined = now;
    stats_.last_refined = now;
    ++stats_.frames_refined;
    stats_.objects_refined += long(out.size());
    stats_.implausible += implausible;
    stats_.last_latency = latency;
    stats_.latency_sum += latency;
    stats_.last_refine_ms = (now - start).toSec() * 1e3;
    stats_.ms_per_evaluation = 1e3 * refine_time_.seconds_per_evaluation();
    stats_.cost_measured = refine_time_.observations() > 0;
  }
  try {  // visualisation must never cost the refinement its result
    if (overlay_pub_.getNumSubscribers() > 0) publishOverlay(frame, slot_of, results);
    if (markers_pub_.getNumSubscribers() > 0) publishMarkers(frame, slot_of, results);
  } catch (const std::exception& e) {
    errors_.error("visualisation", std::string("overlay/markers not published: ") + e.what());
  }
  return out;
}

void RefinerNodelet::reportLostTrack(const Slot& s) {
  errors_.warn("lost_" + s.config.name, "lost track of '" + s.config.name + "' (" +
                                            std::to_string(track_options_.max_failures) +
                                            " implausible refinements in a row); waiting for a detection");
}

}  // namespace diffdope_ros
