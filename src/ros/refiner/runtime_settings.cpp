// Runtime settings <-> dynamic_reconfigure values (runtime_settings.hpp): a parameter of cfg/Refiner.cfg that names
// a library option (its key in the option table) maps to it; mode and publish_implausible are the node's own.
#include "diffdope_ros/runtime_settings.hpp"

#include <sstream>
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

RuntimeSettings with_config(const RefinerConfig& config, const RuntimeSettings& base) {
  RuntimeSettings s = base;
  s.mode = parse_stream_mode(config.mode);
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  for_each_option(msg, s, [](const auto& row, auto& options, const auto& value) { row.set_number(options, value); });
  s.publish_implausible = config.publish_implausible;
  s.track.tracking = s.mode != StreamMode::kContinuous;  // on_request seeds from its own previous results too
  return s;
}

RuntimeSettings from_config(const RefinerConfig& config, const RuntimeSettings& base) {
  RuntimeSettings s = with_config(config, base);
  s.refiner.validate();  // the same checks as the YAML's
  s.track.validate();
  return s;
}

namespace {

template <class T>
std::string text(const T& value) {
  std::ostringstream out;
  out.precision(10);
  out << std::boolalpha << value;
  return out.str();
}
std::string text(unsigned char flag) { return flag ? "true" : "false"; }  // (a BoolParameter's value)

template <class Param>
const Param* find_param(const std::vector<Param>& params, const std::string& name) {
  for (const auto& p : params)
    if (p.name == name) return &p;
  return nullptr;
}

/// Appends a change for each parameter of `after` whose value differs in `before`; numbers are checked
/// against their range [lo, hi].
template <class Param>
void add_changes(const std::vector<Param>& before, const std::vector<Param>& after, const std::vector<Param>* lo,
                 const std::vector<Param>* hi, std::vector<ConfigChange>& out) {
  for (const Param& a : after) {
    const Param* b = find_param(before, a.name);
    if (!b || b->value == a.value) continue;
    ConfigChange c;
    c.name = a.name, c.before = text(b->value), c.after = text(a.value);
    const Param* min = lo ? find_param(*lo, a.name) : nullptr;
    const Param* max = hi ? find_param(*hi, a.name) : nullptr;
    if (min && max) {
      c.at_bound = a.value == min->value || a.value == max->value;
      c.range = text(min->value) + " to " + text(max->value);
    }
    out.push_back(c);
  }
}

}  // namespace

std::vector<ConfigChange> config_changes(const RefinerConfig& before, const RefinerConfig& after) {
  dynamic_reconfigure::Config b, a, lo, hi;
  before.__toMessage__(b);
  after.__toMessage__(a);
  RefinerConfig::__getMin__().__toMessage__(lo);
  RefinerConfig::__getMax__().__toMessage__(hi);
  std::vector<ConfigChange> out;
  add_changes(b.strs, a.strs, decltype(&lo.strs){}, decltype(&hi.strs){}, out);
  add_changes(b.ints, a.ints, &lo.ints, &hi.ints, out);
  add_changes(b.doubles, a.doubles, &lo.doubles, &hi.doubles, out);
  add_changes(b.bools, a.bools, decltype(&lo.bools){}, decltype(&hi.bools){}, out);
  return out;
}

std::string describe(const std::vector<ConfigChange>& changes) {
  std::string out;
  for (const ConfigChange& c : changes) out += (out.empty() ? "" : ", ") + c.name + " " + c.before + " -> " + c.after;
  return out;
}

std::string bound_warning(const std::vector<ConfigChange>& changes) {
  std::string at;
  for (const ConfigChange& c : changes)
    if (c.at_bound) at += (at.empty() ? "" : ", ") + c.name + " " + c.after + " (range " + c.range + ")";
  if (at.empty()) return "";
  return "at the bound of its range: " + at +
         ". dynamic_reconfigure clamps a value outside the range to its bound without a word: if another value "
         "was asked for, it was not applied";
}

}  // namespace diffdope_ros
