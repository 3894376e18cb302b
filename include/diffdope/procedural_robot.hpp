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
#include "diffdope/synthetic.hpp"

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

/// The eye-in-hand setup of the generated arm: a camera on a bracket on the hand (link5), fixed so that in
/// hand_reference_configuration() (the forearm reaching forward, elbow up) it looks from 8 cm under the hand
/// down under the forearm at the base and the shoulder, about 0.6 m away.
constexpr const char* kGeneratedHandLink = "link5";
std::map<std::string, double> hand_reference_configuration();
/// The camera <- link5 of that bracket, from link5's pose in the base frame at the reference configuration.
Pose generated_hand_camera(const Pose& base_from_hand_at_reference);
/// A configuration near the reference (the shoulder turned by up to 0.5 rad, the other joints by 0.25): the
/// hand's camera keeps the lower arm and the base in view.
std::map<std::string, double> random_hand_configuration(const GeneratedRobot& robot, std::mt19937_64& rng);

/// What a generated capture shows besides the arm.
struct RobotSceneOptions {
  /// A table whose top is the base's bottom (z = 0), 1.4 m x 1.2 m, with a box (12 x 10 x 16 cm) standing beside
  /// the base and a can behind it: what a robot stands among, and what a mask derived from depth must leave out.
  bool table = true;
  bool occluder = false;  // a 6 cm box floating between the camera and the upper arm
  SyntheticNoise noise = [] {
    SyntheticNoise n;
    n.background_depth = 2.5;
    return n;
  }();
};

/// One capture of the generated arm: `posed_arm` (the robot merged in its base frame at the capture's joints) seen
/// from `camera_from_base` among what `options` adds. visible_masks[0] is the arm's visible mask.
SyntheticScene synthesize_robot_scene(Renderer& renderer, const Camera& camera, const Mesh& posed_arm,
                                      const Pose& camera_from_base, const RobotSceneOptions& options, uint32_t seed);

/// A camera pose looking at `target` (base frame) from `eye`: camera <- base, OpenCV optical frame (z towards
/// the target, y down along the base's -z as far as possible).
Pose look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target);

}  // namespace diffdope
