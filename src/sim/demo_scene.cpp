// The demo's scene (demo_scene.hpp).
#include "diffdope/demo_scene.hpp"

#include <algorithm>
#include <cmath>

#include <stdexcept>

#include "diffdope/primitives.hpp"
#include "diffdope/procedural.hpp"

namespace diffdope::demo {

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

std::vector<DemoObject> demo_objects(const std::string& which) {
  const auto bottle = [] { return make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.065, 0.04, 0.17), 15000, 2048, 11); };
  const auto box = [] { return make_box(Eigen::Vector3d(0.10, 0.05, 0.14), make_label_texture(512, 11)); };
  std::vector<DemoObject> objects;
  if (which == "can") {
    ObjectSymmetry about_axis;
    about_axis.continuous.push_back({Eigen::Vector3d::UnitZ(), Eigen::Vector3d::Zero()});
    objects.push_back({"can", make_striped_can(), true, 1, about_axis});
  } else if (which == "twins") {  // one mesh, two instances, one label
    const Mesh b = box();
    objects.push_back({"box", b, false, 1, {}});
    objects.push_back({"box", b, false, 1, {}});
  } else if (which == "1") {
    objects.push_back({"bottle", bottle(), false, 1, {}});
  } else if (which == "2" || which == "3") {
    objects.push_back({"box", box(), false, 1, {}});
    objects.push_back({"bottle", bottle(), false, 2, {}});
    if (which == "3")
      objects.push_back({"mug", make_scan_like(ScanShape::Mug, Eigen::Vector3d(0.11, 0.08, 0.095), 15000, 2048, 13),
                         false, 3, {}});
  } else {
    throw std::invalid_argument("demo objects: expected 1, 2, 3, can or twins, got '" + which + "'");
  }
  return objects;
}

Camera demo_camera(int width, int height) {
  const double f = 1.25 * width;
  return Camera(f, f, width / 2.0 - 0.5, height / 2.0 - 0.5, width, height);
}

DemoLayout choose_layout(const std::vector<DemoObject>& objects, const Camera& camera, int frames, double rate,
                         uint64_t seed) {
  const size_t n = objects.size();
  const bool twins = n == 2 && objects[0].name == objects[1].name;
  const Camera check_cam = camera.scaled(std::min(1.0, 160.0 / camera.width));
  auto renderer = make_cpu_renderer();
  std::mt19937_64 layout_rng(seed * 0x9E3779B97F4A7C15ull + 1);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const double spacing = twins ? 0.2 : n == 3 ? 0.12 : 0.14;
  const int check_frames = std::min(frames, 200);
  DemoLayout best;
  double best_score = -1;
  for (int attempt = 0; attempt < 200 && best_score < 0.75; ++attempt) {
    std::vector<Motion> motions;
    for (size_t i = 0; i < n; ++i) {
      Motion m;
      m.R0 = random_rotation(layout_rng);
      const double x = (double(i) - 0.5 * double(n - 1)) * spacing + 0.01 * U(layout_rng);
      m.centre0 = Eigen::Vector3d(x, 0.02 * U(layout_rng), 0.60 + 0.05 * U(layout_rng));
      m.axis = random_unit(layout_rng);
      m.turn_rate = (15.0 + 3.0 * U(layout_rng)) * M_PI / 180.0;
      m.direction = random_unit(layout_rng);
      motions.push_back(m);
    }
    double score = 2.0;  // the worst frame: min visible fraction, minus 1 when something leaves the image
    for (int s = 0; s < check_frames && score > best_score; ++s) {
      const int k = check_frames == frames ? s : int(std::lround(double(s) * (frames - 1) / (check_frames - 1)));
      std::vector<SceneObject> objs;
      for (size_t i = 0; i < n; ++i) objs.push_back({&objects[i].mesh, motions[i].at(k / rate, objects[i].mesh.center())});
      const FrameCheck fc = check_frame(*renderer, check_cam, objs, 2.0);
      score = std::min(score, fc.min_visible - (fc.inside ? 0.0 : 1.0));
    }
    if (score > best_score) {
      best_score = score;
      best.motions = motions;
      best.inside = score >= 0;
      best.min_visible = score >= 0 ? score : score + 1;
    }
  }
  return best;
}

}  // namespace diffdope::demo
