#pragma once
// Rotations of an object that its shape cannot tell apart from no rotation: a bottle about its axis, a box by a
// half turn, a cylinder flipped end over end. Silhouette and depth see the same object after them; only texture
// (or nothing, for a true symmetry) decides. A hard start is often closer to one of them than to the truth, and
// gradient descent does not cross from one to the other (the texture's basin is narrow), so the refiner tries
// them all on each run (RefinerOptions::shape_scan) and lets the loss decide.
#include <Eigen/Core>
#include <optional>
#include <vector>

#include "diffdope/refine_tuning.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

class Mesh;

/// One candidate: a rotation by `angle` about `axis` through `pivot` (model frame), and how far the rotated
/// surface lies from the surface.
struct ShapeRotation {
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit, a principal axis of the surface
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();  // metres: the surface's centroid
  double angle = 0;                                 // radians, in (0, 2 pi)
  /// Mean distance from the rotated surface to the surface, beyond what the sampling itself gives, as a
  /// fraction of the mesh's diameter: ~0 for a symmetry, a few % for a nearly symmetric shape (a mug's handle).
  double discrepancy = 0;
  /// The model-frame transform x -> R (x - pivot) + pivot: a start `initial` becomes initial * as_pose().
  Pose as_pose() const;
};

/// Every candidate the analysis tried: about each of the surface's three principal axes (second moments of an
/// area-uniform sample), every multiple of 360 / kShapeAngleSteps degrees. Deterministic. Mesh::finalize() computes it once.
std::vector<ShapeRotation> analyse_shape_rotations(const Mesh& mesh);

/// The rotations worth trying, at most `max_count`: about an axis where every multiple of 30 degrees is within
/// `tolerance` (a shape of revolution), angles evenly spread over the turn (as many as fit in max_count, at
/// most every 30 degrees); then, about other axes, the angles within `tolerance` that are local minima of the
/// discrepancy (a box's half turns), best first. Empty when tolerance <= 0.
std::vector<ShapeRotation> ambiguous_rotations(const std::vector<ShapeRotation>& candidates, double tolerance,
                                               int max_count);

/// An axis of near revolution of most of the surface, found from its normals (every normal line of a surface
/// of revolution meets the axis; fitted with the lines that miss it most left out, so a part that breaks the
/// symmetry, a mug's handle, is outvoted): kept when three quarters of the surface stay within `tolerance`
/// diameters of the surface after turns of 10, 20 and 40 degrees about it. A mug's body axis, which no
/// principal axis need be (the handle tilts them). angle = 0, pivot on the axis.
std::optional<ShapeRotation> fit_revolution_axis(const Mesh& mesh, double tolerance);

/// The axes of near revolution among the candidates: those about which every multiple of 30 degrees is within
/// `tolerance` (angle 0: the axis and its pivot). Empty when tolerance <= 0.
std::vector<ShapeRotation> revolution_axes(const std::vector<ShapeRotation>& candidates, double tolerance);

}  // namespace diffdope
