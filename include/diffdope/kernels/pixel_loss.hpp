#pragma once
// Per-pixel loss terms and their derivatives w.r.t. the antialiased render (coverage, premultiplied colour,
// premultiplied depth). Premultiplied values make the blend at silhouettes linear; L1 is homogeneous, so
// cov * |I - C/cov| = |cov*I - C| needs no division.
//
//  rgb   = S * ( sum_ch |cov*I_ch - C_ch| / 3 + (1 - cov) * rgb_miss )
//  depth = S * valid * ( min(|cov*I_d - D|, cov*tau) + (1 - cov) * tau ) / tau      (in [0, 1] per pixel)
//  mask  = |S - cov|, except where S = 0 because something is in front of the object: an observed depth more
//          than occlusion_margin nearer than the render means an occluder, and the visible mask is rightly
//          empty there (without this, occluders push the object away).
// An observed object pixel (S > 0) that the render does not cover costs the "miss" value, so holes and
// uncovered pixels never compare against a meaningless background colour or depth.
#include "diffdope/kernels/vec.hpp"

namespace diffdope {

/// Per-term scale factors (weight / normaliser) and robustness constants, plain floats for kernels.
struct PixelLossParams {
  float k_rgb, k_depth, k_mask;  // weight_term / number of pixels the term averages over
  float rgb_miss;                // cost of an observed pixel the render misses, colour term
  float depth_trunc;             // tau, metres: depth errors saturate here
  float occlusion_margin;        // metres; <= 0 disables occlusion handling in the mask term
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

DD_HOST_DEVICE PixelLossValue pixel_loss(const PixelLossParams& P, float S, const float I[3], float Id,
                                         bool depth_valid, float cov, const float C[3], float D,
                                         PixelLossGrad* g) {
  PixelLossValue v{0.f, 0.f, 0.f};
  if (g) *g = PixelLossGrad{0.f, {0.f, 0.f, 0.f}, 0.f};
  if (S > 0.f && P.k_rgb != 0.f) {
    float sum = 0.f, gcov = 0.f;
    for (int ch = 0; ch < 3; ++ch) {
      const float a = cov * I[ch] - C[ch];
      sum += fabsf(a);
      const float sg = signf(a);
      if (g) g->c[ch] -= P.k_rgb * S * sg / 3.f;
      gcov += sg * I[ch];
    }
    v.rgb = S * (sum / 3.f + (1.f - cov) * P.rgb_miss);
    if (g) g->cov += P.k_rgb * S * (gcov / 3.f - P.rgb_miss);
  }
  if (S > 0.f && depth_valid && P.k_depth != 0.f) {
    const float tau = P.depth_trunc;
    const float a = cov * Id - D;
    const float aa = fabsf(a);
    if (aa < cov * tau) {
      v.depth = S * (aa + (1.f - cov) * tau) / tau;
      if (g) {
        g->d -= P.k_depth * S * signf(a) / tau;
        g->cov += P.k_depth * S * (signf(a) * Id - tau) / tau;
      }
    } else {
      v.depth = S;  // saturated: cov*tau + (1-cov)*tau = tau
    }
  }
  const bool occluded = P.occlusion_margin > 0.f && S < 0.5f && depth_valid && cov > 0.f &&
                        Id * cov < D - P.occlusion_margin * cov;  // Id < D / cov - margin
  if (P.k_mask != 0.f && !occluded) {
    const float a = S - cov;
    v.mask = fabsf(a);
    if (g) g->cov -= P.k_mask * signf(a);
  }
  return v;
}

/// One pixel of the loss pass, as both backends run it: observed background the render does not touch costs
/// nothing (and has no gradient); anything else goes through pixel_loss. Id <= 0 means no depth reading.
DD_HOST_DEVICE PixelLossValue pixel_loss_step(const PixelLossParams& P, float S, const float I[3], float Id,
                                              float cov, const float C[3], float D, PixelLossGrad* g) {
  if (S == 0.f && cov == 0.f) {
    if (g) *g = PixelLossGrad{0.f, {0.f, 0.f, 0.f}, 0.f};
    return PixelLossValue{0.f, 0.f, 0.f};
  }
  return pixel_loss(P, S, I, Id, Id > 0.f, cov, C, D, g);
}

}  // namespace diffdope
