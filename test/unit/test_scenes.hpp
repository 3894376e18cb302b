#pragma once
// Shared fixtures for the core tests: a camera, procedural objects, observations rendered by our renderer,
// and central finite differences of the loss.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope::test {

/// Options under which a refinement leaves its start as it was until the Newton steps (one iteration at a
/// negligible rate; no coarse phase, polish or retry): what the steps and the print alignment do on their own.
inline RefinerOptions steps_only_options() {
  RefinerOptions o;
  o.iterations = 1;
  o.lr_low = o.lr_high = 1e-9;
  o.coarse_fraction = 0;
  o.retry_turn = 0;
  o.polish_iterations = 0;
  return o;
}

/// A refinement's evaluations, stage by stage: each within what planned_evaluations() plans for its stage (one
/// start), and together the result's count.
inline void expect_within_plan(const RefineResult& r, const RefinerOptions& o, const std::string& what) {
  long sum = 0;
  for (int stage = 0; stage < kRefineStages; ++stage) {
    EXPECT_LE(r.stage_evaluations[size_t(stage)], planned_evaluations(o, RefineStage(stage)))
        << what << ": stage " << stage;
    sum += r.stage_evaluations[size_t(stage)];
  }
  EXPECT_EQ(sum, r.evaluations) << what;
}

inline Camera test_camera() { return Camera(300.0, 300.0, 159.5, 119.5, 320, 240); }

inline Pose look_pose(double rx, double ry, double rz, double x, double y, double z) {
  Vector6d d;
  d << 0, 0, 0, rx, ry, rz;
  return Pose(se3_exp(d).R, Eigen::Vector3d(x, y, z));
}

/// Observation = what the renderer draws at `pose`: colour over black, depth, binary mask (coverage >= 0.5).
inline Observation observe(Renderer& r, const Camera& cam, const Mesh& mesh, const Pose& pose) {
  const RenderImage img = r.render(cam, mesh, {pose})[0];
  Observation o;
  o.rgb = img.color.clone();
  o.depth = img.depth.clone();
  o.mask = cv::Mat(img.coverage >= 0.5f) / 255;
  o.mask.convertTo(o.mask, CV_32F);
  return o;
}

/// Central finite differences of the loss along each of the 6 update directions, averaged over steps of
/// h * {0.5, 1, 2, 4}: single differences are noisy because pixel-level events (a pixel centre crossing an
/// edge, a blend switching direction) add small jumps; averaging over several scales estimates the slope.
inline Vector6d finite_difference(Renderer& r, const Camera& cam, const Mesh& mesh, const Observation& obs,
                                  const Pose& pose, const LossOptions& loss, double h_trans, double h_rot) {
  const double scales[4] = {0.5, 1.0, 2.0, 4.0};
  std::vector<Pose> poses;
  for (double sc : scales)
    for (int k = 0; k < 6; ++k)
      for (double sgn : {1.0, -1.0}) {
        Vector6d d = Vector6d::Zero();
        d[k] = sgn * sc * (k < 3 ? h_trans : h_rot);
        poses.push_back(pose.updated(d));
      }
  std::vector<LossValue> v;
  r.evaluate(cam, mesh, obs, poses, loss, false, v);
  Vector6d g = Vector6d::Zero();
  for (int s = 0; s < 4; ++s)
    for (int k = 0; k < 6; ++k) {
      const int i = 12 * s + 2 * k;
      g[k] += (v[i].total - v[i + 1].total) / (2 * scales[s] * (k < 3 ? h_trans : h_rot)) / 4.0;
    }
  return g;
}

}  // namespace diffdope::test
