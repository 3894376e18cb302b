#include "diffdope/shape_rotations.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>

#include "diffdope/mesh.hpp"

namespace diffdope {

Pose ShapeRotation::as_pose() const {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  return Pose(R, pivot - R * pivot);
}

namespace {

/// `n` points uniformly distributed over the surface (area-weighted triangles, uniform inside), seeded;
/// `normals` (optional) receives their triangles' unit normals.
std::vector<Eigen::Vector3f> sample_surface(const Mesh& mesh, int n, uint64_t seed,
                                            std::vector<Eigen::Vector3f>* normals = nullptr) {
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
    if (normals) normals->push_back((corner(t, 1) - corner(t, 0)).cross(corner(t, 2) - corner(t, 0)).normalized());
  }
  return out;
}

/// Distance from each of `moved` to the nearest point of `fixed` (brute force on structure-of-arrays, which the
/// compiler vectorises: ~1k x 1k points in about a millisecond).
std::vector<double> nearest_distances(const std::vector<Eigen::Vector3f>& moved, const std::vector<float>& fx,
                                      const std::vector<float>& fy, const std::vector<float>& fz) {
  std::vector<double> out;
  out.reserve(moved.size());
  for (const Eigen::Vector3f& p : moved) {
    float best = std::numeric_limits<float>::infinity();
    for (size_t j = 0; j < fx.size(); ++j) {
      const float dx = fx[j] - p.x(), dy = fy[j] - p.y(), dz = fz[j] - p.z();
      best = std::min(best, dx * dx + dy * dy + dz * dz);
    }
    out.push_back(std::sqrt(double(best)));
  }
  return out;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, size_t(q * double(v.size())));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

/// Mean over `moved` of the distance to the nearest point of `fixed`.
double mean_nearest(const std::vector<Eigen::Vector3f>& moved, const std::vector<float>& fx,
                    const std::vector<float>& fy, const std::vector<float>& fz) {
  double sum = 0;
  for (double d : nearest_distances(moved, fx, fy, fz)) sum += d;
  return moved.empty() ? 0.0 : sum / double(moved.size());
}

}  // namespace

