// A robot from URDF (robot_model.hpp): urdfdom parses, we load the meshes and do the forward kinematics.
#include "diffdope/robot_model.hpp"

#include <console_bridge/console.h>
#include <urdf_parser/urdf_parser.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "diffdope/input_files.hpp"
#include "diffdope/input_limits.hpp"
#include "diffdope/primitives.hpp"

namespace diffdope {
namespace {

/// urdfdom's error messages (console_bridge) while it parses, to be said in our error rather than lost on a
/// console: one parse at a time (the handler is global).
class UrdfdomErrors : public console_bridge::OutputHandler {
 public:
  UrdfdomErrors() : lock_(mutex()) { console_bridge::useOutputHandler(this); }
  ~UrdfdomErrors() override { console_bridge::restorePreviousOutputHandler(); }
  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR && first.empty()) first = text;
  }
  std::string first;  // the first error (later ones follow from it)

 private:
  static std::mutex& mutex() {
    static std::mutex m;
    return m;
  }
  std::lock_guard<std::mutex> lock_;
};

/// The deepest element nesting of an XML text (tags counted; comments, CDATA, declarations and processing
/// instructions skipped), stopping once it exceeds `limit`: urdfdom's parser recurses per level, so a file nested
/// 100 000 deep would exhaust the stack.
int xml_depth(const std::string& xml, int limit) {
  int depth = 0, deepest = 0;
  for (size_t i = xml.find('<'); i != std::string::npos && deepest <= limit; i = xml.find('<', i + 1)) {
    const auto skip_to = [&](const char* end) {
      const size_t e = xml.find(end, i);
      i = e == std::string::npos ? xml.size() : e;
    };
    if (xml.compare(i, 4, "<!--") == 0) skip_to("-->");
    else if (xml.compare(i, 9, "<![CDATA[") == 0) skip_to("]]>");
    else if (xml.compare(i, 2, "<?") == 0 || xml.compare(i, 2, "<!") == 0) skip_to(">");
    else if (xml.compare(i, 2, "</") == 0) depth = std::max(0, depth - 1);
    else {
      const size_t close = xml.find('>', i);
      if (close == std::string::npos) break;
      if (xml[close - 1] != '/') deepest = std::max(deepest, ++depth);
      i = close;
    }
  }
  return deepest;
}

Pose to_pose(const urdf::Pose& p) {
  double x, y, z, w;
  p.rotation.getQuaternion(x, y, z, w);
  return Pose::from_quaternion(x, y, z, w, Eigen::Vector3d(p.position.x, p.position.y, p.position.z));
}

/// A joint's or visual's origin must be finite and within input_limits::kMaxRobotOffset: beyond, the forward
/// kinematics overflow and the failure would surface far from its cause.
void check_origin(const Pose& p, const std::string& where) {
  if (!p.t.allFinite() || !p.R.allFinite()) throw std::runtime_error(where + ": origin is not finite");
  if (p.t.cwiseAbs().maxCoeff() > input_limits::kMaxRobotOffset) {
    std::ostringstream m;
    m.precision(4);
    m << where << ": origin (" << p.t.transpose() << ") m is more than " << input_limits::kMaxRobotOffset
      << " m away: not a robot's";
    throw std::runtime_error(m.str());
  }
}

RobotModel::Joint joint_of(const urdf::Joint& j, const std::string& parent, const std::string& origin) {
  using Joint = RobotModel::Joint;
  Joint joint;
  joint.name = j.name;
  joint.parent = parent;
  joint.child = j.child_link_name;
  joint.parent_from_origin = to_pose(j.parent_to_joint_origin_transform);
  joint.axis = Eigen::Vector3d(j.axis.x, j.axis.y, j.axis.z);
  const std::string where = origin + ": joint '" + j.name + "'";
  check_origin(joint.parent_from_origin, where);
  switch (j.type) {
    case urdf::Joint::FIXED: joint.type = Joint::Type::kFixed; break;
    case urdf::Joint::REVOLUTE: joint.type = Joint::Type::kRevolute; break;
    case urdf::Joint::CONTINUOUS: joint.type = Joint::Type::kContinuous; break;
    case urdf::Joint::PRISMATIC: joint.type = Joint::Type::kPrismatic; break;
    default:
      throw std::runtime_error(where + ": floating and planar joints are not supported (a fixed-base robot is)");
  }
  if (joint.type != Joint::Type::kFixed) {
    if (!joint.axis.allFinite() || joint.axis.norm() < 1e-9) throw std::runtime_error(where + ": zero axis");
    joint.axis.normalize();
  }
  // Revolute and prismatic joints carry limits (urdfdom refuses them without); a position far outside is a
  // wrong unit or a wrong joint, not a robot pose.
  if ((joint.type == Joint::Type::kRevolute || joint.type == Joint::Type::kPrismatic) && j.limits &&
      std::isfinite(j.limits->lower) && std::isfinite(j.limits->upper) && j.limits->lower <= j.limits->upper) {
    joint.lower = j.limits->lower;
    joint.upper = j.limits->upper;
  }
  if (j.mimic) {
    joint.mimic = j.mimic->joint_name;
    joint.multiplier = j.mimic->multiplier;
    joint.offset = j.mimic->offset;
  }
  return joint;
}

}  // namespace

