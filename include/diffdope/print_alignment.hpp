#pragma once
// Print alignment (RefinerOptions::print_search): the last step of a refinement for shapes of near revolution.
// About such an axis (a bottle's; a mug's body while its handle is out of sight), silhouette and depth look the
// same after any turn, and the descent's L1 colour term (a flat render against a lit image) barely sees the
// print, so the descent ends wherever the start's turn left it, off nearly all about the axis
// (docs/benchmarks.md). Here the result is turned about the axis over a
// range of angles and compared by the texture term (Sobel of log grey: lighting's strength and colour leave it
// alone), whose minimum sits at the print's true turn once the silhouette is in place.
#include <functional>
#include <vector>

#include "diffdope/refine_tuning.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/shape_rotations.hpp"

namespace diffdope {

// The alignment's steps, its range about a tracked start and its acceptance bars: refine_tuning.hpp.

struct PrintAlignment {
  Pose pose;                  // the result: the input pose turned by `angle` about the axis
  double angle = 0;           // radians (0: no turn kept)
  double print_before = 0, print_after = 0;  // texture term at the input pose and at the result
  double loss_before = 0, loss_after = 0;    // the refiner's loss (texture weight as configured) there
  int evaluations = 0;
};

/// Evaluates poses (forward only) with the texture term at weight 1 and the other terms as the refiner's loss.
using PrintEvaluator = std::function<void(const std::vector<Pose>& poses, std::vector<LossValue>& out)>;

/// Turns `pose` about `axis` (model frame: ShapeRotation::axis through pivot; angle ignored) by up to +-range
/// radians: of the turns that meet the conditions above, the one with the lowest sum of the texture term and the
/// refiner's loss, each relative to its value at `pose` (none: no turn). Where the print barely registers (a pose
/// not yet converged) the texture term is nearly flat over the turns and its lowest value is noise; the loss,
/// whose colour term sees the print a little, then decides. `texture_weight`: the refiner's own weight of the texture term (its loss = evaluated total -
/// (1 - texture_weight) * texture).
PrintAlignment align_print(const Pose& pose, const ShapeRotation& axis, double range, double texture_weight,
                           const PrintEvaluator& evaluate);

/// Evaluations align_print() makes for `range` at most (fewer when the best coarse turn is at the range's end).
int print_alignment_evaluations(double range);

}  // namespace diffdope
