#pragma once
// Synthetic observations for tests, the demo and the dataset generator: an object rendered over a textured
// background plane, with sensor-like noise (colour noise, depth noise growing with z^2, depth holes, flying
// pixels).
#include <cstdint>
#include <random>

#include "diffdope/observation.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

struct SyntheticNoise {
  double rgb_sigma = 0.02;         // colour noise, [0, 1] units
  double depth_sigma_at_1m = 0.002;  // depth noise (metres) at 1 m, grows with z^2
  /// The depth noise's grain: 0 = independent per pixel; g > 0 = smoothed over g pixels (a Gaussian's sigma) and
  /// rescaled to keep depth_sigma_at_1m per pixel, as a stereo camera's matching window correlates its errors
  /// (averaging a few pixels then leaves most of the noise, as on a real camera).
  double depth_noise_grain_px = 0;
  double hole_fraction = 0.05;     // fraction of depth pixels without a reading (blobs)
  /// Fraction of the objects' silhouette-border pixels that read a depth between the surface in front and the
  /// one behind (a stereo or time-of-flight sensor's mixed pixels), uniformly; the others read none.
  double flying_pixel_fraction = 0;
  double background_depth = 0.9;   // metres: a plane behind the object
  double brightness = 1.0;         // multiplies the object's colours (lighting mismatch)
  /// The colour image's offset from the depth image and the masks, pixels (+x right, +y down): a colour camera
  /// registered to depth with an error, as real RGB-D cameras are by a few pixels. The colour moves; depth and
  /// masks stay. [-kMaxColourOffset, kMaxColourOffset]
  double colour_offset_x_px = 0, colour_offset_y_px = 0;
  static constexpr double kMaxColourOffset = 64;
};

struct SceneObject {
  const Mesh* mesh;
  Pose pose;
};

/// A composed scene: one image of several objects occluding each other over a textured background.
struct SyntheticScene {
  cv::Mat rgb;                         // CV_32FC3 in [0, 1]
  cv::Mat depth;                       // CV_32FC1 metres, 0 = hole
  std::vector<cv::Mat> visible_masks;  // per object, CV_32FC1 0/1: the pixels where it is the front surface
  std::vector<cv::Mat> full_masks;     // per object, its whole silhouette
  std::vector<double> visible_fraction;
};

/// Renders the objects, composites them front to back (antialiased edges) over a textured background plane and
/// adds noise.
SyntheticScene synthesize_scene(Renderer& renderer, const Camera& camera, const std::vector<SceneObject>& objects,
                                const SyntheticNoise& noise, uint32_t seed);

/// One object alone (synthesize_scene with one object); the mask is its rendered coverage >= 0.5 (0/1).
Observation synthesize_observation(Renderer& renderer, const Camera& camera, const Mesh& mesh, const Pose& pose,
                                   const SyntheticNoise& noise, uint32_t seed);

/// The paper's perturbation rule: rotate by exactly `angle` (radians) about a uniformly random axis through the
/// object's centre (`centre` in model coordinates), and translate by exactly `distance` (metres) in a uniformly
/// random direction.
Pose perturb_pose(const Pose& pose, const Eigen::Vector3d& centre, double angle, double distance, std::mt19937_64& rng);

}  // namespace diffdope
