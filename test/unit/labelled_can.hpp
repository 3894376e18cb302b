#pragma once
// A test scene several suites share: a labelled can seen from the side, whose turn about its axis only the label
// shows (our own render of it, with noise).
#include <Eigen/Geometry>

#include "diffdope/device.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/synthetic.hpp"

namespace diffdope::test {

struct LabelledCan {
  Camera cam{420, 420, 159.5, 119.5, 320, 240};
  Mesh can = make_cylinder(0.035, 0.11, 64, make_label_texture(256, 7));
  Pose truth;
  Observation obs;
};

inline LabelledCan labelled_can(const SyntheticNoise& noise = SyntheticNoise()) {
  LabelledCan s;
  Vector6d d;
  d << 0, 0, 0, 1.3, 0.2, 0.1;
  s.truth = Pose(se3_exp(d).R, Eigen::Vector3d(0.0, 0.0, 0.45));
  s.obs = synthesize_observation(*make_cpu_renderer(), s.cam, s.can, s.truth, noise, 3);
  return s;
}

/// The model-frame turn by `degrees` about the can's axis.
inline Pose about_can_axis(double degrees) {
  return Pose(Eigen::AngleAxisd(degrees * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
              Eigen::Vector3d::Zero());
}

}  // namespace diffdope::test
