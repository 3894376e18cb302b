// icp_refine() (icp_baseline.hpp).
#include "icp_baseline.hpp"

#include <Eigen/Cholesky>
#include <chrono>
#include <cmath>

#include "diffdope/object_pixels.hpp"

namespace diffdope {
namespace {

/// Unit normal of the observed surface at (x, y), from the points `step` pixels around it, facing the camera;
/// zero where a neighbour has no reading.
Eigen::Vector3d observed_normal(const Camera& cam, const cv::Mat& depth, int x, int y, int step) {
  if (x < step || y < step || x + step >= depth.cols || y + step >= depth.rows) return Eigen::Vector3d::Zero();
  const auto at = [&](int u, int v) { return cam.back_project(u, v, depth.at<float>(v, u)); };
  const float l = depth.at<float>(y, x - step), r = depth.at<float>(y, x + step);
  const float u = depth.at<float>(y - step, x), d = depth.at<float>(y + step, x);
  if (!(l > 0 && r > 0 && u > 0 && d > 0)) return Eigen::Vector3d::Zero();
  Eigen::Vector3d n = (at(x + step, y) - at(x - step, y)).cross(at(x, y + step) - at(x, y - step));
  if (n.norm() < 1e-12) return Eigen::Vector3d::Zero();
  n.normalize();
  return n.dot(at(x, y)) > 0 ? Eigen::Vector3d(-n) : n;
}

}  // namespace

IcpResult icp_refine(Renderer& renderer, const Camera& camera, const Observation& observed, const Mesh& mesh,
                     const Pose& start, const IcpOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  IcpResult out;
  out.pose = start;
  const auto done = [&] {
    out.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return out;
  };
  if (!observed.has_depth()) return out.error = "no depth image", done();
  const Camera cam = camera.scaled(options.image_scale);
  const Observation obs = observed.resized(cam);
  cv::Mat selected;
  if (obs.has_mask()) {
    selected = obs.mask >= 0.5f;
  } else {
    ObjectPixelsOptions po;  // as the refiner's first derivation about its start
    po.margin = std::min(0.3 * mesh.diameter(), 1.0);
    po.surface_search = std::min(0.5 * mesh.diameter(), 1.0);
    po.touching_render = true;
    if (obs.has_box()) po.bounds = obs.box;
    selected = derive_object_pixels(cam, obs.depth, renderer.render(cam, mesh, {start}), po) >= 0.5f;
  }
  selected &= obs.depth > 0;
  if (cv::countNonZero(selected) < 6) return out.error = "no observed depth near the start", done();
  cv::Mat normals(cam.height, cam.width, CV_32FC3, cv::Scalar::all(0));
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x)
      if (selected.at<uchar>(y, x)) {
        const Eigen::Vector3d n = observed_normal(cam, obs.depth, x, y, 2);
        normals.at<cv::Vec3f>(y, x) = cv::Vec3f(float(n.x()), float(n.y()), float(n.z()));
      }
  using Vector6d = Eigen::Matrix<double, 6, 1>;
  for (; out.iterations < options.iterations; ++out.iterations) {
    const RenderImage img = renderer.render(cam, mesh, {out.pose})[0];
    Eigen::Matrix<double, 6, 6> JtJ = Eigen::Matrix<double, 6, 6>::Zero();
    Vector6d Jtr = Vector6d::Zero();
    int pairs = 0;
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const float zr = img.depth.at<float>(y, x), zo = obs.depth.at<float>(y, x);
        if (!selected.at<uchar>(y, x) || img.coverage.at<float>(y, x) < 0.5f || !(zr > 0)) continue;
        const cv::Vec3f nv = normals.at<cv::Vec3f>(y, x);
        const Eigen::Vector3d n(nv[0], nv[1], nv[2]);
        if (n.isZero()) continue;
        const Eigen::Vector3d p = cam.back_project(x, y, zr), q = cam.back_project(x, y, zo);
        const double r = n.dot(p - q);
        if (std::abs(r) > options.max_distance || std::abs(zr - zo) > options.max_distance) continue;
        Vector6d J;
        J << p.cross(n), n;  // d r / d (rotation about the camera origin, translation)
        JtJ += J * J.transpose();
        Jtr += J * r;
        ++pairs;
      }
    out.pairs = pairs;
    if (pairs < 6) break;
    const Vector6d step = -JtJ.ldlt().solve(Jtr);
    if (!step.allFinite()) break;
    const Eigen::Matrix3d dR = so3_exp(step.head<3>());
    out.pose = Pose(dR * out.pose.R, dR * out.pose.t + step.tail<3>());
    if (step.head<3>().norm() < 1e-6 && step.tail<3>().norm() < 1e-7) {
      ++out.iterations;
      break;
    }
  }
  return done();
}

}  // namespace diffdope
