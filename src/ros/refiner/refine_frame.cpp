// One refinement on a frame: the targets (meshes, starts, each instance's part of its object's mask), one call of
// the node's refiner for all of them, then publishing (publishing.cpp).
#include "diffdope/instance_masks.hpp"
#include "diffdope_ros/conversions.hpp"
#include "ros/refiner/worker.hpp"

namespace diffdope_ros {

std::vector<diffdope_ros::RefinedPose> Worker::refineAndPublish(const Frame& frame, const SeedList& offered,
                                                                        const diffdope::RefinerOptions& options,
                                                                        std::vector<std::string>* skipped) {
  const ros::WallTime start = ros::WallTime::now();
  const SeedList seeds = usableSeeds(frame, offered, options);
  std::vector<diffdope::ObjectTarget> targets;
  TargetList target_of;  // (slot, instance) per target
  std::vector<size_t> seeds_of;
  // An object's mask, split among its instances refined on this frame (one label for all of them).
  std::map<size_t, std::vector<cv::Mat>> instance_masks;
  if (!frame.labels.empty()) {
    std::map<size_t, std::vector<size_t>> of_object;
    for (size_t n = 0; n < seeds.size(); ++n) of_object[seeds[n].object].push_back(n);
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
    const auto& [i, k, starts, steady] = seeds[n];
    Slot& s = *slots_[i];
    const Instance& in = s.instances[size_t(k)];
    diffdope::ObjectTarget t;
    t.mesh = s.mesh.get();
    t.initial = starts.front().pose;
    for (size_t j = 1; j < starts.size(); ++j) t.alternatives.push_back(starts[j].pose);
    t.start_kind = diffdope::start_kind(starts);  // (shape scan, retry: not from a live track)
    if (t.start_kind == diffdope::StartKind::kTracked) t.carried_curvature = s.tracks->track(k).carried_curvature();
    if (steady) t.budget = diffdope::tracked_budget(options_.track);
    if (settings_.mask_source == MaskSource::kBox) t.box = diffdope::detector_box(frame.camera, *s.mesh, starts);
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
  if (targets.empty()) return {};
  // Per-call options (tracking budget, service overrides) run on the node's refiner (its meshes stay cached).
  const ros::WallTime refine_start = ros::WallTime::now();
  std::vector<diffdope::RefineResult> results =
      refiner_->refine_all(frame.camera, frame.observation, targets, options);
  // An undetermined result (with no iteration run, each is its start, unrefined) is never called plausible,
  // whatever the start's scores: it is neither tracked nor put on TF as a refined pose.
  for (diffdope::RefineResult& r : results)
    if (diffdope::verdict_state(r) == diffdope::VerdictState::kUndetermined) r.plausible = false, r.confidence = 0;
  // The cost per evaluation made (RefineResult::evaluations); estimates use planned_evaluations(), an upper
  // bound, so they err long.
  double evaluations = 0;
  for (const diffdope::RefineResult& r : results) evaluations += double(r.evaluations);
  refine_time_.observe(evaluations, (ros::WallTime::now() - refine_start).toSec());
  return publishResults(frame, seeds, target_of, seeds_of, results, skipped, start);
}

Worker::SeedList Worker::usableSeeds(const Frame& frame, const SeedList& offered,
                                     const diffdope::RefinerOptions& options) const {
  SeedList out = offered;
  for (TargetSeeds& target : out) {
    const Slot& s = *slots_[target.object];
    std::vector<diffdope::Pose> poses;
    for (const diffdope::Seed& seed : target.starts) poses.push_back(seed.pose);
    const std::vector<size_t> usable = diffdope::usable_starts(frame.camera, *s.mesh, poses, options);
    if (usable.size() == poses.size()) continue;
    std::vector<bool> keep(poses.size(), false);
    for (size_t k : usable) keep[k] = true;
    std::vector<diffdope::Seed> kept;
    for (size_t k = 0; k < poses.size(); ++k) {
      if (keep[k]) {
        kept.push_back(target.starts[k]);
        continue;
      }
      const std::string why = diffdope::start_problem(frame.camera, *s.mesh, poses[k], options);
      ROS_DEBUG_STREAM("'" << s.instances[size_t(target.instance)].name << "': its "
                           << diffdope::to_string(target.starts[k].source) << " start is left out: " << why);
    }
    target.starts = std::move(kept);
  }
  return out;
}

}  // namespace diffdope_ros
