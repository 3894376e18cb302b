// Joint readings and stillness around an image stamp (joint_history.hpp).
#include "diffdope/joint_history.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "diffdope/option_range.hpp"

namespace diffdope {

void StillnessOptions::validate() const {
  const OptionRange check{"stillness options"};
  check.above("max_joint_velocity", max_velocity, 0, 10, " rad/s");
  check("still_window", window, 0, 10, " s");
  check.above("max_joint_gap", max_gap, 0, 10, " s");
  check("joint_history", keep, 1, 3600, " s");
}

JointHistory::JointHistory(const StillnessOptions& options) : options_((options.validate(), options)) {}

void JointHistory::add(const JointReading& reading) {
  const auto at = std::upper_bound(readings_.begin(), readings_.end(), reading.stamp,
                                   [](double s, const JointReading& r) { return s < r.stamp; });
  readings_.insert(at, reading);
  const double newest = readings_.back().stamp;
  while (!readings_.empty() && readings_.front().stamp < newest - options_.keep) readings_.pop_front();
}

std::optional<std::map<std::string, double>> JointHistory::still_at(double stamp, std::string* why) const {
  const auto say = [&](const std::string& s) {
    if (why) *why = s;
    return std::nullopt;
  };
  if (readings_.empty()) return say("no joint states received");
  const JointReading* nearest = &readings_.front();
  for (const JointReading& r : readings_)
    if (std::abs(r.stamp - stamp) < std::abs(nearest->stamp - stamp)) nearest = &r;
  std::ostringstream m;
  m.precision(3);
  if (std::abs(nearest->stamp - stamp) > options_.max_gap) {
    m << std::fixed << "no joint state within " << options_.max_gap << " s of the image (nearest "
      << nearest->stamp - stamp << " s away): are the clocks the same?";
    return say(m.str());
  }
  if (readings_.back().stamp < stamp + options_.window) {
    m << "the joint states do not yet cover " << options_.window << " s after the image: try again";
    return say(m.str());
  }
  // Every joint's speed inside the window: the reported velocities, and the differences of positions.
  const JointReading* previous = nullptr;
  for (const JointReading& r : readings_) {
    if (r.stamp < stamp - options_.window || r.stamp > stamp + options_.window) continue;
    for (const auto& [name, v] : r.velocity)
      if (std::abs(v) > options_.max_velocity) {
        m << "the robot is moving: joint '" << name << "' at " << v << " rad/s (~max_joint_velocity "
          << options_.max_velocity << ")";
        return say(m.str());
      }
    if (previous && r.stamp > previous->stamp)
      for (const auto& [name, q] : r.position) {
        const auto p = previous->position.find(name);
        if (p == previous->position.end()) continue;
        const double v = (q - p->second) / (r.stamp - previous->stamp);
        if (std::abs(v) > options_.max_velocity) {
          m << "the robot is moving: joint '" << name << "' at " << v << " rad/s (~max_joint_velocity "
            << options_.max_velocity << ")";
          return say(m.str());
        }
      }
    previous = &r;
  }
  return nearest->position;
}

}  // namespace diffdope
