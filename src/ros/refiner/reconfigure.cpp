// RefinerNodelet's runtime tuning (cfg/Refiner.cfg): the server starts from the node's own values, checks what
// it is sent (runtime_settings.hpp) and hands accepted values to the worker.
#include <boost/bind/bind.hpp>

#include "ros/refiner/refiner_nodelet.hpp"

namespace diffdope_ros {

void RefinerNodelet::setupReconfigure() {
  runtime_settings_ = {mode_, refiner_options_, track_options_, publish_implausible_};
  applied_config_ = to_config(runtime_settings_);
  // The server starts from the node's own values (YAML, then ~parameters), not from the .cfg defaults. Its
  // constructor advertises set_parameters before updateConfig below: holding the server's mutex makes a call that
  // arrives in between wait, instead of seeing (and applying) the .cfg defaults.
  boost::recursive_mutex::scoped_lock lock(reconfigure_mutex_);
  reconfigure_server_ =
      std::make_unique<dynamic_reconfigure::Server<RefinerConfig>>(reconfigure_mutex_, getPrivateNodeHandle());
  reconfigure_server_->updateConfig(applied_config_);
  reconfigure_server_->setCallback(
      boost::bind(&RefinerNodelet::onReconfigure, this, boost::placeholders::_1, boost::placeholders::_2));
}

void RefinerNodelet::onReconfigure(RefinerConfig& config, uint32_t level) {
  RuntimeSettings settings;
  try {
    settings = from_config(config, runtime_settings_);
  } catch (const std::invalid_argument& e) {
    // Each refusal answers a request someone just made: logged every time, not throttled.
    errors_.error("reconfigure", std::string("reconfigure refused, the previous values stay: ") + e.what(),
                  ErrorReporter::Logging::kEveryTime);
    config = applied_config_;  // the server publishes what is in force
    return;
  }
  const std::vector<ConfigChange> changes = config_changes(applied_config_, config);
  runtime_settings_ = settings;
  applied_config_ = config;
  if (level == ~0u) return;  // setCallback's first call: the values the node started with
  {
    std::lock_guard<std::mutex> lock(work_mutex_);
    pending_settings_ = settings;
    if (settings.mode == StreamMode::kOnRequest) frame_pending_ = false;  // nothing more is streamed, not even that one
  }
  mode_ = settings.mode;  // the input callbacks read it; the rest the worker takes at its next job
  NODELET_INFO_STREAM("reconfigured (from the next frame): " << (changes.empty() ? "no value changed"
                                                                                 : describe(changes)));
  const std::string bound = bound_warning(changes);
  if (!bound.empty()) errors_.warn("reconfigure", "reconfigured value " + bound, ErrorReporter::Logging::kEveryTime);
}

}  // namespace diffdope_ros
