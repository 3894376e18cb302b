#pragma once
// The objects a refiner node tracks, read from YAML (ROS-free, so tools and tests can read the same file).
//
//   refiner:                # optional: RefinerOptions, the same keys as config/default.yaml
//     iterations: 60
//   objects:
//     - name: cracker                       # [a-zA-Z0-9_]: used in topic and TF frame names
//       mesh: package://my_pkg/meshes/cracker.ply   # or an absolute path, file://, or relative to this file
//       mesh_scale: 0.01                    # metres per mesh unit (default 1)
//       symmetric: false                    # scored with ADD-S when true (evaluation only)
//       symmetries:                         # declared symmetries (symmetry.hpp; mesh frame, metres): the refiner
//         continuous: [{axis: [0, 0, 1], offset: [0, 0, 0]}]  # does not search along them, the poses it
//         discrete: [{translation: [0, 0, 0], rotation: [1, 0, 0, 0]}]  # reports do not spin or flip
//       mask_label: 3                       # label-image value of this object; -1 (default): any nonzero pixel
//       pose_topic: /dope/pose_cracker      # detector PoseStamped topic (default /dope/pose_<name>)
//       class_id: 1                         # DOPE's class id in its Detection3DArray (default: none)
//       model_transform:                    # pose of the mesh in the object frame the detector reports
//         translation: [0, 0, 0]            # metres
//         rotation: [0, 0, 0, 1]            # quaternion x y z w
//
// Or DOPE's own config_pose.yaml, as it is: an object per class with both `weights` (what DOPE detects) and
// `meshes` (file:// or package://), scaled by its `mesh_scales`, with its `class_ids` and the pose topic
// /<topic_publishing>/pose_<name>. DOPE turns the pose it publishes by its `model_transforms` itself, so the
// published pose is the mesh's and none applies here; they and DOPE's `dimensions` serve the mesh's check
// (cuboid_mismatch()).
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "diffdope/pose.hpp"
#include "diffdope/refiner.hpp"

namespace diffdope {

struct ObjectConfig {
  std::string name;
  std::string mesh;        // as written in the file (package://, file://, absolute or relative path)
  std::string mesh_path;   // resolved absolute file path
  double mesh_scale = 1.0; // metres per mesh unit
  bool symmetric = false;  // scored with ADD-S (true whenever symmetries are declared)
  ObjectSymmetry symmetries;  // mesh frame, metres; load_object_mesh() gives them to the mesh
  int mask_label = -1;     // -1: any nonzero mask pixel belongs to the object
  std::string pose_topic;  // empty: the node's default (/dope/pose_<name>)
  /// Instances of this object tracked at once ([1, kMaxInstances]); more than one names them <name>_<k>.
  int max_instances = 1;
  static constexpr int kMaxInstances = 32;  // (InstanceTracks::kMaxInstances)
  int64_t class_id = -1;   // DOPE's class id in its Detection3DArray; -1: none (the node's ~class_ids may give it)
  Pose model_transform;    // mesh frame -> object (detector) frame; identity by default
  /// The detector's cuboid (DOPE's `dimensions`), metres along the cuboid's own axes; zero: not given.
  Eigen::Vector3d cuboid_extent = Eigen::Vector3d::Zero();
  /// Turns the mesh's axes into the cuboid's (DOPE's `model_transforms` rotation); identity by default.
  Eigen::Matrix3d cuboid_from_mesh = Eigen::Matrix3d::Identity();
};

struct ObjectsConfig {
  std::vector<ObjectConfig> objects;
  RefinerOptions refiner;
  /// DOPE's file: the classes it has weights for but no mesh (detected, not refined), and those with a mesh but no
  /// weights (never detected, so not refined); empty for this package's own layout.
  std::vector<std::string> detected_not_refined, meshes_without_weights;
  /// DOPE's `input_is_rectified`: whether the images DOPE (and so this refiner) reads are rectified; unset when the
  /// file does not say.
  std::optional<bool> input_is_rectified;
};

/// The name of instance `instance` on TF and topics: the object's name when it has one instance, else
/// <name>_<instance>.
std::string instance_name(const ObjectConfig& object, int instance);

/// The class id of each object (DOPE's, by which a Detection3DArray names it): `overrides` by name (the node's
/// ~class_ids) first, then the file's. Throws std::runtime_error naming both objects and `origin` when two objects
/// end with one id: their detections could not be told apart.
std::map<std::string, int64_t> object_class_ids(const std::vector<ObjectConfig>& objects,
                                                std::map<std::string, int64_t> overrides, const std::string& origin);

/// DOPE's classes that are not refined, in one line to say once at start ("detected by DOPE but not refined (no
/// mesh): ...; meshes without weights (never detected, not refined): ..."); empty when every class is refined.
std::string unrefined_classes(const ObjectsConfig& cfg);

/// Turns a package:// URL into a file path (the ROS layer passes ros::package::getPath); throws when unknown.
using PackageResolver = std::function<std::string(const std::string& package)>;

/// Reads and checks the file: unique valid names and class ids, required keys, no unknown keys, finite
/// transform, positive scale. Mesh paths are resolved but not opened (a missing mesh disables one object, not the config).
/// Throws std::runtime_error naming the file, the object and the key.
ObjectsConfig load_objects_config(const std::string& path, const PackageResolver& resolve_package = {},
                                  const RefinerOptions& base = RefinerOptions());
ObjectsConfig parse_objects_config(const std::string& yaml, const std::string& origin,
                                   const std::string& base_dir, const PackageResolver& resolve_package = {},
                                   const RefinerOptions& base = RefinerOptions());

/// Resolves a mesh reference: package://pkg/rel, file:///abs, /abs, or a path relative to base_dir (the objects
/// file's folder, never the working directory). Throws std::runtime_error for file:// with a relative path.
std::string resolve_mesh_path(const std::string& mesh, const std::string& base_dir,
                              const PackageResolver& resolve_package);

/// Loads the object's mesh (scaled to metres, model_transform not applied, the declared symmetries attached).
/// Throws std::runtime_error, naming the file, when it cannot be read or does not fit the cuboid.
Mesh load_object_mesh(const ObjectConfig& object);

/// Whether a mesh's extent (metres along its axes, after mesh_scale) fits the object's cuboid: empty when it does
/// (no cuboid given, or every side within kCuboidTolerance, as a handle or a cap leaves it), else one line that
/// says what is wrong and how to fix it: a factor of 10, 100 or 1000 names the likely `mesh_scales`, axes in
/// another order name the `model_transforms` rotation that lines them up, anything else gives both extents.
std::string cuboid_mismatch(const Eigen::Vector3d& mesh_extent, const ObjectConfig& object);
/// A side of the mesh may be this factor longer or shorter than the cuboid's.
constexpr double kCuboidTolerance = 1.3;

}  // namespace diffdope
