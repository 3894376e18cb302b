// The loss's curvature at a refined pose, in units of surface displacement (pose_curvature.hpp).
#include "diffdope/pose_curvature.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <cmath>
#include <limits>

namespace diffdope {

Pose twist_about(const Pose& pose, const Vector6d& delta, const Eigen::Vector3d& pivot) {
  const Eigen::Matrix3d Rw = so3_exp(delta.tail<3>());
  Pose out(Rw * pose.R, Rw * (pose.t - pivot) + pivot + delta.head<3>());
  out.orthonormalize();
  return out;
}

Vector6d gradient_about(const Vector6d& g, const Eigen::Vector3d& pivot) {
  // First order: a twist (v, w) about p is (v + p x w, w) about the camera origin.
  Vector6d out;
  out.head<3>() = g.head<3>();
  out.tail<3>() = g.tail<3>() - pivot.cross(g.head<3>());
  return out;
}

Matrix6d surface_displacement_metric(const Mesh& mesh, const Eigen::Matrix3d& R, const Eigen::Vector3d& pivot_model) {
  // A surface point r (from the pivot) moves by v + w x r = J(r) δ, J = [I, -[r]x]: G = E[Jᵀ J], the area-weighted
  // mean over the triangles (each at its centroid, plus its own spread: exact second moments per triangle).
  Eigen::Vector3d first = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();  // E[r rᵀ]
  double area = 0;
  const auto at = [&](int i) -> Eigen::Vector3d {  // (a value: an Eigen expression would outlive its operand)
    const Vec3f& p = mesh.positions[i];
    return Eigen::Vector3d(p.x, p.y, p.z) - pivot_model;
  };
  for (int f = 0; f < mesh.num_triangles(); ++f) {
    const Eigen::Vector3d a = at(mesh.triangles[3 * f]);
    const Eigen::Vector3d b = at(mesh.triangles[3 * f + 1]);
    const Eigen::Vector3d c = at(mesh.triangles[3 * f + 2]);
    const double A = 0.5 * (b - a).cross(c - a).norm();
    if (!(A > 0)) continue;
    const Eigen::Vector3d m = (a + b + c) / 3.0;
    first += A * m;
    // Second moment of a uniform triangle: (a aᵀ + b bᵀ + c cᵀ + 9 m mᵀ) / 12.
    second += A * (a * a.transpose() + b * b.transpose() + c * c.transpose() + 9.0 * m * m.transpose()) / 12.0;
    area += A;
  }
  Matrix6d G = Matrix6d::Identity();
  if (!(area > 0)) return G;
  first /= area;
  second /= area;
  // E[Jᵀ J] = [[I, -[r̄]x], [[r̄]x, E[|r|²] I - E[r rᵀ]]] (since [r]xᵀ [r]x = |r|² I - r rᵀ).
  Matrix6d Gm;
  Gm.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity();
  Gm.topRightCorner<3, 3>() = -skew(first);
  Gm.bottomLeftCorner<3, 3>() = skew(first);
  Gm.bottomRightCorner<3, 3>() = second.trace() * Eigen::Matrix3d::Identity() - second;
  Matrix6d B = Matrix6d::Zero();
  B.topLeftCorner<3, 3>() = R;
  B.bottomRightCorner<3, 3>() = R;
  return B * Gm * B.transpose();
}

std::vector<Pose> secant_probe_poses(const Pose& pose, const Matrix6d& LinvT, double h, const Eigen::Vector3d& pivot) {
  std::vector<Pose> probes;
  probes.reserve(kSecantProbePoses);
  for (int i = 0; i < 6; ++i)
    for (const double s : {h, -h}) probes.push_back(twist_about(pose, s * LinvT.col(i), pivot));
  probes.push_back(pose);
  return probes;
}

Matrix6d secant_hessian(const std::vector<Vector6d>& gradients, const Matrix6d& Linv, double h) {
  Matrix6d Hq;
  for (int i = 0; i < 6; ++i)
    Hq.col(i) = (Linv * gradients[size_t(2 * i)] - Linv * gradients[size_t(2 * i + 1)]) / (2 * h);
  return 0.5 * (Hq + Hq.transpose());
}

Eigen::Matrix<double, 6, Eigen::Dynamic> complement_of(const std::vector<Vector6d>& directions) {
  if (directions.empty()) return Matrix6d::Identity();
  Eigen::Matrix<double, 6, Eigen::Dynamic> F(6, int(directions.size()));
  for (size_t k = 0; k < directions.size(); ++k) F.col(int(k)) = directions[k];
  const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 6, Eigen::Dynamic>> qr(F);
  const Matrix6d Q = qr.householderQ();
  return Q.rightCols(6 - int(qr.rank()));
}

Vector6d newton_step(const Matrix6d& Hq, const Vector6d& gq, double trust, const std::vector<Vector6d>& free) {
  // In the complement of a declared symmetry's free directions (nothing to gain there). Directions curved less
  // than a thousandth of the most curved one (flat, or downwards: not a minimum) take the step that curvature
  // would give. A step longer than the trust radius is damped, not shortened: -(H + λI)⁻¹ g with λ making it
  // `trust` long (Levenberg-Marquardt), so the barely curved directions, whose long steps follow mostly noise,
  // give way first and the well curved ones keep their Newton length.
  if (!gq.allFinite() || !Hq.allFinite() || !(trust > 0)) return Vector6d::Zero();
  const Eigen::Matrix<double, 6, Eigen::Dynamic> U = complement_of(free);
  if (U.cols() == 0) return Vector6d::Zero();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(U.transpose() * Hq * U);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues().maxCoeff() > 0)) return Vector6d::Zero();
  Eigen::VectorXd curvature = eig.eigenvalues();
  const double floor = 1e-3 * curvature.maxCoeff();
  curvature = curvature.cwiseMax(floor);
  const Eigen::MatrixXd basis = U * eig.eigenvectors();  // orthonormal columns: |basis x| = |x|
  const Eigen::VectorXd g = basis.transpose() * gq;
  const auto damped = [&](double lambda) -> Eigen::VectorXd { return -g.array() / (curvature.array() + lambda); };
  Eigen::VectorXd x = damped(0.0);
  if (!x.allFinite()) return Vector6d::Zero();
  if (x.norm() > trust) {
    // |damped(λ)| falls with λ and is at most |g| / λ: bisect (in log scale) between 0 and |g| / trust.
    double lo = 0.0, hi = g.norm() / trust;
    for (int k = 0; k < 60; ++k) {
      const double mid = lo > 0 ? std::sqrt(lo * hi) : 0.5 * hi;
      (damped(mid).norm() > trust ? lo : hi) = mid;
    }
    x = damped(hi);
    if (x.norm() > trust) x *= trust / x.norm();  // (rounding)
  }
  return basis * x;
}

