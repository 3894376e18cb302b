// The generated test arm (procedural_robot.hpp).
#include "diffdope/procedural_robot.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "diffdope/mesh.hpp"
#include "diffdope/procedural.hpp"

namespace diffdope {
namespace {

Texture grey(float g) { return make_flat_texture(Eigen::Vector3f(g, g, 0.95f * g)); }

}  // namespace

GeneratedRobot write_generated_robot(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(fs::path(dir) / "meshes", ec);
  if (ec) throw std::runtime_error(dir + ": cannot create: " + ec.message());
  // Link meshes, each in its link's frame (the joint at its origin, the link along +z).
  struct Part {
    std::string name;
    Mesh mesh;
    double z_centre;  // visual origin: the mesh centre on the link's z axis
  };
  std::vector<Part> parts;
  parts.push_back({"base", make_box(Eigen::Vector3d(0.22, 0.18, 0.10), grey(0.35f)), 0.05});
  parts.push_back({"link1", make_cylinder(0.055, 0.12, 48, grey(0.6f)), 0.06});
  parts.push_back({"link2", make_box(Eigen::Vector3d(0.07, 0.06, 0.30), grey(0.7f)), 0.15});
  parts.push_back({"link3", make_box(Eigen::Vector3d(0.05, 0.05, 0.25), grey(0.65f)), 0.125});
  parts.push_back({"link4", make_cylinder(0.035, 0.08, 32, grey(0.5f)), 0.04});
  parts.push_back({"link5", make_box(Eigen::Vector3d(0.11, 0.04, 0.06), grey(0.75f)), 0.03});
  for (const Part& p : parts) save_ply(p.mesh, (fs::path(dir) / "meshes" / (p.name + ".ply")).string(), 1.0);

  // Joint offsets along the parent's z (the parent link's length), axes alternating about z and y.
  const double offset[5] = {0.10, 0.12, 0.30, 0.25, 0.08};
  const char* axis[5] = {"0 0 1", "0 1 0", "0 1 0", "0 0 1", "0 1 0"};
  GeneratedRobot robot;
  std::ostringstream u;
  u << "<?xml version=\"1.0\"?>\n<robot name=\"diffdope_test_arm\">\n"
    << "  <material name=\"orange\"><color rgba=\"0.9 0.5 0.1 1\"/></material>\n";
  for (size_t i = 0; i < parts.size(); ++i) {
    const std::string link = i == 0 ? "base_link" : parts[i].name;
    u << "  <link name=\"" << link << "\">\n    <visual>\n      <origin xyz=\"0 0 " << parts[i].z_centre
      << "\" rpy=\"0 0 0\"/>\n      <geometry><mesh filename=\"meshes/" << parts[i].name
      << ".ply\"/></geometry>\n    </visual>\n  </link>\n";
    if (i == 0) continue;
    const std::string joint = "joint" + std::to_string(i), parent = i == 1 ? "base_link" : parts[i - 1].name;
    const double lower = i == 1 ? -2.5 : -1.6, upper = i == 1 ? 2.5 : 1.6;
    u << "  <joint name=\"" << joint << "\" type=\"revolute\">\n    <parent link=\"" << parent
      << "\"/>\n    <child link=\"" << link << "\"/>\n    <origin xyz=\"0 0 " << offset[i - 1]
      << "\" rpy=\"0 0 0\"/>\n    <axis xyz=\"" << axis[i - 1] << "\"/>\n    <limit lower=\"" << lower
      << "\" upper=\"" << upper << "\" effort=\"10\" velocity=\"1\"/>\n  </joint>\n";
    robot.joints.push_back(joint);
    robot.limits[joint] = {lower, upper};
  }
  // A tool on a fixed joint, drawn as a URDF primitive (no mesh file), off the hand's axis.
  u << "  <link name=\"tool\">\n    <visual>\n      <origin xyz=\"0.03 0 0.02\" rpy=\"0 0 0\"/>\n"
    << "      <geometry><box size=\"0.03 0.08 0.04\"/></geometry>\n      <material name=\"orange\"/>\n"
    << "    </visual>\n  </link>\n"
    << "  <joint name=\"tool_joint\" type=\"fixed\">\n    <parent link=\"link5\"/>\n    <child link=\"tool\"/>\n"
    << "    <origin xyz=\"0 0 0.06\" rpy=\"0 0 0\"/>\n  </joint>\n</robot>\n";
  robot.urdf_path = (fs::path(dir) / "robot.urdf").string();
  std::ofstream f(robot.urdf_path);
  f << u.str();
  if (!f) throw std::runtime_error(robot.urdf_path + ": cannot write");
  return robot;
}

std::map<std::string, double> random_configuration(const GeneratedRobot& robot, std::mt19937_64& rng) {
  std::map<std::string, double> q;
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (const std::string& j : robot.joints) {
    const auto [lo, hi] = robot.limits.at(j);
    q[j] = 0.5 * (lo + hi) + 0.6 * 0.5 * (hi - lo) * U(rng);
  }
  // Shoulder and elbow bent forward by at most ~70 degrees: the arm stays up, its links apart.
  q.at("joint2") = 0.6 * U(rng);
  q.at("joint3") = 0.4 + 0.6 * U(rng);
  return q;
}

SyntheticScene synthesize_robot_scene(Renderer& renderer, const Camera& camera, const Mesh& posed_arm,
                                      const Pose& camera_from_base, const RobotSceneOptions& options, uint32_t seed) {
  static const Mesh table = make_box(Eigen::Vector3d(1.4, 1.2, 0.04), make_label_texture(256, 21));
  static const Mesh box = make_box(Eigen::Vector3d(0.12, 0.10, 0.16), make_label_texture(64, 22));
  static const Mesh can = make_cylinder(0.04, 0.12, 32, make_label_texture(64, 23));
  static const Mesh occluder = make_box(Eigen::Vector3d(0.06, 0.06, 0.06), make_label_texture(64, 5));
  const auto at = [&](double x, double y, double z) {
    return camera_from_base * Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, y, z));
  };
  std::vector<SceneObject> objects{{&posed_arm, camera_from_base}};
  if (options.table) {
    objects.push_back({&table, at(0.25, -0.1, -0.02)});
    objects.push_back({&box, at(0.12, -0.30, 0.08)});
    objects.push_back({&can, at(-0.05, 0.30, 0.06)});
  }
  if (options.occluder)  // over part of the upper arm, a fifth of the way from it to the camera
    objects.push_back({&occluder, Pose(Eigen::Matrix3d::Identity(), 0.8 * (camera_from_base * generated_view().centre) +
                                                                     Eigen::Vector3d(0.04, 0, 0))});
  return synthesize_scene(renderer, camera, objects, options.noise, seed);
}

