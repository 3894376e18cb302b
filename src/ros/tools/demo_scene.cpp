// The demo bag's scene (demo_scene.hpp).
#include "ros/tools/demo_scene.hpp"

#include <algorithm>
#include <cmath>

#include "diffdope/primitives.hpp"

using namespace diffdope;

namespace diffdope_demo {

Mesh make_striped_can() {
  Texture t;
  t.width = 4;
  t.height = 256;
  t.rgb.resize(size_t(3 * t.width * t.height));
  for (int y = 0; y < t.height; ++y)
    for (int x = 0; x < t.width; ++x) {
      // Rows of the lower half are the side (v in [0.02, 0.48]); the upper half the caps (make_cylinder).
      const bool side = y >= t.height / 2;
      const int band = (y / 12) % 4;
      const float c[4][3] = {{0.85f, 0.2f, 0.15f}, {0.95f, 0.9f, 0.8f}, {0.15f, 0.3f, 0.7f}, {0.95f, 0.8f, 0.2f}};
      for (int ch = 0; ch < 3; ++ch)
        t.rgb[size_t(3 * (y * t.width + x) + ch)] = side ? c[band][ch] : 0.75f;
    }
  return make_cylinder(0.035, 0.12, 96, std::move(t));
}

Pose Motion::at(double tau, const Eigen::Vector3d& model_centre) const {
  const Eigen::Matrix3d R = so3_exp(axis * (turn_rate * tau)) * R0;
  const Eigen::Vector3d c = centre0 + direction * (drift_amplitude * std::sin(drift_speed / drift_amplitude * tau));
  return Pose(R, c - R * model_centre);
}

Eigen::Vector3d random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v;
  do v = Eigen::Vector3d(n(rng), n(rng), n(rng));
  while (v.norm() < 1e-6);
  return v.normalized();
}

Eigen::Matrix3d random_rotation(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q;
  do q = Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng));
  while (q.norm() < 1e-6);
  return q.normalized().toRotationMatrix();
}

FrameCheck check_frame(Renderer& renderer, const Camera& cam, const std::vector<SceneObject>& objs, double margin) {
  FrameCheck fc;
  std::vector<RenderImage> imgs;
  for (const SceneObject& o : objs) {
    const Eigen::AlignedBox2d b = cam.project_bounds(o.mesh->bbox_corners(o.pose), 0.05);
    if (b.isEmpty() || b.min().x() < margin - 0.5 || b.min().y() < margin - 0.5 ||
        b.max().x() > cam.width - 0.5 - margin || b.max().y() > cam.height - 0.5 - margin)
      fc.inside = false;
    imgs.push_back(renderer.render(cam, *o.mesh, {o.pose})[0]);
  }
  for (size_t i = 0; i < objs.size(); ++i) {
    int full = 0, visible = 0;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        if (imgs[i].coverage.at<float>(y, x) < 0.5f) continue;
        ++full;
        const float d = imgs[i].depth.at<float>(y, x);
        bool front = true;
        for (size_t j = 0; j < objs.size() && front; ++j) {
          if (j == i || imgs[j].coverage.at<float>(y, x) < 0.5f) continue;
          const float dj = imgs[j].depth.at<float>(y, x);
          if (dj > 0.f && dj < d) front = false;
        }
        visible += front;
      }
    fc.min_visible = std::min(fc.min_visible, full > 0 ? double(visible) / full : 0.0);
  }
  return fc;
}

}  // namespace diffdope_demo
