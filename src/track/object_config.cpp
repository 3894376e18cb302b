// Objects YAML (see include/diffdope/object_config.hpp).
#include "diffdope/object_config.hpp"
#include "diffdope/input_files.hpp"
#include "track/object_config_internal.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace diffdope {
namespace {

bool valid_name(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_')) return false;
  return !std::isdigit(static_cast<unsigned char>(s[0]));
}

std::vector<double> read_vector(const YAML::Node& n, size_t size, const std::string& where) {
  if (!n.IsSequence() || n.size() != size)
    throw std::runtime_error(where + ": expected a list of " + std::to_string(size) + " numbers");
  std::vector<double> v;
  for (const auto& e : n) {
    const double x = e.as<double>();
    if (!std::isfinite(x)) throw std::runtime_error(where + ": not a finite number");
    v.push_back(x);
  }
  return v;
}

Pose read_transform(const YAML::Node& n, const std::string& where) {
  if (!n.IsMap()) throw std::runtime_error(where + ": expected translation and rotation");
  Pose p;
  for (const auto& kv : n) {
    const std::string key = kv.first.as<std::string>();
    if (key == "translation") {
      const auto t = read_vector(kv.second, 3, where + ".translation");
      p.t = Eigen::Vector3d(t[0], t[1], t[2]);
    } else if (key == "rotation") {
      const auto q = read_vector(kv.second, 4, where + ".rotation (x y z w)");
      if (std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) < 1e-6)
        throw std::runtime_error(where + ".rotation: zero quaternion");
      p = Pose::from_quaternion(q[0], q[1], q[2], q[3], p.t);
    } else {
      throw std::runtime_error(where + ": unknown key '" + key + "' (translation, rotation)");
    }
  }
  return p;
}

/// symmetries: {continuous: [{axis: [x, y, z], offset: [x, y, z]}], discrete: [{translation, rotation}]}.
ObjectSymmetry read_symmetries(const YAML::Node& n, const std::string& where) {
  if (!n.IsMap()) throw std::runtime_error(where + ": expected continuous and/or discrete");
  ObjectSymmetry sym;
  for (const auto& kv : n) {
    const std::string key = kv.first.as<std::string>();
    if (!kv.second.IsSequence()) throw std::runtime_error(where + "." + key + ": expected a list");
    if (key == "continuous") {
      for (size_t i = 0; i < kv.second.size(); ++i) {
        const YAML::Node a = kv.second[i];
        const std::string w = where + ".continuous[" + std::to_string(i) + "]";
        if (!a.IsMap() || !a["axis"]) throw std::runtime_error(w + ": expected {axis, offset}");
        ObjectSymmetry::Axis axis;
        for (const auto& f : a) {
          const std::string k = f.first.as<std::string>();
          const std::vector<double> v = read_vector(f.second, 3, w + "." + k);
          if (k == "axis") axis.direction = Eigen::Vector3d(v[0], v[1], v[2]);
          else if (k == "offset") axis.offset = Eigen::Vector3d(v[0], v[1], v[2]);
          else throw std::runtime_error(w + ": unknown key '" + k + "' (axis, offset)");
        }
        sym.continuous.push_back(axis);
      }
    } else if (key == "discrete") {
      for (size_t i = 0; i < kv.second.size(); ++i)
        sym.discrete.push_back(read_transform(kv.second[i], where + ".discrete[" + std::to_string(i) + "]"));
    } else {
      throw std::runtime_error(where + ": unknown key '" + key + "' (continuous, discrete)");
    }
  }
  try {
    sym.validate_and_normalise(where);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
  return sym;
}

}  // namespace

