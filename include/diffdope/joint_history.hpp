#pragma once
// Which joint positions go with an image, and whether the robot was still when it was taken (calibration samples
// are refused while the joints move: the image and the joint readings would not agree). ROS-free: the
// calibration node feeds it sensor_msgs/JointState messages. Times in seconds, positions in radians or metres.
#include <deque>
#include <map>
#include <optional>
#include <string>

namespace diffdope {

struct JointReading {
  double stamp = 0;
  std::map<std::string, double> position;
  std::map<std::string, double> velocity;  // may be empty (then the positions' differences are used)
};

struct StillnessOptions {
  double max_velocity = 0.01;  // rad/s (m/s for prismatic joints): faster is "moving"; (0, 10]
  double window = 0.2;         // seconds before and after the image stamp that must be still; [0, 10]
  double max_gap = 0.1;        // seconds: a reading must exist this close to the image stamp; (0, 10]
  double keep = 10.0;          // seconds of readings kept; [1, 3600]
  void validate() const;       // std::invalid_argument naming the value
};

class JointHistory {
 public:
  explicit JointHistory(const StillnessOptions& options = StillnessOptions());
  /// A reading (any order of arrival; older than `keep` before the newest are dropped). Readings with a
  /// non-finite value or mismatched name / position counts are the caller's to refuse before.
  void add(const JointReading& reading);
  /// The positions at `stamp` (the nearest reading) when every joint was still over [stamp - window,
  /// stamp + window]; otherwise nothing, with the reason in `why` (no reading near the stamp, the window not yet
  /// covered, or which joint moved how fast).
  std::optional<std::map<std::string, double>> still_at(double stamp, std::string* why) const;
  void clear() { readings_.clear(); }
  size_t size() const { return readings_.size(); }

 private:
  StillnessOptions options_;
  std::deque<JointReading> readings_;  // by stamp
};

}  // namespace diffdope