std::map<std::string, double> hand_reference_configuration() {
  return {{"joint1", 0.0}, {"joint2", 0.3}, {"joint3", 1.35}, {"joint4", 0.0}, {"joint5", 0.0}};
}

Pose generated_hand_camera(const Pose& base_from_hand) {
  const Eigen::Vector3d eye = base_from_hand.t + Eigen::Vector3d(0, 0, -0.08);
  return look_at(eye, Eigen::Vector3d(0, 0, 0.15)) * base_from_hand;
}

std::map<std::string, double> random_hand_configuration(const GeneratedRobot& robot, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::map<std::string, double> q = hand_reference_configuration();
  for (auto& [joint, value] : q) {
    const auto [lo, hi] = robot.limits.at(joint);
    value = std::clamp(value + (joint == "joint1" ? 0.5 : 0.25) * U(rng), lo, hi);
  }
  return q;
}

GeneratedView generated_view() {
  const Eigen::Vector3d centre(0, 0, 0.35);
  return {Camera(600, 600, 319.5, 239.5, 640, 480), look_at(Eigen::Vector3d(1.2, -0.5, 0.7), centre), centre};
}

Pose look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());  // right: down is the base's -z
  if (x.norm() < 1e-6) x = Eigen::Vector3d::UnitX();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d base_from_camera;
  base_from_camera << x, y, z;
  return Pose(base_from_camera, eye).inverse();
}

}  // namespace diffdope
