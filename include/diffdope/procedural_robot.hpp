#pragma once
// A generated robot arm for the calibration's tests and demo: a base and five links with their own mesh files
// (boxes and cylinders, PLY), five revolute joints and a tool on a fixed joint drawn as a URDF box primitive.
// About 0.75 m tall when stretched; its hand is asymmetric, so every configuration fixes the base's pose.
#include <map>
#include <random>
#include <string>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

struct GeneratedRobot {
  std::string urdf_path;               // DIR/robot.urdf (meshes in DIR/meshes/, referenced relatively)
  std::vector<std::string> joints;     // joint1 .. joint5
  std::map<std::string, std::pair<double, double>> limits;  // radians, per joint
};

/// Writes the URDF and its meshes into `dir` (created). Throws std::runtime_error when a file cannot be written.
GeneratedRobot write_generated_robot(const std::string& dir);

/// A random configuration well inside the limits, the arm raised so that its links spread out in view.
std::map<std::string, double> random_configuration(const GeneratedRobot& robot, std::mt19937_64& rng);

/// The view of the generated arm shared by the tests, diffdope_calibrate --generate and the calibration bag:
/// 640x480, f = 600 px, the camera about 1.4 m from the arm's centre, in front of it and to its side.
struct GeneratedView {
  Camera camera;
  Pose camera_from_base;
  Eigen::Vector3d centre;  // the arm's centre (base frame): where guesses are perturbed about
};
GeneratedView generated_view();

/// A camera pose looking at `target` (base frame) from `eye`: camera <- base, OpenCV optical frame (z towards
/// the target, y down along the base's -z as far as possible).
Pose look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target);

}  // namespace diffdope
