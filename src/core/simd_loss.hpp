#pragma once
// The loss pass over a row of pixels at once on the CPU (Highway vectors, chosen at run time for the CPU it runs
// on): pixel_loss_lanes() on many pixels, the same bits per pixel as pixel_loss_step() one at a time.
#include "diffdope/kernels/pixel_loss.hpp"
#include "diffdope/kernels/silhouette.hpp"

namespace diffdope {

struct LossRow {
  PixelLossParams P;
  const PixelAttr* post;  // n rendered pixels (after the blends)
  const float* S;         // n observed mask values; nullptr: S = 1
  const float* I;         // 3n observed rgb values; nullptr: 0
  const float* D;         // n observed depths (<= 0: no reading); nullptr: 0
  PixelAttr* g_post;      // n: receives dL/d(post); nullptr: no gradient
  int n;
};

/// Runs the row's first pixels, as many as fill whole vectors, and returns how many. Adds each one's (rgb, depth,
/// mask) terms to sum[0..2] as doubles, one pixel after the other in order: the same sums as adding
/// pixel_loss_step()'s values pixel by pixel. The caller does the rest of the row one pixel at a time.
int loss_row(const LossRow& row, double sum[3]);

/// The instruction set loss_row() runs on here (e.g. "AVX3", "AVX2", "SSE4"; for the profile and the README).
const char* loss_row_target();

}  // namespace diffdope
