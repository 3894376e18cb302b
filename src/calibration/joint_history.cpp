// Joint readings and stillness around an image stamp (joint_history.hpp).
#include "diffdope/joint_history.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "base/option_range.hpp"

namespace diffdope {

void StillnessOptions::validate() const {
  const OptionRange check{"stillness options"};
  check.above("max_joint_velocity", max_velocity, 0, 10, " rad/s");
  check("still_window", window, 0, 10, " s");
  check.above("max_joint_gap", max_gap, 0, 10, " s");
  check("joint_history", keep, 1, 3600, " s");
}

JointHistory::JointHistory(const StillnessOptions& options) : options_((options.validate(), options)) {}

size_t JointHistory::size() const {
  size_t n = 0;
  for (const auto& [name, q] : joints_) n += q.size();
  return n;
}

void JointHistory::keep_only(const std::set<std::string>& joints) {
  kept_ = joints;
  if (kept_.empty()) return;
  for (auto it = joints_.begin(); it != joints_.end();) it = kept_.count(it->first) ? std::next(it) : joints_.erase(it);
}

void JointHistory::note_rejected(double stamp, const std::string& why) {
  if (stamp >= newest_ || !std::isfinite(stamp)) rejected_ = why;
}

void JointHistory::add(const JointReading& r) {
  if (r.stamp < newest_ - options_.keep) joints_.clear(), newest_ = -1e300;  // time went back
  if (r.stamp >= newest_) rejected_.clear();
  newest_ = std::max(newest_, r.stamp);
  for (const auto& [name, position] : r.position) {
    if (!kept_.empty() && !kept_.count(name)) continue;
    const auto v = r.velocity.find(name);
    const Sample s{r.stamp, position, v == r.velocity.end() ? 0.0 : v->second, v != r.velocity.end()};
    std::deque<Sample>& q = joints_[name];
    q.insert(std::upper_bound(q.begin(), q.end(), s.stamp, [](double t, const Sample& x) { return t < x.stamp; }), s);
  }
  for (auto& [name, q] : joints_)
    while (!q.empty() && q.front().stamp < newest_ - options_.keep) q.pop_front();
}

bool JointHistory::covers(double stamp) const { return newest_ >= stamp + options_.window; }

std::optional<std::map<std::string, double>> JointHistory::still_at(double stamp, std::string* why) const {
  const auto say = [&](const std::string& s) {
    if (why) *why = rejected_.empty() ? s : s + " (the latest joint_states message was ignored: " + rejected_ + ")";
    return std::nullopt;
  };
  if (joints_.empty()) return say("no joint states received");
  std::ostringstream m;
  m.precision(3);
  if (stamp - newest_ > options_.max_gap) {  // the image is newer than every reading: not "wait", another clock?
    m << std::fixed << "no joint state within " << options_.max_gap << " s of the image (the newest is "
      << stamp - newest_ << " s older): are the clocks the same?";
    return say(m.str());
  }
  if (!covers(stamp)) {
    m << "the joint states do not yet cover " << options_.window << " s after the image: try again";
    return say(m.str());
  }
  std::map<std::string, double> out;
  for (const auto& [name, q] : joints_) {
    if (q.empty()) continue;
    const Sample* nearest = nullptr;
    double lo = 0, hi = 0;
    bool any = false;
    for (const Sample& s : q) {
      if (!nearest || std::abs(s.stamp - stamp) < std::abs(nearest->stamp - stamp)) nearest = &s;
      if (s.stamp < stamp - options_.window || s.stamp > stamp + options_.window) continue;
      if (s.has_velocity && std::abs(s.velocity) > options_.max_velocity) {
        m << "the robot is moving: joint '" << name << "' at " << s.velocity << " rad/s (~max_joint_velocity "
          << options_.max_velocity << ")";
        return say(m.str());
      }
      lo = any ? std::min(lo, s.position) : s.position;
      hi = any ? std::max(hi, s.position) : s.position;
      any = true;
    }
    // Travel over the window rather than differences of successive readings: encoder noise at a high rate
    // would look like speed.
    const double span = std::max(2 * options_.window, 1e-3);
    if (any && (hi - lo) / span > options_.max_velocity) {
      m << "the robot is moving: joint '" << name << "' travelled " << hi - lo << " within " << options_.window
        << " s of the image (~max_joint_velocity " << options_.max_velocity << " rad/s)";
      return say(m.str());
    }
    if (std::abs(nearest->stamp - stamp) > options_.max_gap) {
      m << std::fixed << "no state of joint '" << name << "' within " << options_.max_gap << " s of the image "
        << "(nearest " << nearest->stamp - stamp << " s away): are the clocks the same?";
      return say(m.str());
    }
    out[name] = nearest->position;
  }
  return out;
}

}  // namespace diffdope
