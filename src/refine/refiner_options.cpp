// RefinerOptions' rows of the option table, and what is derived from them: the YAML reader, the checks and
// to_yaml() (config/default.yaml).
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <type_traits>
#include <stdexcept>

#include "base/option_range.hpp"
#include "diffdope/option_table.hpp"
#include "diffdope/refiner.hpp"

#include "diffdope/input_files.hpp"

namespace diffdope {
namespace {

template <typename T>
const char* type_name() {
  if (std::is_same<T, bool>::value) return "true or false";
  if (std::is_integral<T>::value) return "an integer";
  if (std::is_floating_point<T>::value) return "a number";
  return "a string";
}

template <typename T>
void read(const YAML::Node& node, const char* key, T& value, std::set<std::string>& used) {
  used.insert(key);
  const YAML::Node v = node[key];
  if (!v) return;
  try {
    value = v.as<T>();
  } catch (const YAML::Exception&) {
    throw std::invalid_argument(std::string(key) + ": expected " + type_name<T>() + ", got '" +
                                (v.IsScalar() ? v.Scalar() : std::string("a list or mapping")) + "'");
  }
}

void reject_unknown(const YAML::Node& node, const std::set<std::string>& used, const std::string& where) {
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (!used.count(key)) throw std::runtime_error(where + ": unknown key '" + key + "'");
  }
}

/// Reads the value of `row` from `node[row.key()]` when present.
void read_row(const YAML::Node& node, const OptionSpec<RefinerOptions>& row, RefinerOptions& o,
              std::set<std::string>& used) {
  const std::string key = row.key();
  switch (row.type) {
    case OptionType::kBool: return read(node, key.c_str(), row.get<bool>(o), used);
    case OptionType::kInt: return read(node, key.c_str(), row.get<int>(o), used);
    case OptionType::kDouble: return read(node, key.c_str(), row.get<double>(o), used);
    case OptionType::kUnsigned: return read(node, key.c_str(), row.get<uint64_t>(o), used);
    case OptionType::kString: return read(node, key.c_str(), row.get<std::string>(o), used);
  }
}

/// `given` with each deprecated key (renamed_refiner_options()) read as its current one, with a note on stderr.
YAML::Node with_current_names(const YAML::Node& given, const std::string& origin) {
  YAML::Node root = YAML::Clone(given);
  for (const RenamedOption& r : renamed_refiner_options()) {
    if (!root[r.deprecated]) continue;
    if (root[r.current])
      throw std::runtime_error(origin + ": " + r.deprecated + " is the deprecated name of " + r.current +
                               "; give only " + r.current);
    std::cerr << origin << ": " << r.deprecated << " is deprecated, read as " << r.current << "\n";
    root[r.current] = root[r.deprecated];
    root.remove(r.deprecated);
  }
  return root;
}

RefinerOptions parse(const YAML::Node& given, RefinerOptions o, const std::string& origin) {
  if (!given || given.IsNull()) return o;
  if (!given.IsMap()) throw std::runtime_error(origin + ": expected a mapping of option names to values");
  const YAML::Node root = with_current_names(given, origin);
  std::set<std::string> used;
  std::map<std::string, std::set<std::string>> section_used;
  try {
    for (const OptionSpec<RefinerOptions>& row : refiner_option_table()) {
      const std::string section = row.section();
      if (section.empty()) {
        read_row(root, row, o, used);
        continue;
      }
      used.insert(section);
      if (const YAML::Node node = root[section]) read_row(node, row, o, section_used[section]);
    }
    for (const auto& [section, keys] : section_used) reject_unknown(root[section], keys, origin + " (" + section + ")");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(origin + ": " + e.what());
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(origin + ": " + e.what());
  }
  reject_unknown(root, used, origin);
  try {
    o.validate();
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(origin + ": " + e.what());
  }
  return o;
}

}  // namespace

RefinerOptions RefinerOptions::from_yaml_file(const std::string& path, const RefinerOptions& base) {
  return from_yaml_string(read_text_file(path, "the options file"), base, path);
}

