#pragma once
// The refinement's plan (which iterations run at the coarse scale, when the shape scan and the halvings come)
// and the images at each scale (internal header).
#include <chrono>

#include "diffdope/camera.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/refiner.hpp"

namespace diffdope {

/// `camera` at `scale` (itself at 1).
Camera scaled_camera(const Camera& camera, double scale);

/// Wall time since `start`, in milliseconds.
double milliseconds_since(std::chrono::steady_clock::time_point start);

/// Iterations run at the coarse scale (RefinerOptions::coarse_fraction).
/// At least one fine step always follows (the last iteration only evaluates).
int coarse_iterations(const RefinerOptions& o);

/// The iteration whose batch is preceded by the shape scan (RefinerOptions::shape_scan): when the fine
/// phase begins (without a coarse phase: half-way), never on the last iteration; -1 = none.
int scan_iteration(const RefinerOptions& o);

/// Halvings due by iteration k of `iters`: at 25 %, 50 % and 75 % (">=": a stalled coarse phase may jump over
/// them).
int halvings_due(int k, int iters);

/// The two scales of a refinement: the coarse phase's (RefinerOptions::coarse_fraction) and the fine one.
enum class Phase { kCoarse, kFine };

/// Whether the loss, the shape scan or the print alignment compares texture gradients in `phase`
/// (observed_texture() is then needed). The scan and the alignment run at the fine scale only.
bool uses_texture(const RefinerOptions& o, Phase phase);

/// The frame's rgb / depth at `scale`, with the paper's edge map when the loss uses it.
Observation scale_frame(const Camera& camera, const Observation& frame, const RefinerOptions& o, double scale,
                        Phase phase);

}  // namespace diffdope
