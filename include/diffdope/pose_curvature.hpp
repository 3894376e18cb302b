#pragma once
// How firmly an observation pins a refined pose down: the loss's curvature at that pose, measured per metre of
// the model surface's mean displacement (the unit of ADD, what a grasp tolerates). A direction the data do not
// constrain (a bottle's axis with its print unseen, a mug whose handle is hidden) shows as a small curvature and
// a small loss rise along it; the refiner's verdict and the pose covariance are built on it.
#include <Eigen/Core>
#include <vector>

#include "diffdope/refine_tuning.hpp"
#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// The pose moved by the twist δ = (v [m], w [rad], camera axes) about `pivot` (camera frame):
/// R' = exp(w) R, t' = exp(w) (t − pivot) + pivot + v.
Pose twist_about(const Pose& pose, const Vector6d& delta, const Eigen::Vector3d& pivot);

/// The renderer's gradient (w.r.t. T' = exp(δ)·T about the camera origin, renderer.hpp) as the gradient w.r.t.
/// the twist about `pivot` of twist_about().
Vector6d gradient_about(const Vector6d& camera_gradient, const Eigen::Vector3d& pivot);

/// G with δᵀ G δ = the mean squared displacement of the model's surface (area-weighted) under the twist δ about
/// the model point `pivot_model`, for a pose of rotation `R` (camera axes). Symmetric positive definite for any
/// mesh with area that is not a line.
Matrix6d surface_displacement_metric(const Mesh& mesh, const Eigen::Matrix3d& R, const Eigen::Vector3d& pivot_model);

/// Poses of a secant probe: ±h along each axis of the whitened twist (the columns of `LinvT` = L⁻ᵀ, G = L Lᵀ the
/// surface_displacement_metric(): unit RMS surface displacement), in the order +h, −h per axis, then `pose`
/// itself (kSecantProbePoses in all).
constexpr int kSecantProbePoses = 13;
std::vector<Pose> secant_probe_poses(const Pose& pose, const Matrix6d& LinvT, double h, const Eigen::Vector3d& pivot);

/// The whitened secant Hessian (per m² of RMS surface displacement) from the gradients about the pivot at
/// secant_probe_poses(): central differences, symmetrised.
Matrix6d secant_hessian(const std::vector<Vector6d>& gradients, const Matrix6d& Linv, double h);

/// An orthonormal basis of the complement of the span of `directions` (6 × (6 − rank); the identity for none).
Eigen::Matrix<double, 6, Eigen::Dynamic> complement_of(const std::vector<Vector6d>& directions);

/// The Newton step −H⁻¹ g in whitened coordinates (metres of RMS surface displacement), less its components
/// along `free` (whitened directions a declared symmetry leaves free). Curvatures below a thousandth of the
/// largest (a flat direction, or one curved downwards) are raised to it. Longer than `trust`, it is damped to
/// that length, −(H + λI)⁻¹ g (the trust-region step). Zero when no direction curves upwards or the input is not
/// finite.
Vector6d newton_step(const Matrix6d& Hq, const Vector6d& gq, double trust, const std::vector<Vector6d>& free = {});
/// The loss decrease the quadratic model (Hq, gq, whitened as newton_step()'s) predicts for its untrusted Newton
/// step, −(gᵀs + ½ sᵀHs) ≥ 0; 0 when newton_step() gives none.
double newton_decrease(const Matrix6d& Hq, const Vector6d& gq, const std::vector<Vector6d>& free = {});

/// One image of a probed pose. Several views share the pose (a calibration's captures: one camera <- base, the
/// robot in each capture's configuration); the probe weighs their mean loss, as Refiner::refine_views() does.
struct ProbeView {
  const Camera& camera;
  const Mesh& mesh;
  const Observation& observed;
};

/// Evaluations of one probe (per view): a batch of 13 with gradients (±half the distance along the 6 metric axes, and the
/// pose), and one of 2 without (±the distance along the weakest direction).
constexpr int kCurvatureProbeEvaluations = 15;

