#pragma once
// diffdope_calibrate --generate: a generated arm and captures of it, to try the tool and to measure it
// (scripts/calibration_figures).
#include <cstdint>
#include <string>

#include "diffdope/procedural_robot.hpp"

namespace diffdope::tools {

struct GenerateOptions {
  std::string dir;
  int count = 3;                       // captures
  uint64_t seed = 1;
  double init_cm = 5, init_deg = 10;   // the guess: the truth moved about the arm's centre
  bool masks = true, rgb = true;
  bool table = true;                   // the arm on a table, a box and a can beside its base
  bool eye_in_hand = false;            // the camera on the hand's bracket instead of on a stand
  /// The depth camera (and the colour's noise): the generated arm's defaults, changed by --depth-noise,
  /// --noise-grain, --holes and --flying-pixels.
  SyntheticNoise noise = RobotSceneOptions().noise;
};

/// Writes DIR/robot/ (URDF and meshes), DIR/captures/NN/ (depth.png, joints.json, rgb.png, mask.png),
/// camera.json, init.json and truth.json (the camera's pose in the base frame, or in the hand's link eye in
/// hand). Returns the exit code.
int generate_calibration_set(const GenerateOptions& o);

}  // namespace diffdope::tools
