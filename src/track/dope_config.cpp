// DOPE's own config_pose.yaml as an objects file (object_config.hpp).
#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>

#include "track/object_config_internal.hpp"

namespace diffdope::detail {
namespace {

/// DOPE's keys that say a file is its config_pose.yaml (ours has `objects` and `refiner` only).
constexpr const char* kDopeKeys[] = {"meshes", "weights", "dimensions", "class_ids", "topic_publishing",
                                     "mesh_scales", "model_transforms", "architectures"};
/// A cuboid side in DOPE's `dimensions` (centimetres) beyond this is no object a camera refines.
constexpr double kMaxDimensionCm = 1e4;

/// The entries of a DOPE map `key` (object name -> value); an absent or empty map (every line of it commented
/// out, as DOPE ships `meshes`) is empty.
std::map<std::string, YAML::Node> entries(const YAML::Node& root, const char* key, const std::string& origin) {
  std::map<std::string, YAML::Node> out;
  const YAML::Node map = root[key];
  if (!map || map.IsNull()) return out;
  if (!map.IsMap()) throw std::runtime_error(origin + ": DOPE's '" + key + "' must map object names to values");
  for (const auto& kv : map) out.emplace(kv.first.as<std::string>(), kv.second);
  return out;
}

/// DOPE's `dimensions` entry: the cuboid's three sides in centimetres, as metres.
Eigen::Vector3d read_dimensions(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence() || n.size() != 3)
    throw std::runtime_error(where + ": expected the cuboid's three sides in centimetres, e.g. [16.4, 21.3, 7.2]");
  Eigen::Vector3d d;
  for (int i = 0; i < 3; ++i) {
    d[i] = n[i].as<double>();
    if (!std::isfinite(d[i]) || d[i] <= 0 || d[i] > kMaxDimensionCm)
      throw std::runtime_error(where + ": each side must be a positive number of centimetres up to " +
                               std::to_string(int(kMaxDimensionCm)));
  }
  return d / 100.0;
}

/// DOPE's `model_transforms` entry: a 4x4 matrix (rows) whose rotation turns the mesh's axes into the cuboid's.
Eigen::Matrix3d read_model_rotation(const YAML::Node& n, const std::string& where) {
  if (!n.IsSequence() || n.size() != 4)
    throw std::runtime_error(where + ": expected a 4x4 matrix as four rows of four numbers");
  Eigen::Matrix3d R;
  for (int r = 0; r < 4; ++r) {
    if (!n[r].IsSequence() || n[r].size() != 4)
      throw std::runtime_error(where + ": expected a 4x4 matrix as four rows of four numbers");
    for (int c = 0; c < 4; ++c) {
      const double v = n[r][c].as<double>();
      if (!std::isfinite(v)) throw std::runtime_error(where + ": not a finite number");
      if (r < 3 && c < 3) R(r, c) = v;
    }
  }
  if (!(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-3) || R.determinant() < 0)
    throw std::runtime_error(where + ": its upper-left 3x3 is not a rotation");
  return R;
}

}  // namespace

bool is_dope_config(const YAML::Node& root) {
  if (!root.IsMap() || root["objects"] || root["refiner"]) return false;
  return std::any_of(std::begin(kDopeKeys), std::end(kDopeKeys), [&](const char* k) { return bool(root[k]); });
}

ObjectsConfig parse_dope_config(const YAML::Node& root, const std::string& origin, const std::string& base_dir,
                                const PackageResolver& resolve_package, const RefinerOptions& base) {
  ObjectsConfig cfg;
  cfg.refiner = base;
  const auto meshes = entries(root, "meshes", origin);
  const auto weights = entries(root, "weights", origin);
  const bool has_weights = root["weights"] && !root["weights"].IsNull();
  if (meshes.empty())
    throw std::runtime_error(
        origin + ": DOPE's file gives no object a mesh (as DOPE ships it, every 'meshes' line is commented out): "
                 "uncomment 'meshes' (and 'mesh_scales') for the objects DOPE has weights for, or list the objects "
                 "in an objects file of this package's own layout (config/objects.example.yaml)");
  // DOPE detects the classes it has weights for; only those with a mesh too can be refined.
  for (const auto& [name, w] : weights)
    if (!meshes.count(name)) cfg.detected_not_refined.push_back(name);
  for (const auto& [name, m] : meshes)
    if (has_weights && !weights.count(name)) cfg.meshes_without_weights.push_back(name);
  const auto scales = entries(root, "mesh_scales", origin);
  const auto ids = entries(root, "class_ids", origin);
  const auto dimensions = entries(root, "dimensions", origin);
  const auto transforms = entries(root, "model_transforms", origin);
  std::string topic = "dope";
  try {
    if (root["topic_publishing"]) topic = root["topic_publishing"].as<std::string>();
    if (root["input_is_rectified"]) cfg.input_is_rectified = root["input_is_rectified"].as<bool>();
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(origin + ": topic_publishing / input_is_rectified: " + e.what());
  }
  std::set<std::string> names;
  // The file's order: yaml-cpp keeps it, std::map would sort it.
  for (const auto& kv : root["meshes"]) {
    ObjectConfig o;
    o.name = kv.first.as<std::string>();
    if (has_weights && !weights.count(o.name)) continue;
    const std::string where = origin + ": meshes." + o.name;
    try {
      o.mesh = kv.second.as<std::string>();
      if (scales.count(o.name)) o.mesh_scale = scales.at(o.name).as<double>();
      if (ids.count(o.name)) o.class_id = ids.at(o.name).as<int64_t>();
      if (dimensions.count(o.name))
        o.cuboid_extent = read_dimensions(dimensions.at(o.name), origin + ": dimensions." + o.name);
      if (transforms.count(o.name))
        o.cuboid_from_mesh = read_model_rotation(transforms.at(o.name), origin + ": model_transforms." + o.name);
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(where + ": " + e.what());
    }
    o.pose_topic = "/" + topic + "/pose_" + o.name;
    check_object(o, where, origin, base_dir, resolve_package, names);
    cfg.objects.push_back(o);
  }
  if (cfg.objects.empty())
    throw std::runtime_error(origin + ": no object has both DOPE's weights (" + joined(cfg.detected_not_refined) +
                             ") and a mesh (" + joined(cfg.meshes_without_weights) +
                             "): give a mesh to an object DOPE detects");
  // A refined object's detections are picked by class id: a class DOPE detects with the same id would pass as it.
  std::map<int64_t, std::vector<std::string>> by_id;
  for (const auto& [name, id] : ids)
    if (!has_weights || weights.count(name) || meshes.count(name)) {
      try {
        by_id[id.as<int64_t>()].push_back(name);
      } catch (const YAML::Exception& e) {
        throw std::runtime_error(origin + ": class_ids." + name + ": " + e.what());
      }
    }
  for (const auto& [id, named] : by_id) {
    const bool refined = std::any_of(named.begin(), named.end(), [&](const std::string& n) { return names.count(n); });
    if (named.size() > 1 && refined)
      throw std::runtime_error(origin + ": class_ids: " + joined(named) + " share the id " + std::to_string(id) +
                               ": their detections cannot be told apart; give each its own id (in DOPE's file, "
                               "which DOPE reads too)");
  }
  return cfg;
}

}  // namespace diffdope::detail