RobotModel RobotModel::load_urdf(const std::string& path, const PackageResolver& resolve_package,
                                 const MeshLoadOptions& mesh_options) {
  const std::string dir = std::filesystem::absolute(path).parent_path().string();
  return parse_urdf(read_text_file(path, "the URDF"), dir, path, resolve_package, mesh_options);
}

RobotModel RobotModel::parse_urdf(const std::string& xml, const std::string& base_dir, const std::string& origin,
                                  const PackageResolver& resolve_package, const MeshLoadOptions& mesh_options) {
  if (xml.find_first_not_of(" \t\r\n") == std::string::npos) throw std::runtime_error(origin + ": the file is empty");
  if (xml_depth(xml, input_limits::kMaxNesting) > input_limits::kMaxNesting)
    throw std::runtime_error(origin + ": XML nested deeper than " + std::to_string(input_limits::kMaxNesting) +
                             " levels: not a URDF");
  urdf::ModelInterfaceSharedPtr urdf;
  std::string urdfdom_error;
  {
    UrdfdomErrors errors;
    urdf = urdf::parseURDF(xml);
    urdfdom_error = errors.first;
  }
  // urdfdom drops what it cannot read (a visual with a NaN scale) with only a console message: that is an error.
  if (!urdfdom_error.empty()) throw std::runtime_error(origin + ": not a valid URDF: " + urdfdom_error);
  if (!urdf || !urdf->getRoot()) throw std::runtime_error(origin + ": not a valid URDF (no root link)");
  RobotModel model;
  model.name_ = urdf->getName();
  model.root_ = urdf->getRoot()->name;

  std::map<std::string, std::shared_ptr<const Mesh>> loaded;  // by file and colour
  // Depth first, parents before children, without recursion (a chain of thousands of links must not exhaust the
  // stack): each entry is a link and the joint that leads to it (null for the root).
  std::vector<std::pair<urdf::JointConstSharedPtr, urdf::LinkConstSharedPtr>> pending{{nullptr, urdf->getRoot()}};
  while (!pending.empty()) {
    const auto [via, link] = pending.back();
    pending.pop_back();
    if (via) model.joints_.push_back(joint_of(*via, link->getParent()->name, origin));
    for (const urdf::VisualSharedPtr& v : link->visual_array) {
      if (!v || !v->geometry) continue;
      const std::string where = origin + ": link '" + link->name + "'";
      Eigen::Vector3f colour = mesh_options.default_color;
      if (v->material) colour = Eigen::Vector3f(v->material->color.r, v->material->color.g, v->material->color.b);
      RobotVisual rv;
      rv.link = link->name;
      rv.link_from_visual = to_pose(v->origin);
      check_origin(rv.link_from_visual, where + ": visual");
      std::ostringstream key;
      key << colour.transpose() << " ";
      std::function<Mesh()> make;
      switch (v->geometry->type) {
        case urdf::Geometry::MESH: {
          const auto& m = static_cast<const urdf::Mesh&>(*v->geometry);
          try {
            rv.source = resolve_mesh_path(m.filename, base_dir, resolve_package);
          } catch (const std::exception& e) {
            throw std::runtime_error(where + ": mesh " + e.what());
          }
          rv.scale = Eigen::Vector3d(m.scale.x, m.scale.y, m.scale.z);
          if (!rv.scale.allFinite() || rv.scale.cwiseAbs().minCoeff() <= 0)
            throw std::runtime_error(where + ": mesh scale must be finite and non-zero");
          key << rv.source;
          // A description package keeps textures beside its meshes' folder (materials/, textures/): a mesh may
          // read from the URDF's folder and, named by package://, from its package too.
          std::vector<std::string> resource_dirs{base_dir};
          const std::string package_prefix = "package://";
          if (m.filename.rfind(package_prefix, 0) == 0 && resolve_package) {
            const std::string rest = m.filename.substr(package_prefix.size());
            resource_dirs.push_back(resolve_package(rest.substr(0, rest.find('/'))));
          }
          make = [&, path = rv.source, resource_dirs] {
            MeshLoadOptions o = mesh_options;
            o.default_color = colour;
            o.resource_dirs.insert(o.resource_dirs.end(), resource_dirs.begin(), resource_dirs.end());
            return Mesh::load(path, o);
          };
          break;
        }
        case urdf::Geometry::BOX: {
          const auto& b = static_cast<const urdf::Box&>(*v->geometry);
          const Eigen::Vector3d size(b.dim.x, b.dim.y, b.dim.z);
          if (!size.allFinite() || size.minCoeff() <= 0) throw std::runtime_error(where + ": box size must be positive");
          std::ostringstream desc;
          desc << "box " << size.transpose();
          key << desc.str();
          rv.source = desc.str();
          make = [=] { return make_box(size, make_flat_texture(colour, "URDF material colour")); };
          break;
        }
        case urdf::Geometry::CYLINDER: {
          const auto& c = static_cast<const urdf::Cylinder&>(*v->geometry);
          if (!(c.radius > 0) || !(c.length > 0)) throw std::runtime_error(where + ": cylinder size must be positive");
          key << "cylinder " << c.radius << " " << c.length;
          rv.source = "cylinder";
          make = [=, r = c.radius, l = c.length] { return make_cylinder(r, l, 48, make_flat_texture(colour, "URDF material colour")); };
          break;
        }
        case urdf::Geometry::SPHERE: {
          const auto& s = static_cast<const urdf::Sphere&>(*v->geometry);
          if (!(s.radius > 0)) throw std::runtime_error(where + ": sphere radius must be positive");
          key << "sphere " << s.radius;
          rv.source = "sphere";
          make = [=, r = s.radius] { return make_uv_sphere(r, 16, 32, make_flat_texture(colour, "URDF material colour")); };
          break;
        }
        default:
          throw std::runtime_error(where + ": unknown visual geometry");
      }
      auto found = loaded.find(key.str());
      if (found == loaded.end()) {
        try {
          found = loaded.emplace(key.str(), std::make_shared<const Mesh>(make())).first;
        } catch (const std::exception& e) {
          throw std::runtime_error(where + ": " + e.what());
        }
      }
      rv.mesh = found->second;
      model.visuals_.push_back(std::move(rv));
    }
    for (auto j = link->child_joints.rbegin(); j != link->child_joints.rend(); ++j)
      pending.emplace_back(*j, urdf->getLink((*j)->child_link_name));
  }
  if (model.visuals_.empty()) throw std::runtime_error(origin + ": no link has a visual: nothing to render");
  for (const Joint& j : model.joints_)
    if (!j.mimic.empty()) {
      bool found = false;
      for (const Joint& k : model.joints_)
        found = found || (k.name == j.mimic && k.mimic.empty() && k.type != Joint::Type::kFixed);
      if (!found)
        throw std::runtime_error(origin + ": joint '" + j.name + "' mimics '" + j.mimic +
                                 "', which is not a movable joint of the model (or mimics another)");
    }
  return model;
}

