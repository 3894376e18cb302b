// cuboid_mismatch() (object_config.hpp): a mesh against the detector's cuboid.
#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "diffdope/object_config.hpp"

namespace diffdope {
namespace {

/// The worst factor (>= 1) between the mesh's sides and the cuboid's, the cuboid scaled by `scale` and seen
/// through `cuboid_from_mesh`: the side of the mesh along its axis j faces the cuboid's sides by |R(i, j)|.
double worst_factor(const Eigen::Vector3d& mesh, const Eigen::Vector3d& cuboid, const Eigen::Matrix3d& R,
                    double scale) {
  const Eigen::Vector3d expected = scale * (R.cwiseAbs().transpose() * cuboid);
  double worst = 1;
  for (int j = 0; j < 3; ++j) {
    if (!(mesh[j] > 0) || !(expected[j] > 0)) return INFINITY;
    worst = std::max(worst, std::max(mesh[j] / expected[j], expected[j] / mesh[j]));
  }
  return worst;
}

std::string number(double v) {
  std::ostringstream s;
  s << std::setprecision(3) << v;
  return s.str();
}

std::string sides(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << std::setprecision(3) << v.x() << " x " << v.y() << " x " << v.z() << " m";
  return s.str();
}

/// A rotation whose axes are a permutation of the mesh's: the cuboid's axis perm[j] along the mesh's axis j.
Eigen::Matrix3d permutation(const std::array<int, 3>& perm) {
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  for (int j = 0; j < 3; ++j) R(perm[j], j) = 1;
  if (R.determinant() < 0) R.col(2) *= -1;  // a rotation, not a mirror: the sides cannot tell the signs
  return R;
}

std::string dope_matrix(const Eigen::Matrix3d& R) {
  std::ostringstream s;
  s << "[";
  for (int r = 0; r < 4; ++r) {
    s << (r ? ", [" : "[");
    for (int c = 0; c < 4; ++c) s << (c ? ", " : "") << (r < 3 && c < 3 ? R(r, c) : double(r == c));
    s << "]";
  }
  s << "]";
  return s.str();
}

}  // namespace

std::string cuboid_mismatch(const Eigen::Vector3d& mesh_extent, const ObjectConfig& object) {
  const Eigen::Vector3d& cuboid = object.cuboid_extent;
  if (!(cuboid.minCoeff() > 0)) return "";
  const Eigen::Matrix3d& R = object.cuboid_from_mesh;
  if (worst_factor(mesh_extent, cuboid, R, 1.0) <= kCuboidTolerance) return "";
  const std::string intro = "object '" + object.name + "': the mesh (" + sides(mesh_extent) + " after mesh_scale " +
                            number(object.mesh_scale) + ") does not fit DOPE's cuboid (dimensions " + sides(cuboid) +
                            ")";
  // A unit mistake: the same shape, 10, 100 or 1000 times too large or small.
  for (const double factor : {10.0, 100.0, 1000.0, 0.1, 0.01, 0.001})
    if (worst_factor(mesh_extent, cuboid, R, factor) <= kCuboidTolerance) {
      return intro + ": it is " + number(factor) + " times the cuboid's size; mesh_scales: {" + object.name + ": " +
             number(object.mesh_scale / factor) + "} is likely";
    }
  // Axes in another order: the sides fit once the cuboid's axes are permuted.
  std::array<int, 3> perm{0, 1, 2};
  do {
    const Eigen::Matrix3d P = permutation(perm);
    if (worst_factor(mesh_extent, cuboid, P, 1.0) <= kCuboidTolerance)
      return intro + ": its axes are the cuboid's in another order; in DOPE's file, model_transforms: {" +
             object.name + ": " + dope_matrix(P) + "} lines them up (the sides cannot tell the axes' signs: check "
             "the overlay)";
  } while (std::next_permutation(perm.begin(), perm.end()));
  return intro + ": check the mesh, its mesh_scales and DOPE's dimensions for it";
}

}  // namespace diffdope
