#pragma once
// What the refiner nodelet lets a user change while it runs (cfg/Refiner.cfg, dynamic_reconfigure), as one value
// that is validated in one place (the library's own option checks) and applied by the worker at the next frame.
#include <string>
#include <vector>

#include "diffdope/object_track.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope_ros/RefinerConfig.h"
#include "diffdope_ros/stream_mode.hpp"

namespace diffdope_ros {

struct RuntimeSettings {
  StreamMode mode = StreamMode::kTracking;
  diffdope::RefinerOptions refiner;
  diffdope::TrackOptions track;  // track.tracking follows the mode (off in continuous)
  bool publish_implausible = false;
};

/// The reconfigure values of `settings` (what the node runs with, for the server's initial values).
RefinerConfig to_config(const RuntimeSettings& settings);
/// `base` with the values of `config` (what the config does not hold, e.g. the render options, stays as in
/// `base`). Throws std::invalid_argument naming the first value the library refuses.
RuntimeSettings from_config(const RefinerConfig& config, const RuntimeSettings& base);
/// The same without the options' checks (an unknown mode still throws): for taking some of the values out.
RuntimeSettings with_config(const RefinerConfig& config, const RuntimeSettings& base);

/// One value that differs between two sets of reconfigure values.
struct ConfigChange {
  std::string name, before, after;
  /// `after` is a bound of the parameter's range (cfg/Refiner.cfg). dynamic_reconfigure clamps a request outside
  /// the range to its bound before the node sees it, so such a value may not be the one asked for.
  bool at_bound = false;
  std::string range;  // "0 to 10000" (numbers only)
};
/// The values of `after` that differ from `before`, in the .cfg's order.
std::vector<ConfigChange> config_changes(const RefinerConfig& before, const RefinerConfig& after);
/// "iterations 48 -> 0, lr_high 0.03 -> 0.05"
std::string describe(const std::vector<ConfigChange>& changes);
/// A warning for the changes that sit at a bound of their range (empty when none does).
std::string bound_warning(const std::vector<ConfigChange>& changes);

}  // namespace diffdope_ros
