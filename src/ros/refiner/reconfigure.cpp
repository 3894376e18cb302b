// RefinerNodelet's runtime tuning (cfg/Refiner.cfg): the server starts from the node's own values, checks what
// it is sent (runtime_settings.hpp) and hands accepted values to the worker.
#include <boost/bind/bind.hpp>

#include "ros/refiner/refiner_nodelet.hpp"

namespace diffdope_ros {

void RefinerNodelet::setupReconfigure(const WorkerOptions& launch) {
  reconfigure_.settings = {mode_, launch.refiner, launch.track, launch.publish_implausible};
  reconfigure_.applied_config = to_config(reconfigure_.settings);
  // The server starts from the node's own values (YAML, then ~parameters), not from the .cfg defaults. Its
  // constructor advertises set_parameters before updateConfig below: holding the server's mutex makes a call that
  // arrives in between wait, instead of seeing (and applying) the .cfg defaults.
  boost::recursive_mutex::scoped_lock lock(reconfigure_.mutex);
  reconfigure_.server =
      std::make_unique<dynamic_reconfigure::Server<RefinerConfig>>(reconfigure_.mutex, getPrivateNodeHandle());
  reconfigure_.server->updateConfig(reconfigure_.applied_config);
  reconfigure_.server->setCallback(
      boost::bind(&RefinerNodelet::onReconfigure, this, boost::placeholders::_1, boost::placeholders::_2));
}

void RefinerNodelet::onReconfigure(RefinerConfig& config, uint32_t level) {
  RuntimeSettings settings;
  try {
    settings = from_config(config, reconfigure_.settings);
  } catch (const std::invalid_argument& e) {
    // Each refusal answers a request someone just made: logged every time, not throttled.
    errors_.error("reconfigure", std::string("reconfigure refused, the previous values stay: ") + e.what(),
                  ErrorReporter::Logging::kEveryTime);
    config = reconfigure_.applied_config;  // the server publishes what is in force
    return;
  }
  const std::vector<ConfigChange> changes = config_changes(reconfigure_.applied_config, config);
  reconfigure_.settings = settings;
  reconfigure_.applied_config = config;
  if (level == ~0u) return;  // setCallback's first call: the values the node started with
  {
    std::lock_guard<std::mutex> lock(handover_.mutex);
    handover_.pending_settings = settings;
    if (settings.mode == StreamMode::kOnRequest) handover_.frame_pending = false;  // nothing more is streamed, not even that one
  }
  mode_ = settings.mode;  // the input callbacks read it; the rest the worker takes at its next job
  NODELET_INFO_STREAM("reconfigured (from the next frame): " << (changes.empty() ? "no value changed"
                                                                                 : describe(changes)));
  const std::string bound = bound_warning(changes);
  if (!bound.empty()) errors_.warn("reconfigure", "reconfigured value " + bound, ErrorReporter::Logging::kEveryTime);
}

}  // namespace diffdope_ros
