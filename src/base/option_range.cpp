#include "base/option_range.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace diffdope {

void OptionRange::fail(const std::string& message) const { throw std::invalid_argument(what + ": " + message); }

void OptionRange::within(const std::string& name, double v, double lo, bool lo_open, double hi, bool hi_open,
                         const std::string& unit) const {
  const bool inside = std::isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
  if (inside) return;
  std::ostringstream m;
  m << name << " = " << v << " is " << (std::isfinite(v) ? "outside " : "not finite; allowed: ") << (lo_open ? '(' : '[')
    << lo << ", " << hi << (hi_open ? ')' : ']') << unit;
  fail(m.str());
}

void OptionRange::operator()(const std::string& name, double v, double lo, double hi, const std::string& unit) const {
  within(name, v, lo, false, hi, false, unit);
}

void OptionRange::above(const std::string& name, double v, double lo, double hi, const std::string& unit) const {
  within(name, v, lo, true, hi, false, unit);
}

}  // namespace diffdope
