#include "diffdope/shape_rotations.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "diffdope/mesh.hpp"

namespace diffdope {

Pose ShapeRotation::as_pose() const {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  return Pose(R, pivot - R * pivot);
}

namespace {

/// `n` points uniformly distributed over the surface (area-weighted triangles, uniform inside), seeded.
std::vector<Eigen::Vector3f> sample_surface(const Mesh& mesh, int n, uint64_t seed) {
  const int nt = mesh.num_triangles();
  std::vector<double> cumulative(static_cast<size_t>(nt));
  double total = 0;
  auto corner = [&](int t, int k) {
    const Vec3f& p = mesh.positions[size_t(mesh.triangles[3 * size_t(t) + k])];
    return Eigen::Vector3f(p.x, p.y, p.z);
  };
  for (int t = 0; t < nt; ++t) {
    total += 0.5 * double((corner(t, 1) - corner(t, 0)).cross(corner(t, 2) - corner(t, 0)).norm());
    cumulative[size_t(t)] = total;
  }
  std::vector<Eigen::Vector3f> out;
  if (!(total > 0)) return out;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  out.reserve(size_t(n));
  for (int i = 0; i < n; ++i) {
    const double a = U(rng) * total;
    const int t = int(std::min<size_t>(size_t(std::lower_bound(cumulative.begin(), cumulative.end(), a) - cumulative.begin()),
                                       size_t(nt - 1)));
    float u = float(U(rng)), v = float(U(rng));
    if (u + v > 1.f) u = 1.f - u, v = 1.f - v;
    out.push_back(corner(t, 0) + u * (corner(t, 1) - corner(t, 0)) + v * (corner(t, 2) - corner(t, 0)));
  }
  return out;
}

/// Mean over `moved` of the distance to the nearest point of `fixed` (brute force on structure-of-arrays, which
/// the compiler vectorises: ~1k x 1k points in about a millisecond).
double mean_nearest(const std::vector<Eigen::Vector3f>& moved, const std::vector<float>& fx,
                    const std::vector<float>& fy, const std::vector<float>& fz) {
  double sum = 0;
  const size_t n = fx.size();
  for (const Eigen::Vector3f& p : moved) {
    float best = std::numeric_limits<float>::infinity();
    for (size_t j = 0; j < n; ++j) {
      const float dx = fx[j] - p.x(), dy = fy[j] - p.y(), dz = fz[j] - p.z();
      best = std::min(best, dx * dx + dy * dy + dz * dz);
    }
    sum += std::sqrt(double(best));
  }
  return moved.empty() ? 0.0 : sum / double(moved.size());
}

}  // namespace

std::vector<ShapeRotation> analyse_shape_rotations(const Mesh& mesh) {
  constexpr int kSamples = 1024;
  // Two independent samples: the distance between them at no rotation is the sampling's own floor.
  const std::vector<Eigen::Vector3f> a = sample_surface(mesh, kSamples, 1), b = sample_surface(mesh, kSamples, 2);
  if (a.empty() || !(mesh.diameter() > 0)) return {};
  // The surface's exact first and second moments (a sample's would tilt the axes of a short cylinder by degrees).
  double area = 0;
  Eigen::Vector3d first = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
  for (int t = 0; t < mesh.num_triangles(); ++t) {
    Eigen::Vector3d v[3];
    for (int k = 0; k < 3; ++k) {
      const Vec3f& p = mesh.positions[size_t(mesh.triangles[3 * size_t(t) + k])];
      v[k] = Eigen::Vector3d(p.x, p.y, p.z);
    }
    const double A = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).norm();
    const Eigen::Vector3d s = v[0] + v[1] + v[2];
    area += A;
    first += A / 3.0 * s;
    // The integral of x x^T over a triangle: A / 12 (sum of v v^T + s s^T).
    second += A / 12.0 * (v[0] * v[0].transpose() + v[1] * v[1].transpose() + v[2] * v[2].transpose() + s * s.transpose());
  }
  const Eigen::Vector3d mean = first / area;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(second / area - mean * mean.transpose());
  std::vector<float> bx, by, bz;
  for (const auto& p : b) bx.push_back(p.x()), by.push_back(p.y()), bz.push_back(p.z());
  const double floor = mean_nearest(a, bx, by, bz);

  std::vector<ShapeRotation> out;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d axis = eig.eigenvectors().col(j).normalized();
    for (int k = 1; k < kShapeAngleSteps; ++k) {
      ShapeRotation r;
      r.axis = axis;
      r.pivot = mean;  // the surface's centroid: on every axis of symmetry
      r.angle = 2.0 * M_PI * k / kShapeAngleSteps;
      const Pose T = r.as_pose();
      std::vector<Eigen::Vector3f> moved;
      moved.reserve(a.size());
      for (const auto& p : a) moved.push_back((T * p.cast<double>()).cast<float>());
      r.discrepancy = std::max(0.0, mean_nearest(moved, bx, by, bz) - floor) / mesh.diameter();
      out.push_back(r);
    }
  }
  return out;
}

std::vector<ShapeRotation> ambiguous_rotations(const std::vector<ShapeRotation>& candidates, double tolerance,
                                               int max_count) {
  std::vector<ShapeRotation> revolution, discrete;
  if (!(tolerance > 0) || max_count <= 0) return {};
  constexpr int per_axis = kShapeAngleSteps - 1;
  for (size_t first = 0; first + per_axis <= candidates.size(); first += per_axis) {
    const ShapeRotation* c = candidates.data() + first;
    bool all = true;
    for (int k = 0; k < per_axis; ++k) all = all && c[k].discrepancy <= tolerance;
    if (all) {  // a shape of revolution about this axis: spread the starts over the turn
      const int n = std::min(kShapeAngleSteps, max_count + 1);
      for (int k = 1; k < n; ++k) {
        ShapeRotation r = c[0];
        r.angle = 2.0 * M_PI * k / n;
        r.discrepancy = 0;  // (between sampled angles: as good as its neighbours)
        revolution.push_back(r);
      }
      continue;
    }
    for (int k = 0; k < per_axis; ++k) {
      const double d = c[k].discrepancy;
      const double before = k > 0 ? c[k - 1].discrepancy : std::numeric_limits<double>::infinity();
      const double after = k + 1 < per_axis ? c[k + 1].discrepancy : std::numeric_limits<double>::infinity();
      if (d <= tolerance && d <= before && d <= after) discrete.push_back(c[k]);
    }
  }
  std::stable_sort(discrete.begin(), discrete.end(),
                   [](const ShapeRotation& x, const ShapeRotation& y) { return x.discrepancy < y.discrepancy; });
  // Starts about an axis of revolution first (the roll that only texture decides), then the discrete ones.
  std::vector<ShapeRotation> out = revolution;
  out.insert(out.end(), discrete.begin(), discrete.end());
  if (int(out.size()) > max_count) out.resize(size_t(max_count));
  return out;
}

}  // namespace diffdope
