// Which instances a frame or a ~refine call refines, and from which starts (refine_targets.hpp).
#include "diffdope_ros/refine_targets.hpp"

#include <exception>

namespace diffdope_ros {
namespace {

long find_object(const std::vector<TargetObject>& objects, const std::string& name) {
  for (size_t i = 0; i < objects.size(); ++i)
    if (objects[i].name == name) return long(i);
  return -1;
}

}  // namespace

std::string join_names(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& x : names) s += (s.empty() ? "" : ", ") + x;
  return s;
}

StreamingTargets streaming_targets(const std::vector<TargetObject>& objects, double stamp) {
  StreamingTargets out;
  for (size_t i = 0; i < objects.size(); ++i)
    for (int k = 0; objects[i].tracks && k < objects[i].tracks->size(); ++k) {
      auto starts = objects[i].tracks->track(k).seeds_for(stamp);
      if (!starts.empty()) out.seeds.push_back({i, k, std::move(starts)});
    }
  for (auto& s : out.seeds)
    s.steady = diffdope::start_kind(s.starts) == diffdope::StartKind::kTracked &&
               objects[s.object].tracks->track(s.instance).steady(stamp);
  return out;
}

CheckedRequest check_refine_request(const std::vector<TargetObject>& objects, const RefineRequestNames& request,
                                    const diffdope::RefinerOptions& configured) {
  CheckedRequest out;
  auto fail = [&](const std::string& why) {
    out.error = why;
    return out;
  };
  std::vector<std::string> unknown, disabled;
  const auto check_name = [&](const std::string& name) {
    const long i = find_object(objects, name);
    if (i < 0) unknown.push_back(name);
    else if (!objects[size_t(i)].tracks) disabled.push_back(name + " (" + objects[size_t(i)].disabled_reason + ")");
  };
  for (const auto& n : request.object_names) check_name(n);
  for (const auto& n : request.pose_names) check_name(n);
  if (!unknown.empty()) return fail("unknown object name(s): " + join_names(unknown) + " (not in the objects config)");
  if (!disabled.empty()) return fail("object(s) disabled: " + join_names(disabled));
  if (request.iterations < 0 || request.batch_size < 0)
    return fail("iterations and batch_size must be >= 0 (0 = configured)");
  if (request.iterations > 1000 || request.batch_size > 256)
    return fail("iterations <= 1000 and batch_size <= 256 per call (the worker would be blocked for too long)");
  out.options = configured;
  if (request.iterations > 0) out.options.iterations = request.iterations;
  if (request.batch_size > 0) out.options.batch_size = request.batch_size;
  try {
    out.options.validate();
  } catch (const std::exception& e) {
    return fail(e.what());
  }
  for (const auto& n : request.pose_names) out.pose_object.push_back(size_t(find_object(objects, n)));
  out.everything = request.object_names.empty() && request.pose_names.empty();
  out.named.assign(objects.size(), out.everything);
  for (const auto& n : request.object_names) out.named[size_t(find_object(objects, n))] = true;
  return out;
}

RequestTargets plan_request_targets(const std::vector<TargetObject>& objects, const CheckedRequest& request,
                                    const std::map<size_t, std::vector<diffdope::Pose>>& requested, double stamp) {
  RequestTargets out;
  std::vector<std::vector<bool>> chosen(objects.size());  // per object and instance: already has its start
  for (size_t i = 0; i < objects.size(); ++i) chosen[i].assign(size_t(objects[i].max_instances), false);
  for (const auto& [i, poses] : requested) {
    const TargetObject& o = objects[i];
    if (int(poses.size()) > o.max_instances) {
      out.error = "object '" + o.name + "' has " + std::to_string(poses.size()) +
                  " initial poses in the request but max_instances " + std::to_string(o.max_instances) +
                  " in the objects config";
      return out;
    }
    const std::vector<int> instance = o.tracks->assign(poses, stamp);
    for (size_t j = 0; j < poses.size(); ++j) {
      const int k = instance[j];  // (never -1: no more poses than instances)
      out.seeds.push_back({i, k, {diffdope::Seed{poses[j], diffdope::SeedSource::kRequest, stamp}}});
      chosen[i][size_t(k)] = true;
    }
  }
  // Every other instance the call refines: of the named objects, or of all when it names none, those with a start.
  std::vector<std::string> missing;
  for (size_t i = 0; i < objects.size(); ++i) {
    if (!request.named[i] || !objects[i].tracks) continue;
    bool any = requested.count(i) > 0;
    for (int k = 0; k < objects[i].tracks->size(); ++k)
      if (!chosen[i][size_t(k)] && objects[i].tracks->track(k).peek(stamp)) out.known.emplace_back(i, k), any = true;
    if (!any && !request.everything) missing.push_back(objects[i].name);
  }
  if (!missing.empty())
    out.error = "no initial pose for " + join_names(missing) + " (no recent detection or track); pass initial_poses";
  return out;
}

void take_known_starts(const std::vector<TargetObject>& objects, const std::vector<std::pair<size_t, int>>& known,
                       double stamp, std::vector<TargetSeeds>& seeds) {
  for (const auto& [i, k] : known)
    if (auto starts = objects[i].tracks->track(k).seeds_for(stamp); !starts.empty())
      seeds.push_back({i, k, std::move(starts)});
}

}  // namespace diffdope_ros