std::string resolve_mesh_path(const std::string& mesh, const std::string& base_dir,
                              const PackageResolver& resolve_package) {
  namespace fs = std::filesystem;
  const std::string pkg_prefix = "package://", file_prefix = "file://";
  if (mesh.rfind(pkg_prefix, 0) == 0) {
    const std::string rest = mesh.substr(pkg_prefix.size());
    const size_t slash = rest.find('/');
    if (slash == std::string::npos || slash == 0) throw std::runtime_error("'" + mesh + "': expected package://PKG/PATH");
    if (!resolve_package) throw std::runtime_error("'" + mesh + "': package:// URLs need ROS to resolve");
    const std::string root = resolve_package(rest.substr(0, slash));
    if (root.empty()) throw std::runtime_error("'" + mesh + "': package '" + rest.substr(0, slash) + "' not found");
    return (fs::path(root) / rest.substr(slash + 1)).lexically_normal().string();
  }
  if (mesh.rfind(file_prefix, 0) == 0) {
    // file:// names an absolute path (file:///abs); what follows file:// otherwise would be a host, and taken as
    // a path it would resolve against whatever folder the node was started in.
    const fs::path p(mesh.substr(file_prefix.size()));
    if (!p.is_absolute())
      throw std::runtime_error("'" + mesh + "': a file:// URL takes an absolute path (file:///path/to/mesh); a path "
                               "relative to the objects file's folder is written without file://");
    return p.lexically_normal().string();
  }
  const fs::path p(mesh);
  if (p.is_absolute()) return p.lexically_normal().string();
  return (fs::path(base_dir) / p).lexically_normal().string();
}

