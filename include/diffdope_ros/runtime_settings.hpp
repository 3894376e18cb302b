#pragma once
// What the refiner nodelet lets a user change while it runs (cfg/Refiner.cfg, dynamic_reconfigure), as one value
// that is validated in one place (the library's own option checks) and applied by the worker at the next frame.
#include <string>

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

}  // namespace diffdope_ros
