#pragma once
// The demo's scene (the ROS demo bag, diffdope_make_bag; the tracking benchmark, bench_tracking): the objects,
// the camera, their slow motion, and the layout that keeps every frame usable (each object mostly visible,
// inside the image).
#include <random>
#include <string>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/symmetry.hpp"
#include "diffdope/synthetic.hpp"

namespace diffdope::demo {

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

/// The demo's objects: "1" a scan-like bottle; "2" a low-poly printed box (label 1) and the bottle (2); "3" also
/// a scan-like mug (3); "can" a striped can, declared symmetric about its axis; "twins" two instances of the box
/// (one label). Scan-like: 15k triangles, UV atlas, 2048^2 print. Throws std::invalid_argument on another name.
std::vector<DemoObject> demo_objects(const std::string& which);

/// The demo's camera: a focal length of 1.25 x the width, the principal point at the centre.
diffdope::Camera demo_camera(int width, int height);

/// A layout of the objects' motions (side by side about 0.6 m in front of the camera, each turning ~15 deg/s
/// about its own axis and drifting ~2 cm/s), redrawn (deterministically from `seed`) until over `frames` at
/// `rate` Hz every object stays inside the image and at least 75 % visible, or the best of 200 draws.
struct DemoLayout {
  std::vector<Motion> motions;
  double min_visible = 0;  // the worst frame's least visible object (checked on a 160-pixel-wide camera)
  bool inside = false;     // every object inside the image in every frame
};
DemoLayout choose_layout(const std::vector<DemoObject>& objects, const diffdope::Camera& camera, int frames,
                         double rate, uint64_t seed);

/// Per object, the fraction of its silhouette that is in front of the others (as synthesize_scene decides), and
/// whether its projected bounding box stays inside the image by `margin` pixels.
struct FrameCheck {
  double min_visible = 1.0;
  bool inside = true;
};
FrameCheck check_frame(diffdope::Renderer& renderer, const diffdope::Camera& cam,
                       const std::vector<diffdope::SceneObject>& objs, double margin);

}  // namespace diffdope::demo
