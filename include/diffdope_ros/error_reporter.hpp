#pragma once
// Bad input is reported, never dropped silently: every error is logged (throttled per category, so one bad
// topic cannot hide another) and counted, and the latest one is kept for diagnostics.
#include <map>
#include <mutex>
#include <string>

namespace diffdope_ros {

class ErrorReporter {
 public:
  /// At most this many categories are kept apart (per level); later ones are counted and throttled together
  /// as "other", so a caller that puts values in a category cannot grow the diagnostics or bypass the throttle.
  static constexpr size_t kMaxCategories = 32;

  /// kEveryTime: the answer to one deliberate request (a refused reconfigure), logged whatever the throttle.
  enum class Logging { kThrottled, kEveryTime };

  explicit ErrorReporter(double throttle_period_s = 5.0) : period_(throttle_period_s) {}
  void set_throttle_period(double seconds) { period_ = seconds; }

  /// Logs `message` with ROS_ERROR unless this category was logged less than the throttle period ago (always
  /// with Logging::kEveryTime).
  void error(const std::string& category, const std::string& message, Logging logging = Logging::kThrottled);
  /// The same at WARN level; warnings are counted but do not become last_error.
  void warn(const std::string& category, const std::string& message, Logging logging = Logging::kThrottled);

  struct Summary {
    std::string last_error;
    double last_error_time = 0;  // wall seconds, 0 = never
    std::map<std::string, long> error_counts;
    std::map<std::string, long> warn_counts;
  };
  Summary summary() const;

 private:
  bool should_log(const std::string& key, double now);
  double period_;
  mutable std::mutex mutex_;
  std::map<std::string, double> last_logged_;
  Summary summary_;
};

}  // namespace diffdope_ros
