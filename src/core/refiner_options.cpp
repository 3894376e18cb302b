// RefinerOptions from YAML (the same keys as the struct's fields; see config/default.yaml).
#include <yaml-cpp/yaml.h>

#include <set>
#include <stdexcept>

#include "diffdope/refiner.hpp"

namespace diffdope {
namespace {

template <typename T>
void read(const YAML::Node& node, const char* key, T& value, std::set<std::string>& used) {
  used.insert(key);
  if (node[key]) value = node[key].as<T>();
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
    read(root, "seed", o.seed, used);
    read(root, "successive_halving", o.successive_halving, used);
    read(root, "early_stop_patience", o.early_stop_patience, used);
    read(root, "early_stop_tolerance", o.early_stop_tolerance, used);
    read(root, "no_mask_window", o.no_mask_window, used);
    read(root, "inlier_threshold", o.inlier_threshold, used);
    read(root, "min_mask_iou", o.min_mask_iou, used);
    read(root, "min_depth_inliers", o.min_depth_inliers, used);
    read(root, "device", o.device, used);
    used.insert("loss");
    if (const YAML::Node l = root["loss"]) {
      std::set<std::string> lu;
      read(l, "weight_rgb", o.loss.weight_rgb, lu);
      read(l, "weight_depth", o.loss.weight_depth, lu);
      read(l, "weight_mask", o.loss.weight_mask, lu);
      read(l, "weight_edges", o.loss.weight_edges, lu);
      read(l, "edge_scale", o.loss.edge_scale, lu);
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

void RefinerOptions::validate() const {
  auto fail = [](const std::string& m) { throw std::invalid_argument("refiner options: " + m); };
  if (batch_size < 1) fail("batch_size must be >= 1");
  if (iterations < 0) fail("iterations must be >= 0");
  if (!(lr_low > 0) || !(lr_high >= lr_low)) fail("need 0 < lr_low <= lr_high");
  if (!(lr_decay > 0) || lr_decay > 1) fail("lr_decay must be in (0, 1]");
  if (!(image_scale > 0) || image_scale > 4) fail("image_scale must be in (0, 4]");
  if (!(coarse_fraction >= 0) || !(coarse_fraction < 1)) fail("coarse_fraction must be in [0, 1)");
  if (!(coarse_scale > 0) || !(coarse_scale <= 1)) fail("coarse_scale must be in (0, 1]");
  if (loss.weight_rgb < 0 || loss.weight_depth < 0 || loss.weight_mask < 0 || loss.weight_edges < 0)
    fail("loss weights must be >= 0");
  if (!(loss.edge_scale > 0)) fail("loss.edge_scale must be > 0");
  if (!(loss.depth_truncation > 0)) fail("loss.depth_truncation must be > 0");
  if (early_stop_patience < 0) fail("early_stop_patience must be >= 0");
  if (!(render.lod_pixel_error >= 0) || render.lod_pixel_error > 100)
    fail("render.lod_pixel_error must be in [0, 100] pixels (0: always the full mesh)");
  if (device != "cpu" && device != "cuda" && device != "auto") fail("device must be auto, cpu or cuda");
}

}  // namespace diffdope