/// The loss around a pose, probed with kCurvatureProbeEvaluations evaluations.
struct PoseCurvature {
  /// Secant Hessian of the loss w.r.t. the twist about the pose's pivot (per m², per m·rad, per rad²):
  /// central differences of the gradient at ±step of surface displacement along each axis of the metric.
  Matrix6d hessian = Matrix6d::Zero();
  Matrix6d metric = Matrix6d::Identity();  // surface_displacement_metric() at the pose
  /// Eigenvalues of the Hessian in surface-displacement units, ascending: loss per (metre of mean surface
  /// displacement)², along the directions that are its eigenvectors.
  Vector6d curvatures = Vector6d::Zero();
  Vector6d weakest_twist = Vector6d::Zero();  // δ that displaces the surface by 1 m along the least curved direction
  /// The loss rise measured at ±`distance` of surface displacement along the weakest direction (the smaller of
  /// the two sides; may be negative when the pose is not at a minimum).
  double weakest_rise = 0;
  double loss = 0;  // loss at the pose itself
  bool valid = false;  // false when a probe left the image (non-finite loss) or the metric is degenerate
};

/// Probes the loss of `mesh` at `pose` (camera frame) against `observed`, about the pivot pose * mesh.center().
/// `free_twists`: twists about that pivot along which a declared symmetry makes the object look the same on
/// purpose (symmetry.hpp); they are projected out before the weakest direction is sought. `distance`: surface
/// displacement (metres) of the rise probe; the Hessian's differences use half of it.
PoseCurvature probe_pose_curvature(Renderer& renderer, const Camera& camera, const Mesh& mesh,
                                   const Observation& observed, const LossOptions& loss, const Pose& pose,
                                   double distance, const std::vector<Vector6d>& free_twists = {});
/// The same over several views of one pose, about the pivot pose * `pivot_model` (the meshes' common frame); the
/// metric is the views' mean.
PoseCurvature probe_pose_curvature(Renderer& renderer, const std::vector<ProbeView>& views, const LossOptions& loss,
                                   const Pose& pose, const Eigen::Vector3d& pivot_model, double distance,
                                   const std::vector<Vector6d>& free_twists = {});

/// The curvature `measured` at `measured_at` (an earlier frame of a tracked object), carried to `pose`: its
/// Hessian turned with the object (in the object's axes, about the pivot, the loss keeps its shape over a frame's
/// motion), the metric, the loss at `pose` and the rise along the weakest direction measured again: 3 evaluations
/// without gradients per view instead of kCurvatureProbeEvaluations. Not valid when `measured` is not.
PoseCurvature carry_pose_curvature(Renderer& renderer, const std::vector<ProbeView>& views, const LossOptions& loss,
                                   const PoseCurvature& measured, const Pose& measured_at, const Pose& pose,
                                   const Eigen::Vector3d& pivot_model, double distance,
                                   const std::vector<Vector6d>& free_twists = {});
/// Evaluations of carry_pose_curvature() per view.
constexpr int kCarriedCurvatureEvaluations = 3;
/// A curvature a frame measured (RefineResult::curvature) and the pose it was measured at, to carry to the next.
struct MeasuredCurvature {
  PoseCurvature curvature;
  Pose pose;
};


/// A covariance of the pose from the loss's curvature (a Laplace approximation). The loss, a mean of L1
/// residuals over `pixels` object pixels, is read as the negative log-likelihood N · L / L* of Laplace noise
/// whose scale is the residual L* the pose leaves (N = pixels / kCorrelatedPixels), so Σ = L* / N · H⁻¹, H the
/// probe's Hessian. Directions the secant Hessian does not see curved upwards (flat, or negative: not a clean
/// minimum) get the largest variance allowed, `max_std` metres of mean surface displacement (the object's
/// size: beyond it nothing is known), as do the free twists of a declared symmetry. Of the twist about the
/// pivot (v metres, w radians, camera axes), as PoseCurvature::hessian; zero when `c` is not valid.
Matrix6d pose_covariance(const PoseCurvature& c, int pixels, double max_std);

/// The same covariance for the frame whose origin is `origin` (camera frame), ROS's PoseWithCovariance
/// convention: (x, y, z) the origin's displacement in metres, then rotations in radians about the camera's x, y,
/// z axes (the header frame's), row-major.
Matrix6d covariance_at_origin(const Matrix6d& twist_covariance, const Eigen::Vector3d& pivot,
                              const Eigen::Vector3d& origin);

}  // namespace diffdope
