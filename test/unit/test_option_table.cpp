// The option table is the one source of the options: config/default.yaml is its output, the YAML reader reads
// every row, validate() checks every row's range, and cfg/Refiner.cfg (dynamic_reconfigure) agrees with it.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "diffdope/object_track.hpp"
#include "diffdope/option_table.hpp"
#include "diffdope/refiner.hpp"

using namespace diffdope;

namespace {

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// A valid value of `row` that differs from its default.
template <class Options>
void set_other_value(const OptionSpec<Options>& row, Options& o) {
  switch (row.type) {
    case OptionType::kBool: row.template get<bool>(o) = !row.template get<bool>(o); break;
    case OptionType::kUnsigned: row.template get<uint64_t>(o) += 12345; break;
    case OptionType::kString: row.template get<std::string>(o) = row.choices.empty() ? "x" : row.choices.back(); break;
    case OptionType::kInt:
    case OptionType::kDouble: {
      double v = row.lo + 0.37 * (row.hi - row.lo);
      if (row.type == OptionType::kInt) v = std::round(v);
      if (v == row.number(o)) v = row.type == OptionType::kInt ? v + 1 : v * 1.01;
      row.set_number(o, v);
      break;
    }
  }
}

}  // namespace

TEST(OptionTable, DefaultYamlIsTheTablesOutput) {
  const std::string file = read_text(std::string(DIFFDOPE_SOURCE_DIR) + "/config/default.yaml");
  EXPECT_EQ(file, RefinerOptions().to_yaml())
      << "config/default.yaml differs from the option table: regenerate it with "
         "`diffdope_refine --print-config > config/default.yaml`";
}

TEST(OptionTable, DefaultsLieInTheirRangesAndNamesAreUnique) {
  const RefinerOptions defaults;
  std::set<std::string> keys;
  for (const auto& row : refiner_option_table()) {
    EXPECT_TRUE(keys.insert(row.key()).second) << row.name << ": a second row with this key";
    EXPECT_FALSE(row.doc.empty()) << row.name;
    if (row.type == OptionType::kInt || row.type == OptionType::kDouble) {
      EXPECT_LT(row.lo, row.hi) << row.name;
      const double v = row.number(defaults);
      EXPECT_TRUE(row.lo_open ? v > row.lo : v >= row.lo) << row.name;
      EXPECT_TRUE(row.hi_open ? v < row.hi : v <= row.hi) << row.name;
    }
  }
  for (const auto& row : track_option_table()) EXPECT_TRUE(keys.insert(row.key()).second) << row.name;
  EXPECT_NO_THROW(defaults.validate());
  EXPECT_NO_THROW(TrackOptions().validate());
}

TEST(OptionTable, YamlReadsBackEveryRow) {
  RefinerOptions o;
  for (const auto& row : refiner_option_table()) set_other_value(row, o);
  ASSERT_NO_THROW(o.validate());
  const RefinerOptions back = RefinerOptions::from_yaml_string(o.to_yaml(), "to_yaml");
  const RefinerOptions defaults;
  for (const auto& row : refiner_option_table()) {
    EXPECT_EQ(row.text(back), row.text(o)) << row.name;
    EXPECT_NE(row.text(back), row.text(defaults)) << row.name << " was not read";
  }
}

TEST(OptionTable, EveryNumberIsCheckedAgainstItsRange) {
  for (const auto& row : refiner_option_table()) {
    if (row.type != OptionType::kInt && row.type != OptionType::kDouble) continue;
    const std::string key = row.key();
    for (double bad : {row.hi + 1 + std::abs(row.hi), row.lo - 1 - std::abs(row.lo),
                       std::numeric_limits<double>::quiet_NaN()}) {
      if (row.type == OptionType::kInt && !std::isfinite(bad)) continue;
      RefinerOptions o;
      row.set_number(o, bad);
      try {
        o.validate();
        ADD_FAILURE() << row.name << " = " << bad << " passed validate()";
      } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find(row.name), std::string::npos) << e.what();
      }
    }
    if (row.lo_open || row.hi_open) {
      RefinerOptions o;
      row.set_number(o, row.lo_open ? row.lo : row.hi);
      EXPECT_THROW(o.validate(), std::invalid_argument) << row.name << " at its open bound";
    }
  }
  for (const auto& row : track_option_table()) {
    if (row.type != OptionType::kInt && row.type != OptionType::kDouble) continue;
    TrackOptions t;
    row.set_number(t, row.hi + 1 + std::abs(row.hi));
    EXPECT_THROW(t.validate(), std::invalid_argument) << row.name;
  }
}

TEST(OptionTable, StringChoicesAreChecked) {
  RefinerOptions o;
  o.device = "gpu";
  EXPECT_THROW(o.validate(), std::invalid_argument);
}

// Every parameter of cfg/Refiner.cfg is a library option (same type, same default, a range inside the library's)
// or one of the node's own settings; the node maps the options by these names.
TEST(OptionTable, ReconfigureAgreesWithTheTable) {
  const std::string cfg = read_text(std::string(DIFFDOPE_SOURCE_DIR) + "/cfg/Refiner.cfg");
  const std::regex add(R"re(\w+\.add\("(\w+)",\s*(\w+)_t,\s*0,\s*"[^"]*",\s*([^,\)]+)(?:,\s*([^,\)]+),\s*([^,\)]+))?)re");
  const std::set<std::string> node_settings = {"mode", "publish_implausible"};
  const RefinerOptions refiner_defaults;
  const TrackOptions track_defaults;
  int options = 0;
  for (std::sregex_iterator it(cfg.begin(), cfg.end(), add), end; it != end; ++it) {
    const std::smatch& m = *it;
    const std::string name = m[1], type = m[2], def = m[3];
    if (node_settings.count(name)) continue;
    const OptionSpec<RefinerOptions>* row = nullptr;
    for (const auto& r : refiner_option_table())
      if (r.key() == name) row = &r;
    const OptionSpec<TrackOptions>* track_row = nullptr;
    for (const auto& r : track_option_table())
      if (r.key() == name) track_row = &r;
    ASSERT_TRUE(row || track_row) << "cfg/Refiner.cfg: '" << name << "' is neither an option nor a node setting";
    ++options;
    const OptionType t = row ? row->type : track_row->type;
    const double lo = row ? row->lo : track_row->lo, hi = row ? row->hi : track_row->hi;
    const bool lo_open = row ? row->lo_open : track_row->lo_open, hi_open = row ? row->hi_open : track_row->hi_open;
    const double expected = row ? row->number(refiner_defaults) : track_row->number(track_defaults);
    const std::map<std::string, OptionType> types = {
        {"int", OptionType::kInt}, {"double", OptionType::kDouble}, {"bool", OptionType::kBool}};
    ASSERT_TRUE(types.count(type)) << name;
    EXPECT_EQ(types.at(type), t) << name << ": type";
    const double d = t == OptionType::kBool ? (def == "True" ? 1 : 0) : std::stod(def);
    EXPECT_NEAR(d, expected, 1e-12 * std::max(1.0, std::abs(expected))) << name << ": default";
    if (m[4].matched) {
      const double clo = std::stod(m[4]), chi = std::stod(m[5]);
      EXPECT_TRUE(lo_open ? clo > lo : clo >= lo) << name << ": minimum " << clo << " below the library's " << lo;
      EXPECT_TRUE(hi_open ? chi < hi : chi <= hi) << name << ": maximum " << chi << " above the library's " << hi;
    }
  }
  EXPECT_GT(options, 20);
}
