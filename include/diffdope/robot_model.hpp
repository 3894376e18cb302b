#pragma once
// A robot read from URDF (urdfdom): its links' visual meshes and the forward kinematics that place them in the
// root link's frame (the robot base) for given joint positions. Camera-to-robot calibration renders a robot this
// way (calibration.hpp). Units: metres, radians (prismatic joints: metres).
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "diffdope/mesh.hpp"
#include "diffdope/object_config.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

/// One visual element of a link: a mesh file (STL, DAE, OBJ, PLY, ... through assimp) or a URDF primitive (box,
/// cylinder, sphere), placed by the visual's origin, with the URDF mesh's per-axis scale.
struct RobotVisual {
  std::string link;
  Pose link_from_visual;
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  std::shared_ptr<const Mesh> mesh;  // finalized; shared by visuals of one file and colour
  std::string source;                // the file (resolved) or the primitive, for messages
};

class RobotModel {
 public:
  /// Reads the URDF, resolves package:// (with `resolve_package`), file:// and relative mesh paths (relative to
  /// the URDF's directory), loads every visual mesh. Throws std::runtime_error naming the file and the link or
  /// joint: unreadable XML, a missing mesh, floating or planar joints (not a fixed-base arm), no visual at all.
  static RobotModel load_urdf(const std::string& path, const PackageResolver& resolve_package = {},
                              const MeshLoadOptions& mesh_options = {});
  static RobotModel parse_urdf(const std::string& xml, const std::string& base_dir, const std::string& origin,
                               const PackageResolver& resolve_package = {}, const MeshLoadOptions& mesh_options = {});

  const std::string& name() const { return name_; }
  const std::string& root_link() const { return root_; }
  const std::vector<RobotVisual>& visuals() const { return visuals_; }
  /// The joints whose positions link_poses() needs: movable (revolute, continuous, prismatic), not mimic.
  std::vector<std::string> joint_names() const;

  /// One joint of the tree, as read from the URDF.
  struct Joint {
    std::string name, parent, child;
    enum class Type { kFixed, kRevolute, kContinuous, kPrismatic } type = Type::kFixed;
    Pose parent_from_origin;
    Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
    std::string mimic;  // the joint this one follows (q = multiplier * q_mimic + offset)
    double multiplier = 1, offset = 0;
    /// The URDF's limits (revolute, prismatic); infinite for continuous and fixed joints.
    double lower = -std::numeric_limits<double>::infinity(), upper = std::numeric_limits<double>::infinity();
  };
  /// How far link_poses() lets a position pass its joint's limits (joint_states run a little past them) before it
  /// refuses it as a wrong unit or joint.
  static constexpr double kJointLimitSlackRadians = 0.1, kJointLimitSlackMetres = 0.01;

  /// Root (base) from every link at `positions` (joint name -> radians or metres; extra names are ignored).
  /// Throws std::invalid_argument naming a needed joint that is missing, not finite or beyond its limits by
  /// more than kJointLimitSlack*.
  std::map<std::string, Pose> link_poses(const std::map<std::string, double>& positions) const;
  /// Every visual placed in the base frame at `positions` (for merge_meshes()), but those of `leave_out`'s links.
  std::vector<MeshPart> posed_visuals(const std::map<std::string, double>& positions,
                                      const std::set<std::string>& leave_out = {}) const;
  bool has_link(const std::string& link) const;
  /// `link` and every link joined to it through fixed joints only (up and down the tree): what moves with it.
  std::set<std::string> links_fixed_to(const std::string& link) const;

 private:
  double position_of(const Joint& j, const std::map<std::string, double>& positions) const;

  std::string name_, root_;
  std::vector<Joint> joints_;  // parents before children (a walk from the root)
  std::vector<RobotVisual> visuals_;
};

}  // namespace diffdope
