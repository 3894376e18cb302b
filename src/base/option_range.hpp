#pragma once
// Range checks for options (one message format for the library, the tools and the node): a number that is not
// finite or lies outside its documented range throws std::invalid_argument naming the option, its value and the
// range, e.g. "refiner options: iterations = 1e+09 is outside [0, 10000]".
#include <algorithm>
#include <string>
#include <vector>

#include "diffdope/option_table.hpp"

namespace diffdope {

struct OptionRange {
  std::string what;  // whose options ("refiner options", "~ parameters", ...)
  [[noreturn]] void fail(const std::string& message) const;
  /// lo <= v <= hi
  void operator()(const std::string& name, double v, double lo, double hi, const std::string& unit = "") const;
  /// lo < v <= hi
  void above(const std::string& name, double v, double lo, double hi, const std::string& unit = "") const;
  /// lo <(=) v <(=) hi, each bound open or closed.
  void within(const std::string& name, double v, double lo, bool lo_open, double hi, bool hi_open,
              const std::string& unit = "") const;
};

/// Checks every number of `rows` (those without a section; nested structs check their own) against its range
/// and every string against its choices; names in messages are `prefix` + the row's name.
template <class Options>
void check_option_ranges(const std::vector<OptionSpec<Options>>& rows, const Options& o, const OptionRange& check,
                         const std::string& prefix = "") {
  for (const OptionSpec<Options>& r : rows) {
    if (!r.section().empty()) continue;
    if (r.type == OptionType::kInt || r.type == OptionType::kDouble) {
      check.within(prefix + r.name, r.number(o), r.lo, r.lo_open, r.hi, r.hi_open, r.unit);
    } else if (r.type == OptionType::kString && !r.choices.empty()) {
      const std::string& v = r.template get<std::string>(o);
      if (std::find(r.choices.begin(), r.choices.end(), v) == r.choices.end()) {
        std::string list;
        for (const std::string& c : r.choices) list += (list.empty() ? "" : ", ") + c;
        check.fail(prefix + r.name + " = '" + v + "' is not one of " + list);
      }
    }
  }
}

}  // namespace diffdope