double newton_decrease(const Matrix6d& Hq, const Vector6d& gq, const std::vector<Vector6d>& free) {
  const Vector6d s = newton_step(Hq, gq, std::numeric_limits<double>::infinity(), free);
  return std::max(0.0, -(gq.dot(s) + 0.5 * s.dot(Hq * s)));
}

PoseCurvature probe_pose_curvature(Renderer& renderer, const Camera& camera, const Mesh& mesh,
                                   const Observation& observed, const LossOptions& loss, const Pose& pose,
                                   double distance, const std::vector<Vector6d>& free_twists) {
  return probe_pose_curvature(renderer, {{camera, mesh, observed}}, loss, pose, mesh.center(), distance, free_twists);
}

namespace {

/// The views' mean loss (and, with gradients, its gradient about `pivot`) at each of `poses`.
void mean_over_views(Renderer& renderer, const std::vector<ProbeView>& views, const LossOptions& loss,
                     const std::vector<Pose>& poses, const Eigen::Vector3d& pivot, bool with_gradient,
                     std::vector<double>& totals, std::vector<Vector6d>& gradients) {
  totals.assign(poses.size(), 0.0);
  gradients.assign(poses.size(), Vector6d::Zero());
  std::vector<LossValue> v;
  for (const ProbeView& view : views) {
    renderer.evaluate(view.camera, view.mesh, view.observed, poses, loss, with_gradient, v);
    for (size_t k = 0; k < poses.size(); ++k) {
      totals[k] += v[k].total;
      if (with_gradient) gradients[k] += gradient_about(v[k].gradient, pivot);
    }
  }
  for (size_t k = 0; k < poses.size(); ++k) totals[k] /= double(views.size()), gradients[k] /= double(views.size());
}

/// The metric of `views` at `pose` (their mean) into out.metric; false when it is degenerate.
bool set_metric(const std::vector<ProbeView>& views, const Pose& pose, const Eigen::Vector3d& pivot_model,
                PoseCurvature& out) {
  Matrix6d metric = Matrix6d::Zero();
  for (const ProbeView& view : views) metric += surface_displacement_metric(view.mesh, pose.R, pivot_model);
  out.metric = metric / double(views.size());
  return Eigen::LLT<Matrix6d>(out.metric).info() == Eigen::Success;
}

/// From the whitened Hessian `Hq` (q = Lᵀ δ: |q| = RMS surface displacement, out.metric = L Lᵀ): the curvatures
/// and the weakest direction in the complement of the free twists, and the rise along it (`loss_at`: the mean
/// loss at poses) above out.loss.
template <class LossAt>
void finish_curvature(PoseCurvature& out, const Matrix6d& Hq, const Pose& pose, const Eigen::Vector3d& pivot,
                      double distance, const std::vector<Vector6d>& free_twists, const LossAt& loss_at) {
  const Matrix6d L = Eigen::LLT<Matrix6d>(out.metric).matrixL();
  const Matrix6d LinvT = L.inverse().transpose();
  // The directions a declared symmetry leaves free are not weaknesses of the data: search their complement.
  std::vector<Vector6d> free_whitened;
  for (const Vector6d& f : free_twists) free_whitened.push_back(L.transpose() * f);
  const Eigen::Matrix<double, 6, Eigen::Dynamic> U = complement_of(free_whitened);
  const Eigen::MatrixXd Hs = U.transpose() * Hq * U;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs);
  if (eig.info() != Eigen::Success || Hs.rows() == 0) return;
  out.curvatures.setConstant(std::numeric_limits<double>::infinity());
  for (int i = 0; i < int(Hs.rows()); ++i) out.curvatures[i] = eig.eigenvalues()[i];
  const Vector6d u = U * eig.eigenvectors().col(0);
  out.weakest_twist = LinvT * u;
  const std::vector<double> sides = loss_at({twist_about(pose, distance * out.weakest_twist, pivot),
                                             twist_about(pose, -distance * out.weakest_twist, pivot)});
  out.weakest_rise = std::min(sides[0], sides[1]) - out.loss;
  out.valid = std::isfinite(out.weakest_rise);
}

}  // namespace

