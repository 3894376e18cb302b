#pragma once
// Which joint positions go with an image, and whether the robot was still when it was taken (calibration samples
// are refused while the joints move: the image and the joint readings would not agree). ROS-free: the
// calibration node feeds it sensor_msgs/JointState messages, which may come from several publishers (an arm and
// its gripper), each naming only its own joints. Times in seconds, positions in radians or metres.
#include <deque>
#include <map>
#include <set>
#include <optional>
#include <string>

namespace diffdope {

struct JointReading {
  double stamp = 0;
  std::map<std::string, double> position;
  std::map<std::string, double> velocity;  // may be empty
};

struct StillnessOptions {
  /// rad/s (m/s for prismatic joints): a joint whose reported velocity, or whose travel over the window divided by
  /// the window, exceeds this is moving. (0, 10]
  double max_velocity = 0.01;
  double window = 0.2;    // seconds before and after the image stamp that must be still; [0, 10]
  double max_gap = 0.1;   // seconds: each joint needs a reading this close to the image stamp; (0, 10]
  double keep = 10.0;     // seconds of readings kept; [1, 3600]
  void validate() const;  // std::invalid_argument naming the value
};

class JointHistory {
 public:
  explicit JointHistory(const StillnessOptions& options = StillnessOptions());
  /// A reading (any order of arrival). Readings older than `keep` before the newest are dropped; a reading
  /// older than that (time went back: a looped bag, a restarted clock) starts the history afresh.
  void add(const JointReading& reading);
  /// Whether readings reach `window` past `stamp` (else still_at() cannot vouch for it yet).
  bool covers(double stamp) const;
  /// The positions at `stamp` (each joint's nearest reading) when every joint was still over [stamp - window,
  /// stamp + window]; otherwise nothing, with the reason in `why` (no reading near the stamp, the window not yet
  /// covered, or which joint moved how fast).
  std::optional<std::map<std::string, double>> still_at(double stamp, std::string* why) const;
  void clear() { joints_.clear(); }
  /// From now on only these joints are kept (the robot's; empty: all): a joint another robot or a tool
  /// publishes is no joint of this one, and neither stops nor stalls a sample.
  void keep_only(const std::set<std::string>& joints);
  /// A message the caller could not use (NaN positions, names and positions of different lengths): when no
  /// reading came after it, still_at()'s refusals name it as the cause.
  void note_rejected(double stamp, const std::string& why);
  /// Readings kept, over all joints.
  size_t size() const;

 private:
  struct Sample {
    double stamp, position, velocity;
    bool has_velocity;
  };
  StillnessOptions options_;
  std::map<std::string, std::deque<Sample>> joints_;  // per joint, by stamp
  double newest_ = -1e300;
  std::set<std::string> kept_;  // empty: every joint
  std::string rejected_;        // the last message rejected after the newest reading; empty: none
};

}  // namespace diffdope