std::vector<ShapeRotation> analyse_shape_rotations(const Mesh& mesh) {
  // Two independent samples: the distance between them at no rotation is the sampling's own floor.
  const std::vector<Eigen::Vector3f> a = sample_surface(mesh, kShapeSamples, 1), b = sample_surface(mesh, kShapeSamples, 2);
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

namespace {
constexpr int kAnglesPerAxis = kShapeAngleSteps - 1;  // the candidates of one axis, consecutive
/// Whether every multiple of 30 degrees about the axis of candidates c[0 .. kAnglesPerAxis) is within tolerance.
bool is_revolution(const ShapeRotation* c, double tolerance) {
  for (int k = 0; k < kAnglesPerAxis; ++k)
    if (!(c[k].discrepancy <= tolerance)) return false;
  return true;
}
}  // namespace

std::vector<ShapeRotation> revolution_axes(const std::vector<ShapeRotation>& candidates, double tolerance) {
  std::vector<ShapeRotation> out;
  if (!(tolerance > 0)) return out;
  for (size_t first = 0; first + kAnglesPerAxis <= candidates.size(); first += kAnglesPerAxis)
    if (is_revolution(candidates.data() + first, tolerance)) {
      ShapeRotation r = candidates[first];
      r.angle = 0;
      r.discrepancy = 0;
      out.push_back(r);
    }
  return out;
}

std::optional<ShapeRotation> fit_revolution_axis(const Mesh& mesh, double tolerance) {
  if (!(tolerance > 0) || !(mesh.diameter() > 0)) return std::nullopt;
  std::vector<Eigen::Vector3f> normals;
  const std::vector<Eigen::Vector3f> a = sample_surface(mesh, kShapeSamples, 3, &normals);
  if (a.size() < 16) return std::nullopt;
  // The normal line of sample i, in Pluecker coordinates (n, m = p x n), meets the axis (direction d, moment
  // dbar = c x d) when n . dbar + m . d = 0: linear in (dbar, d). Least squares with |d| = 1, dbar eliminated
  // (dbar = -Nnn^-1 Nnm d): d is the least eigenvector of the Schur complement. Refitted: samples whose
  // residual exceeds 3 times the median's count no more (a handle's normal lines miss the body's axis).
  const Eigen::Vector3d centre = mesh.center();  // (coordinates about the centre: better conditioned)
  std::vector<Eigen::Vector3d> n(a.size()), m(a.size());
  for (size_t i = 0; i < a.size(); ++i) {
    n[i] = normals[i].cast<double>();
    m[i] = (a[i].cast<double>() - centre).cross(n[i]);
  }
  std::vector<double> w(a.size(), 1.0);
  Eigen::Vector3d d = Eigen::Vector3d::UnitZ(), dbar = Eigen::Vector3d::Zero();
  for (int round = 0; round < kRevolutionFitRounds; ++round) {
    Eigen::Matrix3d Nnn = Eigen::Matrix3d::Zero(), Nnm = Eigen::Matrix3d::Zero(), Nmm = Eigen::Matrix3d::Zero();
    for (size_t i = 0; i < a.size(); ++i) {
      Nnn += w[i] * n[i] * n[i].transpose();
      Nnm += w[i] * n[i] * m[i].transpose();
      Nmm += w[i] * m[i] * m[i].transpose();
    }
    // A small ridge: when every normal is across the axis (an open tube) dbar's part along d is free; the
    // ridge takes it as 0, which is all the axis needs (d x dbar is the same).
    Nnn += 1e-9 * std::max(Nnn.trace(), 1e-30) * Eigen::Matrix3d::Identity();
    const Eigen::FullPivLU<Eigen::Matrix3d> lu(Nnn);
    if (!lu.isInvertible()) return std::nullopt;  // no samples left
    const Eigen::Matrix3d schur = Nmm - Nnm.transpose() * lu.solve(Nnm);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (schur + schur.transpose()));
    d = eig.eigenvectors().col(0).normalized();
    dbar = -lu.solve(Nnm * d);
    std::vector<double> r(a.size());
    for (size_t i = 0; i < a.size(); ++i) r[i] = std::abs(n[i].dot(dbar) + m[i].dot(d));
    std::vector<double> sorted = r;
    std::nth_element(sorted.begin(), sorted.begin() + long(sorted.size() / 2), sorted.end());
    const double cut = kRevolutionInlierCut * std::max(sorted[sorted.size() / 2], 1e-6 * mesh.diameter());
    for (size_t i = 0; i < a.size(); ++i) w[i] = r[i] <= cut ? 1.0 : 0.0;
  }
  ShapeRotation axis;
  axis.axis = d;
  axis.pivot = centre + d.cross(dbar);  // the axis point nearest the centre (dbar = c x d)
  // Kept when most of the surface (kRevolutionShare) maps onto itself after turns over the print search's
  // range: the turned sample's distances to a second sample, against the samples' own distances.
  const std::vector<Eigen::Vector3f> b = sample_surface(mesh, kShapeSamples, 4);
  std::vector<float> bx, by, bz;
  for (const auto& p : b) bx.push_back(p.x()), by.push_back(p.y()), bz.push_back(p.z());
  const double floor = quantile(nearest_distances(a, bx, by, bz), kRevolutionShare);
  for (const double degrees : kRevolutionCheckDegrees) {
    axis.angle = degrees * M_PI / 180.0;
    const Pose T = axis.as_pose();
    std::vector<Eigen::Vector3f> moved;
    for (const auto& p : a) moved.push_back((T * p.cast<double>()).cast<float>());
    const double q = quantile(nearest_distances(moved, bx, by, bz), kRevolutionShare);
    if (!((q - floor) / mesh.diameter() <= tolerance)) return std::nullopt;
  }
  axis.angle = 0;
  return axis;
}

std::vector<ShapeRotation> ambiguous_rotations(const std::vector<ShapeRotation>& candidates, double tolerance,
                                               int max_count) {
  std::vector<ShapeRotation> revolution, discrete;
  if (!(tolerance > 0) || max_count <= 0) return {};
  constexpr int per_axis = kAnglesPerAxis;
  for (size_t first = 0; first + per_axis <= candidates.size(); first += per_axis) {
    const ShapeRotation* c = candidates.data() + first;
    if (is_revolution(c, tolerance)) {  // a shape of revolution about this axis: spread the starts over the turn
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
