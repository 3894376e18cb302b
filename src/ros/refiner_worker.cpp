// RefinerNodelet's worker thread: which objects a frame refines and from which starts, the refinement, and
// publishing (TF, poses, scores). Set-up and callbacks: refiner_nodelet.cpp; overlay and markers:
// refiner_visualization.cpp.
#include <tf2/exceptions.h>

#include <algorithm>
#include <geometry_msgs/PoseWithCovarianceStamped.h>

#include "diffdope/instance_masks.hpp"
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
    for (auto& slot : slots_)
      if (slot->tracks) slot->tracks->set_options(settings->track);
  } catch (const std::invalid_argument& e) {  // (checked by the callback already: a bug guard)
    errors_.error("reconfigure", std::string("reconfigured values not applied: ") + e.what());
    try {  // back to the values in force (valid: they were accepted before)
      if (refiner_) refiner_->set_options(refiner_options_);
      for (auto& slot : slots_)
        if (slot->tracks) slot->tracks->set_options(track_options_);
    } catch (const std::exception&) {
    }
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
      // Waits ~tf_timeout in wall time: tf2's own timeout sleeps in ROS time, which stands still while a bag
      // is paused or over (sim time), and the worker would hang there.
      const auto available = [&] {
        return !time_travel ? tf_buffer_->canTransform(camera, source, frame.header.stamp)
                            : tf_buffer_->canTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame_);
      };
      const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(tf_timeout_);
      while (!available() && ros::WallTime::now() < deadline && ros::ok()) ros::WallDuration(0.005).sleep();
      if (!time_travel)  // (throws, saying why, when it is still not there)
        t = tf_buffer_->lookupTransform(camera, source, frame.header.stamp);
      else  // the detection's frame at its own stamp, through a fixed frame to the camera at the image stamp
        t = tf_buffer_->lookupTransform(camera, frame.header.stamp, source, pose.header.stamp, fixed_frame_);
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
    if (slot->tracks) slot->tracks->reset();
    slot->tracking = 0;
  }
  errors_.warn("time", "time went back by " + format_fixed(back, 2) + " s (image stamped " + format_fixed(stamp) +
                           "; a looped bag or a restarted clock?): tracks and unused detections reset");
}

void RefinerNodelet::absorbDetections(const Frame& frame) {
  std::vector<std::pair<size_t, std::vector<geometry_msgs::PoseStamped>>> pending;
  {
    std::lock_guard<std::mutex> lock(detections_mutex_);
    for (size_t i = 0; i < slots_.size(); ++i)
      if (slots_[i]->pending_detections) {
        pending.emplace_back(i, std::move(*slots_[i]->pending_detections));
        slots_[i]->pending_detections.reset();
      }
  }
  for (auto& [i, msgs] : pending) {
    Slot& s = *slots_[i];
    if (!s.tracks) continue;
    std::vector<diffdope::Pose> poses;
    double stamp = frame.header.stamp.toSec();
    for (const auto& msg : msgs) {
      try {
        poses.push_back(meshPoseInCamera(msg, s, frame));
        if (poses.size() == 1 && !msg.header.stamp.isZero()) stamp = msg.header.stamp.toSec();  // (one message)
      } catch (const std::exception& e) {
        errors_.error("pose/" + s.config.name, std::string("initial pose ignored: ") + e.what());
      }
    }
    const std::vector<int> instance = s.tracks->add_detections(poses, stamp);
    const long extra = long(std::count(instance.begin(), instance.end(), -1));
    if (extra > 0) {
      errors_.warn("instances/" + s.config.name,
                   std::to_string(extra) + " detection(s) of '" + s.config.name + "' beyond its max_instances (" +
                       std::to_string(s.config.max_instances) + ") ignored: every instance already had one");
      std::lock_guard<std::mutex> lock(work_mutex_);
      stats_.extra_detections += extra;
    }
  }
  // A detection too old for this frame can never be used (frames only get newer): say so, with both stamps
  // (a detector stamping with another clock, e.g. wall time under sim time, shows up here).
  const double image_stamp = frame.header.stamp.toSec();
  for (auto& slot : slots_)
    for (int k = 0; slot->tracks && k < slot->tracks->size(); ++k)
      if (auto stale = slot->tracks->track(k).take_stale_detection(image_stamp))
        errors_.error("pose/" + slot->config.name,
                      "initial pose of '" + slot->instances[size_t(k)].name + "' ignored: stamped " +
                          format_fixed(stale->stamp) + ", more than ~max_detection_age (" +
                          format_fixed(track_options_.max_detection_age, 1) + " s) before the image at " +
                          format_fixed(image_stamp));
}

void RefinerNodelet::updateTrackingFlags(double stamp) {
  for (auto& slot : slots_) {
    int n = 0;
    for (int k = 0; slot->tracks && k < slot->tracks->size(); ++k) n += slot->tracks->track(k).tracking(stamp);
    slot->tracking = n;
  }
}