RefinerOptions RefinerOptions::from_yaml_string(const std::string& yaml, const RefinerOptions& base,
                                                const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(origin + ": " + e.what());
  }
  try {
    check_yaml_expansion(root, origin);
  } catch (const InputFileError& e) {
    throw std::runtime_error(origin + ": " + e.what());
  }
  return parse(root, base, origin);
}

RefinerOptions RefinerOptions::from_yaml_file(const std::string& path) {
  return from_yaml_file(path, RefinerOptions());
}

RefinerOptions RefinerOptions::from_yaml_string(const std::string& yaml, const std::string& origin) {
  return from_yaml_string(yaml, RefinerOptions(), origin);
}

namespace {

/// refiner_option_table()'s rows after the accuracy stages': the schedule's seed and stops, the object's pixels,
/// the verdict, the device.
void append_rows(std::vector<OptionSpec<RefinerOptions>>& r) {
  using O = RefinerOptions;
  const std::vector<OptionSpec<O>> rows = {
    option_row("seed", &O::seed, 0, 0, "", "learning-rate draws: same seed, same inputs, same result"),
    option_row("successive_halving", &O::successive_halving, 0, 0, "",
               "keep the better half of the runs at 25, 50 and 75 % of the iterations (false: the paper's algorithm)"),
    option_row("early_stop_patience", &O::early_stop_patience, 0, O::kMaxIterations, " iterations (0: off)",
               "stop when no run improved by early_stop_tolerance for this many iterations"),
    option_row("early_stop_tolerance", &O::early_stop_tolerance, 0, 1, "", "relative loss improvement that counts"),
    option_row("no_mask_window", &O::no_mask_window, 0, 10, "",
               "without a mask: how far the object may be from its start, as a fraction of its size"),
    option_row("derive_mask", &O::derive_mask, 0, 0, "",
               "with depth: derive the object's pixels near its render, without a mask, or to check a given one "
               "(false: a window; a mask as given)"),
    option_row("inlier_threshold", &O::inlier_threshold, 0, 10, " metres",
               "a depth reading this near the render is an inlier, at least (verdict, scores)", true),
    option_row("max_depth_noise", &O::max_depth_noise, 0, 1, " metres at 1 m (0: a fixed band)",
               "verdict: the noisiest depth excused; the inlier band is 3x the noise measured, up to this"),
    option_row("min_mask_iou", &O::min_mask_iou, 0, 1, "", "verdict: plausible needs at least this mask IoU"),
    option_row("min_depth_inliers", &O::min_depth_inliers, 0, 1, "",
               "verdict: plausible needs at least this fraction of depth inliers"),
    option_row("min_print_significance", &O::min_print_significance, 0, 100, " (0: not weighed)",
               "verdict: the print lines up at least this many standard deviations above chance"),
    option_row("probe_distance", &O::probe_distance, 0, 1, " metres (0: off)",
               "the loss is probed around the result at this surface displacement (curvature, covariance)"),
    option_row("device", &O::device, 0, 0, "", "cpu, cuda (an error without a GPU) or auto (CUDA when present)"),
    option_row("plain_model_rgb", &O::plain_model_rgb, 0, 0, "",
               "true: a model without print (one colour) still gets the colour term"),
  };
  r.insert(r.end(), rows.begin(), rows.end());
  r[r.size() - 2].choices = {"cpu", "cuda", "auto"};
}

}  // namespace

const std::vector<RenamedOption>& renamed_refiner_options() {
  static const std::vector<RenamedOption> renamed = {{"explore_tolerance", "shape_tolerance"},
                                                     {"explore_texture_weight", "scan_texture_weight"}};
  return renamed;
}