namespace detail {

void check_object(ObjectConfig& o, const std::string& entry, const std::string& origin, const std::string& base_dir,
                  const PackageResolver& resolve_package, std::set<std::string>& names) {
  if (!valid_name(o.name))
    throw std::runtime_error(entry + ": 'name' must be a non-empty identifier [a-zA-Z_][a-zA-Z0-9_]*, got '" +
                             o.name + "'");
  const std::string where = origin + ": object '" + o.name + "'";
  if (!names.insert(o.name).second) throw std::runtime_error(where + ": name used twice");
  if (o.mesh.empty()) throw std::runtime_error(where + ": 'mesh' is required");
  if (!(o.mesh_scale > 0) || !std::isfinite(o.mesh_scale))
    throw std::runtime_error(where + ": 'mesh_scale' must be positive");
  if (o.mask_label < -1) throw std::runtime_error(where + ": 'mask_label' must be -1 or a label value >= 0");
  if (o.max_instances < 1 || o.max_instances > ObjectConfig::kMaxInstances)
    throw std::runtime_error(where + ": 'max_instances' must be in [1, " +
                             std::to_string(ObjectConfig::kMaxInstances) + "]");
  if (o.class_id < -1) throw std::runtime_error(where + ": 'class_id' must be -1 (none) or a DOPE class id >= 0");
  try {
    o.mesh_path = resolve_mesh_path(o.mesh, base_dir, resolve_package);
  } catch (const std::exception& e) {  // name the file and the object, not only the URL
    throw std::runtime_error(where + ": 'mesh' " + e.what());
  }
  if (!o.symmetries.empty()) o.symmetric = true;  // declared symmetries are scored with ADD-S too
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

}  // namespace detail

std::map<std::string, int64_t> object_class_ids(const std::vector<ObjectConfig>& objects,
                                                std::map<std::string, int64_t> overrides, const std::string& origin) {
  for (const ObjectConfig& o : objects)
    if (o.class_id >= 0) overrides.emplace(o.name, o.class_id);  // (an override of that name stays)
  std::map<int64_t, std::string> owner;
  for (const ObjectConfig& o : objects) {
    const auto id = overrides.find(o.name);
    if (id == overrides.end()) continue;
    const auto [it, fresh] = owner.emplace(id->second, o.name);
    if (!fresh)
      throw std::runtime_error(origin + ": objects '" + it->second + "' and '" + o.name + "' share the class id " +
                               std::to_string(id->second) + ": their detections cannot be told apart; give each "
                               "its own");
  }
  return overrides;
}

std::string unrefined_classes(const ObjectsConfig& cfg) {
  if (cfg.detected_not_refined.empty() && cfg.meshes_without_weights.empty()) return "";
  const auto list = [](const std::vector<std::string>& names) {
    return names.empty() ? std::string("none") : detail::joined(names);
  };
  return "detected by DOPE but not refined (no mesh): " + list(cfg.detected_not_refined) +
         "; meshes without weights (never detected, not refined): " + list(cfg.meshes_without_weights);
}

ObjectsConfig parse_objects_config(const std::string& yaml, const std::string& origin, const std::string& base_dir,
                                   const PackageResolver& resolve_package, const RefinerOptions& base) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(origin + ": not valid YAML: " + e.what());
  }
  try {
    check_yaml_expansion(root, origin);
  } catch (const InputFileError& e) {
    throw std::runtime_error(origin + ": " + e.what());
  }
  if (!root.IsMap()) throw std::runtime_error(origin + ": expected a mapping with 'objects' (and 'refiner')");
  if (detail::is_dope_config(root)) {
    try {
      return detail::parse_dope_config(root, origin, base_dir, resolve_package, base);
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(origin + ": " + e.what());
    }
  }
  ObjectsConfig cfg;
  cfg.refiner = base;
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (key == "refiner") {
      YAML::Emitter out;
      out << kv.second;
      cfg.refiner = RefinerOptions::from_yaml_string(out.c_str(), base, origin + " (refiner)");
    } else if (key != "objects") {
      throw std::runtime_error(origin + ": unknown key '" + key + "' (objects, refiner)");
    }
  }
  const YAML::Node objects = root["objects"];
  if (!objects || !objects.IsSequence() || objects.size() == 0)
    throw std::runtime_error(origin + ": 'objects' must be a non-empty list");
  std::set<std::string> names;
  for (size_t i = 0; i < objects.size(); ++i) {
    const YAML::Node n = objects[i];
    std::string where = origin + ": objects[" + std::to_string(i) + "]";
    if (!n.IsMap()) throw std::runtime_error(where + ": expected a mapping");
    ObjectConfig o;
    try {
      for (const auto& kv : n) {
        const std::string key = kv.first.as<std::string>();
        if (key == "name") o.name = kv.second.as<std::string>();
        else if (key == "mesh") o.mesh = kv.second.as<std::string>();
        else if (key == "mesh_scale") o.mesh_scale = kv.second.as<double>();
        else if (key == "symmetric") o.symmetric = kv.second.as<bool>();
        else if (key == "mask_label") o.mask_label = kv.second.as<int>();
        else if (key == "pose_topic") o.pose_topic = kv.second.as<std::string>();
        else if (key == "max_instances") o.max_instances = kv.second.as<int>();
        else if (key == "class_id") o.class_id = kv.second.as<int64_t>();
        else if (key == "model_transform") o.model_transform = read_transform(kv.second, where + ".model_transform");
        else if (key == "symmetries") o.symmetries = read_symmetries(kv.second, where + ".symmetries");
        else
          throw std::runtime_error(where + ": unknown key '" + key +
                                   "' (name, mesh, mesh_scale, symmetric, symmetries, mask_label, pose_topic, "
                                   "max_instances, class_id, model_transform)");
      }
    } catch (const YAML::Exception& e) {
      throw std::runtime_error(where + ": " + e.what());
    }
    detail::check_object(o, where, origin, base_dir, resolve_package, names);
    cfg.objects.push_back(o);
  }
  object_class_ids(cfg.objects, {}, origin);
  // Instances are named <name>_<k> on TF and topics: no other object may carry one of those names.
  for (const ObjectConfig& o : cfg.objects)
    for (int k = 0; o.max_instances > 1 && k < o.max_instances; ++k)
      if (names.count(instance_name(o, k)))
        throw std::runtime_error(origin + ": object '" + instance_name(o, k) + "' has the name of instance " +
                                 std::to_string(k) + " of '" + o.name + "' (max_instances " +
                                 std::to_string(o.max_instances) + "): rename one");
  return cfg;
}

std::string instance_name(const ObjectConfig& object, int instance) {
  return object.max_instances > 1 ? object.name + "_" + std::to_string(instance) : object.name;
}

ObjectsConfig load_objects_config(const std::string& path, const PackageResolver& resolve_package,
                                  const RefinerOptions& base) {
  const std::string dir = std::filesystem::absolute(path).parent_path().string();
  return parse_objects_config(read_text_file(path, "the objects config"), path, dir, resolve_package, base);
}

Mesh load_object_mesh(const ObjectConfig& object) {
  MeshLoadOptions mo;
  mo.scale = object.mesh_scale;
  Mesh mesh = Mesh::load(object.mesh_path, mo);
  mesh.symmetry = object.symmetries;
  const std::string mismatch = cuboid_mismatch(mesh.bbox_max() - mesh.bbox_min(), object);
  if (!mismatch.empty()) throw std::runtime_error(object.mesh_path + ": " + mismatch);
  return mesh;
}

}  // namespace diffdope
