#include "diffdope_ros/error_reporter.hpp"

#include <ros/console.h>
#include <ros/time.h>

namespace diffdope_ros {

bool ErrorReporter::should_log(const std::string& key, double now) {
  auto it = last_logged_.find(key);
  if (it != last_logged_.end() && now - it->second < period_) return false;
  last_logged_[key] = now;
  return true;
}

namespace {

const std::string& bounded(const std::map<std::string, long>& counts, const std::string& category) {
  static const std::string other = "other";
  return counts.count(category) || counts.size() < ErrorReporter::kMaxCategories - 1 ? category : other;
}

}  // namespace

void ErrorReporter::error(const std::string& given_category, const std::string& message, Logging logging) {
  const double now = ros::WallTime::now().toSec();
  bool log;
  long count;
  std::string category;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    category = bounded(summary_.error_counts, given_category);
    count = ++summary_.error_counts[category];
    summary_.last_error = message;
    summary_.last_error_time = now;
    log = should_log("E" + category, now) || logging == Logging::kEveryTime;
  }
  if (log) {
    if (count > 1) ROS_ERROR_STREAM_NAMED("diffdope", message << " [" << category << " error #" << count << "]");
    else ROS_ERROR_STREAM_NAMED("diffdope", message);
  }
}

void ErrorReporter::warn(const std::string& given_category, const std::string& message, Logging logging) {
  const double now = ros::WallTime::now().toSec();
  bool log;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string& category = bounded(summary_.warn_counts, given_category);
    ++summary_.warn_counts[category];
    log = should_log("W" + category, now) || logging == Logging::kEveryTime;
  }
  if (log) ROS_WARN_STREAM_NAMED("diffdope", message);
}

ErrorReporter::Summary ErrorReporter::summary() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return summary_;
}

}  // namespace diffdope_ros