const std::vector<OptionSpec<RefinerOptions>>& refiner_option_table() {
  using O = RefinerOptions;
  static const std::vector<OptionSpec<O>> rows = [] {
    std::vector<OptionSpec<O>> r = {
        option_row("batch_size", &O::batch_size, 1, O::kMaxBatchSize, "", "B parallel runs, each with its own learning rate"),
        option_row("iterations", &O::iterations, 0, O::kMaxIterations, "", "gradient steps per run (paper: 100; config/paper.yaml)"),
        option_row("lr_low", &O::lr_low, 0, 10, "", "lowest learning rate drawn (dimensionless, see refiner.hpp)", true),
        option_row("lr_high", &O::lr_high, 0, 10, "", "highest learning rate drawn, >= lr_low", true),
        option_row("lr_log_uniform", &O::lr_log_uniform, 0, 0, "", "true: draw rates log-uniformly (the paper's \"exponent\" variant)"),
        option_row("lr_decay", &O::lr_decay, 0, 1, "", "rate multiplier reached at the last iteration", true),
        option_row("image_scale", &O::image_scale, O::kMinImageScale, 4, "", "refine on images resized by this factor"),
        option_row("coarse_fraction", &O::coarse_fraction, 0, 1, "",
                   "share of the iterations on images resized by a further coarse_scale (0: the paper's single scale)",
                   false, true),
        option_row("coarse_scale", &O::coarse_scale, 0.05, 1, "", "the coarse phase's further resize factor"),
        option_row("shape_tolerance", &O::shape_tolerance, 0, 0.2, " (0: none)",
                   "turns moving the surface less than this share of its diameter are the shape's near symmetries: "
                   "scanned, weighed by the print, their axes aligned"),
        option_row("shape_scan", &O::shape_scan, 0, 0, "",
                   "true: when the fine phase begins, every run is tried turned by each near symmetry"),
        option_row("scan_texture_weight", &O::scan_texture_weight, 0, LossOptions::kMaxWeight, "",
                   "texture term added to the shape scan's comparison"),
        option_row("print_search", &O::print_search, 0, M_PI, " radians (0: off)",
                   "print alignment: turn about an axis of near revolution to where the print fits best"),
        option_row("retry_turn", &O::retry_turn, 0, M_PI, " radians (0: off)",
                   "a rejected result is refined again from starts turned by this about the principal axes"),
        option_row("polish_iterations", &O::polish_iterations, 0, O::kMaxIterations, " (0: off)",
                   "after the descent, polish_runs runs go on from the result at small rates"),
        option_row("polish_runs", &O::polish_runs, 1, 16, "", "runs of the polish, at lr_low doubling per run"),
        option_row("newton_rounds", &O::newton_rounds, 0, 32, " (0: off)",
                   "then Newton steps on the loss's probed curvature, taken on clear evidence; the reach doubles "
                   "while the valley goes on, else halves"),
    };
    append_rows(r);
    append_section(r, loss_option_table(), "loss", &O::loss);
    append_section(r, render_option_table(), "render", &O::render);
    return r;
  }();
  return rows;
}


std::string RefinerOptions::to_yaml() const {
  std::ostringstream out;
  out << "# RefinerOptions (include/diffdope/refiner.hpp): every key is optional, unknown keys are rejected.\n"
         "# Units: metres, radians; the range of each value follows its comment.\n";
  std::string section;
  for (const OptionSpec<RefinerOptions>& row : refiner_option_table()) {
    if (row.section() != section) {
      section = row.section();
      out << section << ":\n";
    }
    std::string line = (section.empty() ? "" : "  ") + row.key() + ": " + row.text(*this);
    line.resize(std::max<size_t>(line.size() + 1, 28), ' ');
    std::string range;
    if (row.type == OptionType::kInt || row.type == OptionType::kDouble) {
      std::ostringstream r;
      r << (row.lo_open ? "(" : "[") << row.lo << ", " << row.hi << (row.hi_open ? ")" : "]") << row.unit;
      range = "; " + r.str();
    }
    out << line << "# " << row.doc << range << "\n";
  }
  return out.str();
}

// Every number must be finite and inside its range (the table above), so a typo cannot turn into NaN losses or an
// endless refinement.
void RefinerOptions::validate() const {
  const OptionRange check{"refiner options"};
  check_option_ranges(refiner_option_table(), *this, check);
  if (lr_high < lr_low) check.fail("lr_high must be >= lr_low");
  if (coarse_fraction > 0 && image_scale * coarse_scale < kMinImageScale) {
    std::ostringstream m;
    m << "image_scale * coarse_scale = " << image_scale * coarse_scale << " is below " << kMinImageScale;
    check.fail(m.str());
  }
  loss.validate();
  render.validate();
}

}  // namespace diffdope