std::vector<std::string> RobotModel::joint_names() const {
  std::vector<std::string> out;
  for (const Joint& j : joints_)
    if (j.type != Joint::Type::kFixed && j.mimic.empty()) out.push_back(j.name);
  return out;
}

double RobotModel::position_of(const Joint& j, const std::map<std::string, double>& positions) const {
  const std::string& name = j.mimic.empty() ? j.name : j.mimic;
  const auto it = positions.find(name);
  if (it == positions.end()) throw std::invalid_argument("joint '" + name + "' has no position");
  if (!std::isfinite(it->second)) throw std::invalid_argument("joint '" + name + "': position is not finite");
  const double q = j.mimic.empty() ? it->second : j.multiplier * it->second + j.offset;
  const double slack = j.type == Joint::Type::kPrismatic ? kJointLimitSlackMetres : kJointLimitSlackRadians;
  // (A mimic follows another joint: its own limits are often nominal.)
  if (j.mimic.empty() && (q < j.lower - slack || q > j.upper + slack)) {
    std::ostringstream m;
    m << "joint '" << j.name << "': position " << q << " is outside its limits [" << j.lower << ", " << j.upper
      << "] (radians, or metres for a prismatic joint)";
    throw std::invalid_argument(m.str());
  }
  return q;
}

std::map<std::string, Pose> RobotModel::link_poses(const std::map<std::string, double>& positions) const {
  std::map<std::string, Pose> out;
  out[root_] = Pose();
  for (const Joint& j : joints_) {  // parents first
    Pose motion;
    if (j.type == Joint::Type::kRevolute || j.type == Joint::Type::kContinuous)
      motion.R = Eigen::AngleAxisd(position_of(j, positions), j.axis).toRotationMatrix();
    else if (j.type == Joint::Type::kPrismatic)
      motion.t = position_of(j, positions) * j.axis;
    out[j.child] = out.at(j.parent) * j.parent_from_origin * motion;
  }
  return out;
}

std::vector<MeshPart> RobotModel::posed_visuals(const std::map<std::string, double>& positions,
                                                const std::set<std::string>& leave_out) const {
  const std::map<std::string, Pose> links = link_poses(positions);
  std::vector<MeshPart> parts;
  for (const RobotVisual& v : visuals_)
    if (!leave_out.count(v.link)) parts.push_back({v.mesh.get(), links.at(v.link) * v.link_from_visual, v.scale});
  return parts;
}

bool RobotModel::has_link(const std::string& link) const {
  if (link == root_) return true;
  for (const Joint& j : joints_)
    if (j.child == link) return true;
  return false;
}

std::set<std::string> RobotModel::links_fixed_to(const std::string& link) const {
  std::set<std::string> out{link};
  for (bool grew = true; grew;) {  // joints_ is a tree walk: a few sweeps reach every fixed neighbour
    grew = false;
    for (const Joint& j : joints_)
      if (j.type == Joint::Type::kFixed && out.count(j.parent) != out.count(j.child)) {
        out.insert(j.parent);
        out.insert(j.child);
        grew = true;
      }
  }
  return out;
}

}  // namespace diffdope
