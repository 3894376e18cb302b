// Runtime settings <-> dynamic_reconfigure values (runtime_settings.hpp): a parameter of cfg/Refiner.cfg that names
// a library option (its key in the option table) maps to it; mode and publish_implausible are the node's own.
#include "diffdope_ros/runtime_settings.hpp"

#include <stdexcept>
#include <type_traits>
#include <vector>

#include "diffdope/option_table.hpp"

namespace diffdope_ros {

const char* to_string(StreamMode mode) {
  switch (mode) {
    case StreamMode::kContinuous: return "continuous";
    case StreamMode::kTracking: return "tracking";
    case StreamMode::kOnRequest: return "on_request";
  }
  return "?";
}

StreamMode parse_stream_mode(const std::string& name) {
  for (StreamMode m : {StreamMode::kContinuous, StreamMode::kTracking, StreamMode::kOnRequest})
    if (name == to_string(m)) return m;
  throw std::invalid_argument("mode: unknown value '" + name + "' (continuous, tracking, on_request)");
}

namespace {

template <class Options>
const diffdope::OptionSpec<Options>* find_row(const std::vector<diffdope::OptionSpec<Options>>& rows,
                                              const std::string& key) {
  for (const auto& r : rows)
    if (r.key() == key) return &r;
  return nullptr;
}

/// Calls `visit(value)` with a reference to each number the reconfigure message holds, for the parameters that
/// are library options (found by name in the option tables: "weight_rgb" is loss.weight_rgb).
template <class Visit>
void for_each_option(dynamic_reconfigure::Config& msg, RuntimeSettings& s, Visit visit) {
  auto apply = [&](const std::string& name, auto& value) {
    if (const auto* r = find_row(diffdope::refiner_option_table(), name)) visit(*r, s.refiner, value);
    else if (const auto* t = find_row(diffdope::track_option_table(), name)) visit(*t, s.track, value);
  };
  for (auto& p : msg.ints) apply(p.name, p.value);
  for (auto& p : msg.doubles) apply(p.name, p.value);
  for (auto& p : msg.bools) apply(p.name, p.value);
}

}  // namespace

RefinerConfig to_config(const RuntimeSettings& settings) {
  RefinerConfig c = RefinerConfig::__getDefault__();
  dynamic_reconfigure::Config msg;
  c.__toMessage__(msg);
  RuntimeSettings s = settings;
  for_each_option(msg, s, [](const auto& row, const auto& options, auto& value) {
    value = static_cast<std::remove_reference_t<decltype(value)>>(row.number(options));
  });
  c.__fromMessage__(msg);
  c.mode = to_string(s.mode);
  c.publish_implausible = s.publish_implausible;
  return c;
}

RuntimeSettings from_config(const RefinerConfig& config, const RuntimeSettings& base) {
  RuntimeSettings s = base;
  s.mode = parse_stream_mode(config.mode);
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  for_each_option(msg, s, [](const auto& row, auto& options, const auto& value) { row.set_number(options, value); });
  s.publish_implausible = config.publish_implausible;
  s.track.tracking = s.mode != StreamMode::kContinuous;  // on_request seeds from its own previous results too
  s.refiner.validate();  // the same checks as the YAML's
  s.track.validate();
  return s;
}

}  // namespace diffdope_ros
