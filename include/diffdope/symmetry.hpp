#pragma once
// Symmetries declared for an object (BOP's models_info.json, the objects config): model-frame transforms after
// which the object looks the same by design — a plain cylinder turned about its axis, a box whose print repeats
// after a half turn. The refiner does not search along them, does not count them against its verdict, and
// reports one canonical pose of the equivalent ones, so a tracked symmetric object does not spin or flip.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "diffdope/pose.hpp"

namespace diffdope {

struct ObjectSymmetry {
  /// Rotation about a line (model frame): every angle is a symmetry.
  struct Axis {
    Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();      // a point of the line, metres
  };
  std::vector<Axis> continuous;  // at most kMaxContinuous
  /// Model-frame transforms x -> R x + t (metres), besides the identity (BOP lists every one of the group).
  std::vector<Pose> discrete;  // at most kMaxDiscrete
  static constexpr size_t kMaxContinuous = 3;
  static constexpr size_t kMaxDiscrete = 64;

  bool empty() const { return continuous.empty() && discrete.empty(); }
  /// Throws std::invalid_argument naming what is wrong: non-finite values, a zero axis, a rotation that is not
  /// orthonormal, too many entries. Normalises the axes.
  void validate_and_normalise(const std::string& origin);

  /// Whether the model-frame transform `m` is one of the declared symmetries, within `angle_tol` radians and
  /// `distance_tol` metres of surface displacement at `radius` from the offset (the shape scan skips those).
  bool contains(const Pose& m, double angle_tol, double distance_tol, double radius) const;
  /// Among the poses equivalent to `pose` (pose * S for each declared S, and every angle about the continuous
  /// axes), the one whose rotation is nearest to `reference`'s. Tracking passes the previous frame's pose (no
  /// spin, no flip); a fresh result passes canonical_reference() (a history-free choice).
  Pose nearest_equivalent(const Pose& pose, const Eigen::Matrix3d& reference) const;
  /// The reference of a history-free canonical form: the camera's axes (the equivalent pose whose model axes
  /// are closest to the camera's).
  static Eigen::Matrix3d canonical_reference() { return Eigen::Matrix3d::Identity(); }
  /// The twists about `pivot` (camera frame, as pose_curvature.hpp's) that move `pose` along its continuous
  /// axes.
  std::vector<Eigen::Matrix<double, 6, 1>> free_twists(const Pose& pose, const Eigen::Vector3d& pivot) const;
};

}  // namespace diffdope
