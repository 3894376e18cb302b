#pragma once
// Per-pixel loss terms and their derivatives w.r.t. the antialiased render (coverage, premultiplied colour,
// premultiplied depth). Premultiplied values make the blend at silhouettes linear; L1 is homogeneous, so
// cov * |I - C/cov| = |cov*I - C| needs no division.
//
//  rgb   = S * ( sum_ch |cov*I_ch - C_ch| / 3 + (1 - cov) * rgb_miss )
//  depth = S * valid * ( min(|cov*I_d - D|, cov*tau) + (1 - cov) * tau ) / tau      (in [0, 1] per pixel)
//          tau = depth_trunc * (I_d / z_ref)^power: the noise's growth with distance
//  mask  = |S - cov|, except where S = 0 because something is in front of the object: an observed depth more
//          than occlusion_margin nearer than the render means an occluder, and the visible mask is rightly
//          empty there (without this, occluders push the object away).
// An observed object pixel (S > 0) that the render does not cover costs the "miss" value, so holes and
// uncovered pixels never compare against a meaningless background colour or depth.
#include "render/kernels/lanes.hpp"
#include "diffdope/vec.hpp"

namespace diffdope {

/// Per-term scale factors (weight / normaliser) and robustness constants, plain floats for kernels.
struct PixelLossParams {
  float k_rgb, k_depth, k_mask;  // weight_term / number of pixels the term averages over
  float rgb_miss;                // cost of an observed pixel the render misses, colour term
  float depth_trunc;             // tau, metres: depth errors saturate here
  float occlusion_margin;        // metres; <= 0 disables occlusion handling in the mask term
  float depth_noise_scale;       // 1 / z_ref: tau and the error are taken relative to (I_d / z_ref)^power
  int depth_noise_power;         // 0 (tau fixed), 1 or 2 (LossOptions::depth_noise_power)
};

struct PixelLossValue {
  float rgb, depth, mask;  // unscaled per-pixel terms
};

/// Derivatives of the scaled total w.r.t. coverage, premultiplied colour and depth.
struct PixelLossGrad {
  float cov;
  float c[3];
  float d;
};

/// What pixel_loss_lanes() gives for L::V's pixels at once: pixel_loss()'s values and gradient.
template <class L>
struct PixelLossLanes {
  typename L::V rgb, depth, mask;     // unscaled per-pixel terms
  typename L::V g_cov, g_c[3], g_d;   // derivatives of the scaled total
};

/// pixel_loss() over a lane type: every per-pixel condition is a select(), in the order the formula above states
/// them. `depth_valid` as pixel_loss()'s.
#include "render/kernels/pixel_loss_lanes.inc"

/// One pixel: pixel_loss_lanes() on ScalarLanes. `g` (optional) receives the derivatives.
DD_HOST_DEVICE PixelLossValue pixel_loss(const PixelLossParams& P, float S, const float I[3], float Id,
                                         bool depth_valid, float cov, const float C[3], float D,
                                         PixelLossGrad* g) {
  const PixelLossLanes<ScalarLanes> r = pixel_loss_lanes<ScalarLanes>(P, S, I, Id, depth_valid, cov, C, D);
  if (g) *g = PixelLossGrad{r.g_cov, {r.g_c[0], r.g_c[1], r.g_c[2]}, r.g_d};
  return PixelLossValue{r.rgb, r.depth, r.mask};
}

/// One pixel of the loss pass, as both backends run it: observed background the render does not touch costs
/// nothing (and has no gradient; pixel_loss() gives the same zeros there); anything else goes through
/// pixel_loss. Id <= 0 means no depth reading.
DD_HOST_DEVICE PixelLossValue pixel_loss_step(const PixelLossParams& P, float S, const float I[3], float Id,
                                              float cov, const float C[3], float D, PixelLossGrad* g) {
  if (S == 0.f && cov == 0.f) {
    if (g) *g = PixelLossGrad{0.f, {0.f, 0.f, 0.f}, 0.f};
    return PixelLossValue{0.f, 0.f, 0.f};
  }
  return pixel_loss(P, S, I, Id, Id > 0.f, cov, C, D, g);
}

}  // namespace diffdope