PoseCurvature probe_pose_curvature(Renderer& renderer, const std::vector<ProbeView>& views, const LossOptions& loss,
                                   const Pose& pose, const Eigen::Vector3d& pivot_model, double distance,
                                   const std::vector<Vector6d>& free_twists) {
  PoseCurvature out;
  if (views.empty() || !set_metric(views, pose, pivot_model, out) || !(distance > 0)) return out;
  const Eigen::Vector3d pivot = pose * pivot_model;
  const Matrix6d L = Eigen::LLT<Matrix6d>(out.metric).matrixL();
  const Matrix6d Linv = L.inverse();
  const double h = 0.5 * distance;
  std::vector<double> totals;
  std::vector<Vector6d> gradients;
  mean_over_views(renderer, views, loss, secant_probe_poses(pose, Linv.transpose(), h, pivot), pivot, true, totals,
                  gradients);
  out.loss = totals.back();
  for (const double t : totals)
    if (!std::isfinite(t)) return out;
  const Matrix6d Hq = secant_hessian(gradients, Linv, h);
  out.hessian = L * Hq * L.transpose();
  finish_curvature(out, Hq, pose, pivot, distance, free_twists, [&](const std::vector<Pose>& poses) {
    std::vector<Vector6d> unused;
    mean_over_views(renderer, views, loss, poses, pivot, false, totals, unused);
    return totals;
  });
  return out;
}

