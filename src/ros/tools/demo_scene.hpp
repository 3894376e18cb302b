#pragma once
// The demo bag's scene (make_demo_bag.cpp): the objects, their slow motion, and the checks that keep every frame
// usable (each object mostly visible, inside the image).
#include <random>
#include <string>
#include <vector>

#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/symmetry.hpp"
#include "diffdope/synthetic.hpp"

namespace diffdope_demo {

struct DemoObject {
  std::string name;
  diffdope::Mesh mesh;
  bool symmetric;
  int label;
  diffdope::ObjectSymmetry declared;  // written to objects.yaml; the detector reports a random turn about it
};

/// A can whose print repeats all around (stripes along its height, plain caps): symmetric about its axis, as
/// the objects config then declares.
diffdope::Mesh make_striped_can();

/// A slow smooth motion: a fixed-rate turn about `axis` through the mesh centre, and a back-and-forth drift of
/// the centre along `direction` (speed `drift_speed` at its middle).
struct Motion {
  Eigen::Matrix3d R0;
  Eigen::Vector3d centre0;  // camera frame, metres
  Eigen::Vector3d axis;     // camera frame, unit
  double turn_rate = 0;     // rad/s
  Eigen::Vector3d direction;
  double drift_amplitude = 0.03;  // metres
  double drift_speed = 0.02;      // metres / s

  diffdope::Pose at(double tau, const Eigen::Vector3d& model_centre) const;
};

Eigen::Vector3d random_unit(std::mt19937_64& rng);
Eigen::Matrix3d random_rotation(std::mt19937_64& rng);

/// Per object, the fraction of its silhouette that is in front of the others (as synthesize_scene decides), and
/// whether its projected bounding box stays inside the image by `margin` pixels.
struct FrameCheck {
  double min_visible = 1.0;
  bool inside = true;
};
FrameCheck check_frame(diffdope::Renderer& renderer, const diffdope::Camera& cam,
                       const std::vector<diffdope::SceneObject>& objs, double margin);

}  // namespace diffdope_demo
