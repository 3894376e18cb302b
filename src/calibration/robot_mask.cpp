// The robot's pixels in a capture without a mask (Calibrator::derive_mask): depth near the robot rendered at the
// current estimate, less the surfaces the robot stands on or beside (a table, a box, a wall), found as planes in
// the depth outside the robot's reach and followed into it.
#include <opencv2/imgproc.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "diffdope/calibration.hpp"

namespace diffdope {
namespace {

struct Plane {
  Eigen::Vector3d normal;  // unit
  double offset = 0;       // normal . p + offset = 0
  double distance(const Eigen::Vector3d& p) const { return std::abs(normal.dot(p) + offset); }
};

/// Least-squares plane through `points` (the eigenvector of the smallest scatter).
Plane fit_plane(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= double(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& p : points) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  Plane plane;
  plane.normal = eig.eigenvectors().col(0).normalized();
  plane.offset = -plane.normal.dot(mean);
  return plane;
}

/// RANSAC: the plane through three of `points` that the most of them lie within `tolerance` of (hypotheses scored
/// on at most 8000 of them), refit to its inliers. Deterministic (fixed seed): the same capture gives the same
/// mask.
Plane dominant_plane(const std::vector<Eigen::Vector3d>& points, double tolerance, std::mt19937& rng) {
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  std::vector<size_t> sample;
  const size_t n_sample = std::min<size_t>(points.size(), 8000);
  for (size_t k = 0; k < n_sample; ++k) sample.push_back(pick(rng));
  Plane best;
  size_t best_count = 0;
  for (int h = 0; h < 200; ++h) {
    const Eigen::Vector3d &a = points[pick(rng)], &b = points[pick(rng)], &c = points[pick(rng)];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    Plane p{n.normalized(), 0};
    p.offset = -p.normal.dot(a);
    size_t count = 0;
    for (size_t k : sample) count += p.distance(points[k]) <= tolerance;
    if (count > best_count) best_count = count, best = p;
  }
  if (best_count == 0) return best;
  for (int refit = 0; refit < 2; ++refit) {
    std::vector<Eigen::Vector3d> inliers;
    for (const auto& q : points)
      if (best.distance(q) <= tolerance) inliers.push_back(q);
    if (inliers.size() < 3) break;
    best = fit_plane(inliers);
  }
  return best;
}

Eigen::Vector3d back_project(const Camera& camera, int x, int y, double z) {
  return {(x - camera.cx) * z / camera.fx, (y - camera.cy) * z / camera.fy, z};
}

}  // namespace

cv::Mat Calibrator::derive_mask(const Mesh& posed_robot, const Camera& camera, const Observation& observed,
                                const Pose& camera_from_mount, double margin) {
  observed.validate(camera);
  if (!observed.has_depth()) throw std::invalid_argument("derive_mask: no depth image");
  if (!(margin > 0)) throw std::invalid_argument("derive_mask: the margin must be positive");
  // The robot at the estimate, full frame: what it covers and at what depth. A pixel the rasterizer covers
  // without a depth (a sliver at a silhouette) says nothing of the robot's depth range.
  const RenderImage img = renderer_->render(camera, posed_robot, {camera_from_mount})[0];
  const cv::Mat covered = (img.coverage >= 0.5f) & (img.depth > 0.0f);
  if (cv::countNonZero(covered) == 0) return cv::Mat::zeros(camera.height, camera.width, CV_32F);
  double z_near = 0;
  {
    cv::Mat d = img.depth.clone();
    d.setTo(std::numeric_limits<float>::infinity(), ~covered);
    cv::minMaxLoc(d, &z_near);
  }
  const int radius =
      std::clamp(int(std::ceil(margin * std::max(camera.fx, camera.fy) / std::max(z_near, 0.05))), 1, 200);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1));
  cv::Mat nearest = img.depth.clone(), farthest = img.depth.clone();
  nearest.setTo(std::numeric_limits<float>::infinity(), ~covered);
  farthest.setTo(0.0f, ~covered);
  cv::erode(nearest, nearest, kernel);     // smallest robot depth around each pixel
  cv::dilate(farthest, farthest, kernel);  // largest
  const cv::Mat& d = observed.depth;
  const cv::Mat within_reach = farthest > 0;  // where the robot may be, the estimate's error up to the margin
  cv::Mat mask = (d > 0) & (d >= nearest - margin) & (d <= farthest + margin) & within_reach;

  // Surfaces beside the robot: planes of the depth where the robot cannot be, each followed into its reach by
  // connectivity (a table runs under the base, a box's side continues past it). Their pixels leave the mask
  // unless the robot at the estimate is there at that depth (the base's foot on the table). A plane must cover
  // 0.5 % of the image; the RANSAC tolerance (2 cm) admits a sensor's noise at a few metres, and what is removed
  // is what lies within 3 sigma of the plane's own spread (at least 5 mm).
  // The observed points (camera frame), once; z = 0 where there is no reading.
  std::vector<Eigen::Vector3d> cloud(size_t(camera.width) * size_t(camera.height), Eigen::Vector3d::Zero());
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const float z = d.at<float>(y, x);
      if (z > 0 && std::isfinite(z))
        cloud[size_t(y) * size_t(camera.width) + size_t(x)] = back_project(camera, x, y, z);
    }
  const auto point = [&](int x, int y) -> const Eigen::Vector3d& {
    return cloud[size_t(y) * size_t(camera.width) + size_t(x)];
  };
  std::vector<Eigen::Vector3d> outside;
  for (int y = 0; y < camera.height; y += 2)
    for (int x = 0; x < camera.width; x += 2)
      if (point(x, y).z() > 0 && !within_reach.at<uchar>(y, x)) outside.push_back(point(x, y));
  const size_t min_points = size_t(0.005 * camera.width * camera.height / 4);
  const double tolerance = 0.02;
  std::mt19937 rng(1);
  for (int k = 0; k < 6 && outside.size() >= std::max<size_t>(min_points, 3); ++k) {
    const Plane plane = dominant_plane(outside, tolerance, rng);
    std::vector<double> residuals;
    std::vector<Eigen::Vector3d> rest;
    for (const auto& p : outside) {
      const double r = plane.distance(p);
      if (r <= tolerance) residuals.push_back(r);
      else rest.push_back(p);
    }
    if (residuals.size() < min_points) break;
    std::nth_element(residuals.begin(), residuals.begin() + long(residuals.size() / 2), residuals.end());
    const double spread = 1.4826 * residuals[residuals.size() / 2];  // |r| has median 0.674 sigma; MAD of r
    const double band = std::clamp(3 * spread, 0.005, tolerance);
    cv::Mat on_plane = cv::Mat::zeros(camera.height, camera.width, CV_8U);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x)
        if (point(x, y).z() > 0 && plane.distance(point(x, y)) <= band) on_plane.at<uchar>(y, x) = 255;
    cv::Mat labels;
    const int n_labels = cv::connectedComponents(on_plane, labels, 8, CV_32S);
    std::vector<char> reaches_outside(size_t(n_labels), 0);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x)
        if (on_plane.at<uchar>(y, x) && !within_reach.at<uchar>(y, x))
          reaches_outside[size_t(labels.at<int>(y, x))] = 1;
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        if (!mask.at<uchar>(y, x) || !on_plane.at<uchar>(y, x) || !reaches_outside[size_t(labels.at<int>(y, x))])
          continue;
        const float rendered = covered.at<uchar>(y, x) ? img.depth.at<float>(y, x) : 0.0f;
        if (!(rendered > 0 && std::abs(d.at<float>(y, x) - rendered) <= band)) mask.at<uchar>(y, x) = 0;
      }
    outside.swap(rest);
  }
  cv::Mat out;
  mask.convertTo(out, CV_32F, 1.0 / 255.0);
  return out;
}

}  // namespace diffdope
