// RefinerOptions from YAML (the same keys as the struct's fields; see config/default.yaml).
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <sstream>
#include <type_traits>
#include <stdexcept>

#include "diffdope/object_track.hpp"
#include "base/option_range.hpp"
#include "diffdope/refiner.hpp"

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

RefinerOptions parse(const YAML::Node& root, RefinerOptions o, const std::string& origin) {
  if (!root || root.IsNull()) return o;
  if (!root.IsMap()) throw std::runtime_error(origin + ": expected a mapping of option names to values");
  std::set<std::string> used;
  try {
    read(root, "batch_size", o.batch_size, used);
    read(root, "iterations", o.iterations, used);
    read(root, "lr_low", o.lr_low, used);
    read(root, "lr_high", o.lr_high, used);
    read(root, "lr_log_uniform", o.lr_log_uniform, used);
    read(root, "lr_decay", o.lr_decay, used);
    read(root, "image_scale", o.image_scale, used);
    read(root, "coarse_fraction", o.coarse_fraction, used);
    read(root, "coarse_scale", o.coarse_scale, used);
    read(root, "explore_tolerance", o.explore_tolerance, used);
    read(root, "explore_texture_weight", o.explore_texture_weight, used);
    read(root, "print_search", o.print_search, used);
    read(root, "retry_turn", o.retry_turn, used);
    read(root, "seed", o.seed, used);
    read(root, "successive_halving", o.successive_halving, used);
    read(root, "early_stop_patience", o.early_stop_patience, used);
    read(root, "early_stop_tolerance", o.early_stop_tolerance, used);
    read(root, "no_mask_window", o.no_mask_window, used);
    read(root, "inlier_threshold", o.inlier_threshold, used);
    read(root, "min_mask_iou", o.min_mask_iou, used);
    read(root, "min_depth_inliers", o.min_depth_inliers, used);
    read(root, "min_print_significance", o.min_print_significance, used);
    read(root, "probe_distance", o.probe_distance, used);
    read(root, "plain_model_rgb", o.plain_model_rgb, used);
    read(root, "polish_iterations", o.polish_iterations, used);
    read(root, "polish_runs", o.polish_runs, used);
    read(root, "device", o.device, used);
    used.insert("loss");
    if (const YAML::Node l = root["loss"]) {
      std::set<std::string> lu;
      read(l, "weight_rgb", o.loss.weight_rgb, lu);
      read(l, "weight_depth", o.loss.weight_depth, lu);
      read(l, "weight_mask", o.loss.weight_mask, lu);
      read(l, "weight_edges", o.loss.weight_edges, lu);
      read(l, "edge_scale", o.loss.edge_scale, lu);
      read(l, "weight_texture", o.loss.weight_texture, lu);
      read(l, "texture_epsilon", o.loss.texture_epsilon, lu);
      read(l, "rgb_miss", o.loss.rgb_miss, lu);
      read(l, "depth_truncation", o.loss.depth_truncation, lu);
      read(l, "occlusion_margin", o.loss.occlusion_margin, lu);
      reject_unknown(l, lu, origin + " (loss)");
    }
    used.insert("render");
    if (const YAML::Node r = root["render"]) {
      std::set<std::string> ru;
      read(r, "cull_back_faces", o.render.cull_back_faces, ru);
      read(r, "auto_cull_closed", o.render.auto_cull_closed, ru);
      read(r, "near_plane", o.render.near_plane, ru);
      read(r, "roi_margin", o.render.roi_margin, ru);
      read(r, "lod_pixel_error", o.render.lod_pixel_error, ru);
      read(r, "threads", o.render.threads, ru);
      reject_unknown(r, ru, origin + " (render)");
    }
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
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(path + ": cannot read the file");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  return parse(root, base, path);
}

RefinerOptions RefinerOptions::from_yaml_string(const std::string& yaml, const RefinerOptions& base,
                                                const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
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




// Every number must be finite and inside its documented range (include/diffdope/refiner.hpp), so a typo cannot
// turn into NaN losses or an endless refinement.
void RefinerOptions::validate() const {
  const OptionRange check{"refiner options"};
  check("batch_size", batch_size, 1, kMaxBatchSize);
  check("iterations", iterations, 0, kMaxIterations);
  check.above("lr_low", lr_low, 0, 10);
  check.above("lr_high", lr_high, 0, 10);
  if (lr_high < lr_low) check.fail("lr_high must be >= lr_low");
  check.above("lr_decay", lr_decay, 0, 1);
  check("image_scale", image_scale, kMinImageScale, 4);
  if (!(coarse_fraction >= 0 && coarse_fraction < 1)) check.fail("coarse_fraction must be in [0, 1)");
  check("coarse_scale", coarse_scale, 0.05, 1);
  check("explore_tolerance", explore_tolerance, 0, 0.2);
  check("explore_texture_weight", explore_texture_weight, 0, LossOptions::kMaxWeight);
  check("print_search", print_search, 0, M_PI);
  check("retry_turn", retry_turn, 0, M_PI);
  check("polish_iterations", polish_iterations, 0, kMaxIterations, " (0: off)");
  check("polish_runs", polish_runs, 1, 16);
  if (coarse_fraction > 0 && image_scale * coarse_scale < kMinImageScale) {
    std::ostringstream m;
    m << "image_scale * coarse_scale = " << image_scale * coarse_scale << " is below " << kMinImageScale;
    check.fail(m.str());
  }
  check("early_stop_patience", early_stop_patience, 0, kMaxIterations, " iterations (0: off)");
  check("early_stop_tolerance", early_stop_tolerance, 0, 1);
  check("no_mask_window", no_mask_window, 0, 10);
  check.above("inlier_threshold", inlier_threshold, 0, 10, " metres");
  check("min_mask_iou", min_mask_iou, 0, 1);
  check("min_depth_inliers", min_depth_inliers, 0, 1);
  check("min_print_significance", min_print_significance, 0, 100);
  check("probe_distance", probe_distance, 0, 1, " metres");
  if (device != "cpu" && device != "cuda" && device != "auto") check.fail("device must be auto, cpu or cuda");
  loss.validate();
  render.validate();
}

}  // namespace diffdope