PoseCurvature carry_pose_curvature(Renderer& renderer, const std::vector<ProbeView>& views, const LossOptions& loss,
                                   const PoseCurvature& measured, const Pose& measured_at, const Pose& pose,
                                   const Eigen::Vector3d& pivot_model, double distance,
                                   const std::vector<Vector6d>& free_twists) {
  PoseCurvature out;
  if (!measured.valid || views.empty() || !set_metric(views, pose, pivot_model, out) || !(distance > 0)) return out;
  // The twist about the pivot in the object's axes is (Rᵀ v, Rᵀ w): the Hessian turns with the object.
  Matrix6d turn = Matrix6d::Zero();
  turn.topLeftCorner<3, 3>() = turn.bottomRightCorner<3, 3>() = pose.R * measured_at.R.transpose();
  out.hessian = turn * measured.hessian * turn.transpose();
  const Eigen::Vector3d pivot = pose * pivot_model;
  std::vector<double> totals;
  std::vector<Vector6d> unused;
  mean_over_views(renderer, views, loss, {pose}, pivot, false, totals, unused);
  out.loss = totals[0];
  if (!std::isfinite(out.loss)) return out;
  const Matrix6d Linv = Eigen::LLT<Matrix6d>(out.metric).matrixL().toDenseMatrix().inverse();
  finish_curvature(out, Linv * out.hessian * Linv.transpose(), pose, pivot, distance, free_twists,
                   [&](const std::vector<Pose>& poses) {
    mean_over_views(renderer, views, loss, poses, pivot, false, totals, unused);
    return totals;
  });
  return out;
}

Matrix6d pose_covariance(const PoseCurvature& c, int pixels, double max_std) {
  if (!c.valid || pixels <= 0 || !(max_std > 0)) return Matrix6d::Zero();
  const Eigen::LLT<Matrix6d> llt(c.metric);
  if (llt.info() != Eigen::Success) return Matrix6d::Zero();
  const Matrix6d L = llt.matrixL(), Linv = L.inverse();
  // In whitened coordinates q = Lᵀ δ (|q| = RMS surface displacement): H_q = L⁻¹ H L⁻ᵀ.
  const Matrix6d Hq = Linv * c.hessian * Linv.transpose();
  const Eigen::SelfAdjointEigenSolver<Matrix6d> eig(0.5 * (Hq + Hq.transpose()));
  if (eig.info() != Eigen::Success) return Matrix6d::Zero();
  const double n = std::max(1.0, pixels / kCorrelatedPixels), residual = std::max(c.loss, 1e-9);
  const double max_var = max_std * max_std;
  Vector6d var;
  for (int i = 0; i < 6; ++i) {
    const double lambda = eig.eigenvalues()[i];
    var[i] = lambda > 0 ? std::min(max_var, residual / (n * lambda)) : max_var;
  }
  const Matrix6d U = eig.eigenvectors();
  const Matrix6d cov_q = U * var.asDiagonal() * U.transpose();
  return Linv.transpose() * cov_q * Linv;  // δ = L⁻ᵀ q
}

Matrix6d covariance_at_origin(const Matrix6d& twist_covariance, const Eigen::Vector3d& pivot,
                              const Eigen::Vector3d& origin) {
  // The origin moves by v + w x (origin - pivot) = v - [origin - pivot]x w; the rotation is w.
  Matrix6d J = Matrix6d::Identity();
  J.topRightCorner<3, 3>() = -skew(origin - pivot);
  return J * twist_covariance * J.transpose();
}

}  // namespace diffdope
