// Which detection of a Detection3DArray seeds which object (detection_selection.hpp).
#include "diffdope_ros/detection_selection.hpp"

#include "diffdope_ros/conversions.hpp"

#include <algorithm>

namespace diffdope_ros {

DetectionSelection select_detections(const DecodedDetectionArray& array,
                                     const std::map<std::string, int64_t>& class_ids) {
  DetectionSelection out;
  std::map<std::string, std::vector<std::pair<double, geometry_msgs::PoseStamped>>> scored;
  for (size_t k = 0; k < array.detections.size(); ++k) {
    const DecodedDetection& d = array.detections[k];
    if (d.results.empty()) continue;
    const DecodedHypothesis* h = nullptr;  // the best usable one
    for (const DecodedHypothesis& r : d.results)
      if (r.problem.empty() && (!h || r.score > h->score)) h = &r;
    if (!h) {
      out.unusable.push_back("detection " + std::to_string(k) + ": " + d.results.front().problem);
      continue;
    }
    std::string name;
    for (const auto& [object, id] : class_ids)
      if (id == h->class_id) name = object;
    if (name.empty()) {
      out.unknown_class_ids.push_back(h->class_id);
      continue;
    }
    geometry_msgs::PoseStamped p;
    const bool own = !d.frame_id.empty();
    p.header.frame_id = own ? d.frame_id : array.frame_id;
    p.header.stamp = own ? ros::Time(d.stamp_sec, d.stamp_nsec) : ros::Time(array.stamp_sec, array.stamp_nsec);
    p.pose = pose_to_msg(h->pose);
    scored[name].emplace_back(h->score, p);
  }
  for (auto& [name, list] : scored) {
    std::stable_sort(list.begin(), list.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    for (auto& entry : list) out.by_object[name].push_back(entry.second);
  }
  return out;
}

}  // namespace diffdope_ros
