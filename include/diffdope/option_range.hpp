#pragma once
// Range checks for options (one message format for the library, the tools and the node): a number that is not
// finite or lies outside its documented range throws std::invalid_argument naming the option, its value and the
// range, e.g. "refiner options: iterations = 1e+09 is outside [0, 10000]".
#include <string>

namespace diffdope {

struct OptionRange {
  std::string what;  // whose options ("refiner options", "~ parameters", ...)
  [[noreturn]] void fail(const std::string& message) const;
  /// lo <= v <= hi
  void operator()(const std::string& name, double v, double lo, double hi, const std::string& unit = "") const;
  /// lo < v <= hi
  void above(const std::string& name, double v, double lo, double hi, const std::string& unit = "") const;
};

}  // namespace diffdope