void RefinerNodelet::processStreaming(const std::shared_ptr<const Frame>& frame) {
  if (!frame) return;
  resetOnTimeJump(*frame);
  absorbDetections(*frame);
  SeedList seeds;
  const double stamp = frame->header.stamp.toSec();
  for (size_t i = 0; i < slots_.size(); ++i)
    for (int k = 0; slots_[i]->tracks && k < slots_[i]->tracks->size(); ++k) {
      auto starts = slots_[i]->tracks->track(k).seeds_for(stamp);
      if (!starts.empty()) seeds.push_back({i, k, std::move(starts)});
    }
  // Every object on a steady track: the tracking budget (~track_batch_size x ~track_iterations).
  bool all_steady = true;
  for (const auto& s : seeds)
    all_steady = all_steady && !diffdope::explores(s.starts) && slots_[s.slot]->tracks->track(s.instance).steady(stamp);
  std::vector<std::string> skipped;
  if (!seeds.empty())
    refineAndPublish(*frame, seeds,
                     all_steady ? diffdope::tracked_options(refiner_options_, track_options_) : refiner_options_,
                     &skipped);
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
  // The request's own poses, per object: several of one object are its instances (matched to the tracked ones
  // by proximity, else new ones).
  std::map<size_t, std::vector<diffdope::Pose>> requested;
  for (const auto& p : req.initial_poses) {
    const size_t i = size_t(find(p.name));
    try {
      requested[i].push_back(meshPoseInCamera(p.pose, *slots_[i], *frame));
    } catch (const std::exception& e) {
      return fail(e.what());
    }
  }
  SeedList seeds;
  std::vector<std::vector<bool>> chosen(slots_.size());  // per object and instance: already has its start
  for (size_t i = 0; i < slots_.size(); ++i) chosen[i].assign(size_t(slots_[i]->config.max_instances), false);
  for (const auto& [i, poses] : requested) {
    const Slot& s = *slots_[i];
    if (int(poses.size()) > s.config.max_instances)
      return fail("object '" + s.config.name + "' has " + std::to_string(poses.size()) +
                  " initial poses in the request but max_instances " + std::to_string(s.config.max_instances) +
                  " in the objects config");
    const std::vector<int> instance = s.tracks->assign(poses, stamp);
    for (size_t j = 0; j < poses.size(); ++j) {
      const int k = instance[j];  // (never -1: no more poses than instances)
      seeds.push_back({i, k, {diffdope::Seed{poses[j], diffdope::SeedSource::kRequest, stamp}}});
      chosen[i][size_t(k)] = true;
    }
  }
  // Every other instance the request refines: of the named objects, or of all when it names none, those with a
  // start (detection or track). Checked before any detection is used up: a failed request uses none.
  const bool everything = req.object_names.empty() && req.initial_poses.empty();
  std::vector<bool> named(slots_.size(), everything);
  for (const auto& n : req.object_names) named[size_t(find(n))] = true;
  std::vector<std::pair<size_t, int>> known;
  std::vector<std::string> missing;
  for (size_t i = 0; i < slots_.size(); ++i) {
    if (!named[i] || !slots_[i]->tracks) continue;
    bool any = requested.count(i) > 0;
    for (int k = 0; k < slots_[i]->tracks->size(); ++k)
      if (!chosen[i][size_t(k)] && slots_[i]->tracks->track(k).peek(stamp)) known.emplace_back(i, k), any = true;
    if (!any && !everything) missing.push_back(slots_[i]->config.name);
  }
  if (!missing.empty())
    return fail("no initial pose for " + join(missing) + " (no recent detection or track); pass initial_poses");
  // The time budget, before any detection is used up.
  const int targets = int(seeds.size() + known.size());
  if (const std::string why = diffdope::check_request_time(options, targets, refine_time_, max_request_time_);
      !why.empty())
    return fail(why);
  for (const auto& [i, k] : known)
    if (auto starts = slots_[i]->tracks->track(k).seeds_for(stamp); !starts.empty())
      seeds.push_back({i, k, std::move(starts)});
  if (seeds.empty()) return fail("no object has a known pose (no recent detection or track); pass initial_poses");
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
  TargetList target_of;  // (slot, instance) per target
  std::vector<size_t> seeds_of;
  std::vector<diffdope_ros::RefinedPose> out;
  // An object's mask, split among its instances refined on this frame (one label for all of them).
  std::map<size_t, std::vector<cv::Mat>> instance_masks;
  if (!frame.labels.empty()) {
    std::map<size_t, std::vector<size_t>> of_object;
    for (size_t n = 0; n < seeds.size(); ++n) of_object[seeds[n].slot].push_back(n);
    for (const auto& [i, list] : of_object) {
      const Slot& s = *slots_[i];
      const cv::Mat mask = object_mask(frame.labels, s.config.mask_label);
      if (s.config.max_instances == 1) {
        instance_masks[i] = {mask};
        continue;
      }
      std::vector<diffdope::Pose> starts;
      for (size_t n : list) starts.push_back(seeds[n].starts.front().pose);
      instance_masks[i] =
          diffdope::split_mask_among_instances(mask, frame.camera, *s.mesh, starts, options.no_mask_window);
    }
  }
  std::map<size_t, size_t> used_masks;  // per object: how many of its split masks are taken
  for (size_t n = 0; n < seeds.size(); ++n) {
    const auto& [i, k, starts] = seeds[n];
    Slot& s = *slots_[i];
    const Instance& in = s.instances[size_t(k)];
    diffdope::ObjectTarget t;
    t.mesh = s.mesh.get();
    t.initial = starts.front().pose;
    for (size_t j = 1; j < starts.size(); ++j) t.alternatives.push_back(starts[j].pose);
    t.explore = diffdope::explores(starts);  // (shape scan, retry: not from a live track)
    if (!frame.labels.empty()) {
      t.mask = instance_masks[i][used_masks[i]++];
      if (cv::countNonZero(t.mask) == 0) {
        // The segmentation says the object is not visible: refining against an empty mask would push it away.
        errors_.warn("empty_mask_" + in.name, "object '" + in.name + "' has no pixels in the mask (label " +
                                                  std::to_string(s.config.mask_label) + "): not refined");
        if (s.tracks->report(k, t.initial, false, frame.header.stamp.toSec())) reportLostTrack(s, k);
        if (skipped) skipped->push_back(in.name + " (no pixels with its label in the mask)");
        continue;
      }
    }
    targets.push_back(t);
    target_of.emplace_back(i, k);
    seeds_of.push_back(n);
  }
  if (targets.empty()) {
    return out;
  }
  // Per-call overrides (service) run on the node's refiner too (its meshes stay cached), then it is set back.
  struct CallOptions {
    diffdope::Refiner& refiner;
    const diffdope::RefinerOptions saved;
    ~CallOptions() {
      try {
        refiner.set_options(saved);  // (they were in force, so valid: this cannot throw today)
      } catch (...) {
      }
    }
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
  for (size_t n = 0; n < results.size(); ++n) {
    const auto [i, k] = target_of[n];
    Slot& s = *slots_[i];
    Instance& in = s.instances[size_t(k)];
    diffdope::ObjectTrack& track = s.tracks->track(k);
    const diffdope::RefineResult& r = results[n];
    const std::vector<diffdope::Seed>& starts = seeds[seeds_of[n]].starts;
    if (!r.error.empty()) {
      errors_.error("refine_" + in.name, "object '" + in.name + "' not refined: " + r.error);
      if (skipped) skipped->push_back(in.name + " (" + r.error + ")");
      if (s.tracks->report(k, starts.front().pose, false, frame.header.stamp.toSec())) reportLostTrack(s, k);
      continue;
    }
    const diffdope::Seed& seed = starts[std::min<size_t>(size_t(r.start), starts.size() - 1)];
    const diffdope::Pose refined = track.reported_pose(r.pose, s.mesh->symmetry);  // no spin / flip (symmetry)
    if (s.tracks->report(k, refined, r.plausible, frame.header.stamp.toSec())) reportLostTrack(s, k);
    implausible += !r.plausible;
    const diffdope::Pose inv_model = s.config.model_transform.inverse();
    diffdope_ros::RefinedPose p;
    p.name = s.config.name;
    p.instance = k;
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
    in.pose_pub.publish(p.pose);
    if (r.curvature.valid) {  // the pose with the covariance the loss's curvature gives (pose_curvature.hpp)
      geometry_msgs::PoseWithCovarianceStamped c;
      c.header = p.pose.header;
      c.pose.pose = p.pose.pose;
      const diffdope::Matrix6d cov =
          diffdope::covariance_at_origin(r.covariance, r.pivot, (refined * inv_model).t);
      for (int a = 0; a < 6; ++a)
        for (int b = 0; b < 6; ++b) c.pose.covariance[size_t(6 * a + b)] = cov(a, b);
      in.cov_pub.publish(c);
    }
    if (in.last_tf_stamp == frame.header.stamp) continue;  // already on TF for this image: listeners keep the first
    in.last_tf_stamp = frame.header.stamp;
    geometry_msgs::TransformStamped t;
    t.header = frame.header;
    t.child_frame_id = frame_prefix_ + in.name;
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
    if (overlay_pub_.getNumSubscribers() > 0) publishOverlay(frame, target_of, results);
    if (markers_pub_.getNumSubscribers() > 0) publishMarkers(frame, target_of, results);
  } catch (const std::exception& e) {
    errors_.error("visualisation", std::string("overlay/markers not published: ") + e.what());
  }
  return out;
}

void RefinerNodelet::reportLostTrack(const Slot& s, int instance) {
  const std::string& name = s.instances[size_t(instance)].name;
  errors_.warn("lost_" + name, "lost track of '" + name + "' (" + std::to_string(track_options_.max_failures) +
                                   " implausible refinements in a row); waiting for a detection");
}

}  // namespace diffdope_ros
