#pragma once
// diffdope_calibrate --generate: a generated arm and captures of it, to try the tool and to measure it
// (scripts/calibration_figures).
#include <cstdint>
#include <string>

namespace diffdope::tools {

struct GenerateOptions {
  std::string dir;
  int count = 3;                       // captures
  uint64_t seed = 1;
  double init_cm = 5, init_deg = 10;   // the guess: the truth moved about the arm's centre
  bool masks = true, rgb = true;
  bool table = true;                   // the arm on a table, a box and a can beside its base
  bool eye_in_hand = false;            // the camera on the hand's bracket instead of on a stand
  /// The depth camera: noise (metres at 1 m, growing with z^2), the share of pixels in dropout holes, and the
  /// share of the silhouettes' border pixels that read a mixed depth (SyntheticNoise).
  double depth_sigma_at_1m = 0.002, depth_noise_grain_px = 0, hole_fraction = 0.05, flying_pixel_fraction = 0;
};

/// Writes DIR/robot/ (URDF and meshes), DIR/captures/NN/ (depth.png, joints.json, rgb.png, mask.png),
/// camera.json, init.json and truth.json (the camera's pose in the base frame, or in the hand's link eye in
/// hand). Returns the exit code.
int generate_calibration_set(const GenerateOptions& o);

}  // namespace diffdope::tools
