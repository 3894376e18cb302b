#pragma once
// The options' one table: per option its name (the YAML key and the node's parameter), its field, its range and
// unit, and a one-line doc. The YAML reader, validate(), RefinerOptions::to_yaml() (config/default.yaml is its
// output), the node's dynamic_reconfigure mapping and the checks of cfg/Refiner.cfg are derived from it. The
// defaults are the structs' own initialisers (Options{}), so they are written once too.
#include <charconv>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace diffdope {

enum class OptionType { kBool, kInt, kDouble, kUnsigned, kString };

template <class Options>
struct OptionSpec {
  std::string name;  // "batch_size"; a nested struct's fields carry its section: "loss.weight_rgb"
  OptionType type = OptionType::kDouble;
  double lo = 0, hi = 0;  // numbers (kInt, kDouble): the accepted range; bools and strings have none
  bool lo_open = false, hi_open = false;
  std::string unit;  // appended to the range in messages: " metres", " radians", " (0: off)"
  std::string doc;   // one line
  std::vector<std::string> choices;  // kString: the accepted values (empty: any)
  std::function<void*(Options&)> field;

  template <class T>
  T& get(Options& o) const { return *static_cast<T*>(field(o)); }
  template <class T>
  const T& get(const Options& o) const { return *static_cast<const T*>(field(const_cast<Options&>(o))); }
  /// The value as a number (bools 0 / 1); not for kString.
  double number(const Options& o) const {
    switch (type) {
      case OptionType::kBool: return get<bool>(o) ? 1 : 0;
      case OptionType::kInt: return get<int>(o);
      case OptionType::kUnsigned: return double(get<uint64_t>(o));
      default: return get<double>(o);
    }
  }
  void set_number(Options& o, double v) const {
    switch (type) {
      case OptionType::kBool: get<bool>(o) = v != 0; break;
      case OptionType::kInt: get<int>(o) = static_cast<int>(v); break;
      case OptionType::kUnsigned: get<uint64_t>(o) = static_cast<uint64_t>(v); break;
      case OptionType::kDouble: get<double>(o) = v; break;
      case OptionType::kString: break;
    }
  }
  /// The value as a YAML scalar (numbers round-trip exactly).
  std::string text(const Options& o) const {
    switch (type) {
      case OptionType::kBool: return get<bool>(o) ? "true" : "false";
      case OptionType::kInt: return std::to_string(get<int>(o));
      case OptionType::kUnsigned: return std::to_string(get<uint64_t>(o));
      case OptionType::kString: return get<std::string>(o);
      case OptionType::kDouble: break;
    }
    char buf[400];
    const double v = get<double>(o);
    const bool plain = v == 0 || (std::abs(v) >= 1e-6 && std::abs(v) < 1e9);  // 0.0005 rather than 5e-04
    const auto r = plain ? std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::fixed)
                         : std::to_chars(buf, buf + sizeof(buf), v);
    std::string s(buf, r.ptr);
    if (s.find_first_of(".en") == std::string::npos) s += ".0";  // a float in YAML's eyes
    return s;
  }
  /// The name without its section ("weight_rgb" for "loss.weight_rgb").
  std::string key() const { return name.substr(name.rfind('.') + 1); }
  /// The section ("loss"), empty for a top-level option.
  std::string section() const {
    const size_t dot = name.rfind('.');
    return dot == std::string::npos ? std::string() : name.substr(0, dot);
  }
};

namespace option_table_detail {
template <class T> constexpr OptionType type_of();
template <> constexpr OptionType type_of<bool>() { return OptionType::kBool; }
template <> constexpr OptionType type_of<int>() { return OptionType::kInt; }
template <> constexpr OptionType type_of<double>() { return OptionType::kDouble; }
template <> constexpr OptionType type_of<uint64_t>() { return OptionType::kUnsigned; }
template <> constexpr OptionType type_of<std::string>() { return OptionType::kString; }
}  // namespace option_table_detail

/// One row: `member`'s type gives the option's; [lo, hi] (or open bounds) for numbers.
template <class Options, class T>
OptionSpec<Options> option_row(const char* name, T Options::*member, double lo, double hi, const char* unit,
                               const char* doc, bool lo_open = false, bool hi_open = false) {
  OptionSpec<Options> s;
  s.name = name;
  s.type = option_table_detail::type_of<T>();
  s.lo = lo;
  s.hi = hi;
  s.lo_open = lo_open;
  s.hi_open = hi_open;
  s.unit = unit;
  s.doc = doc;
  s.field = [member](Options& o) -> void* { return &(o.*member); };
  return s;
}

/// The rows of a nested struct as rows of the outer one, named "<section>.<name>".
template <class Outer, class Inner>
void append_section(std::vector<OptionSpec<Outer>>& out, const std::vector<OptionSpec<Inner>>& rows,
                    const std::string& section, Inner Outer::*member) {
  for (const OptionSpec<Inner>& r : rows) {
    OptionSpec<Outer> s;
    s.name = section + "." + r.name;
    s.type = r.type;
    s.lo = r.lo;
    s.hi = r.hi;
    s.lo_open = r.lo_open;
    s.hi_open = r.hi_open;
    s.unit = r.unit;
    s.doc = r.doc;
    s.choices = r.choices;
    s.field = [member, f = r.field](Outer& o) -> void* { return f(o.*member); };
    out.push_back(std::move(s));
  }
}

struct LossOptions;
struct RenderOptions;
struct RefinerOptions;
struct TrackOptions;
const std::vector<OptionSpec<LossOptions>>& loss_option_table();
const std::vector<OptionSpec<RenderOptions>>& render_option_table();
/// RefinerOptions' own rows, then "loss.*" and "render.*" (config/default.yaml's order).
const std::vector<OptionSpec<RefinerOptions>>& refiner_option_table();
/// Deprecated names of refiner_option_table() keys, as (deprecated, current): still read as the current key
/// (a config that gives both is refused), with a note naming the current one.
struct RenamedOption {
  const char* deprecated;
  const char* current;
};
const std::vector<RenamedOption>& renamed_refiner_options();
/// TrackOptions' rows, named as the node's parameters.
const std::vector<OptionSpec<TrackOptions>>& track_option_table();

}  // namespace diffdope
