#pragma once
// Differentiable edge map of the rendered image (the paper's edge term compares it with Canny edges of the
// observed image): Sobel gradient magnitude m of the rendered grey level, saturated smoothly,
//   E(p) = m / (m + scale) in [0, 1),   grey = mean of the premultiplied colour channels.
// A smooth saturation (not min(1, m / scale)) keeps the loss differentiable where edges are strong.
// Forward and backward are written as gathers over the 3x3 neighbourhood (no scattered writes), so a GPU thread
// per pixel needs no atomics.
#include "diffdope/vec.hpp"

namespace diffdope {

/// Sobel x and y kernels, indexed [dy + 1][dx + 1].
DD_HOST_DEVICE float sobel_x(int dx, int dy) { return float(dx) * (dy == 0 ? 2.f : 1.f); }
DD_HOST_DEVICE float sobel_y(int dx, int dy) { return float(dy) * (dx == 0 ? 2.f : 1.f); }

/// Grey level at (x, y) of a W x H image, 0 outside (nothing is rendered outside the region of interest).
DD_HOST_DEVICE float grey_at(const float* grey, int W, int H, int x, int y) {
  return (x < 0 || y < 0 || x >= W || y >= H) ? 0.f : grey[y * W + x];
}

/// Sobel x and y responses at (x, y) of a W x H image (0 outside).
DD_HOST_DEVICE void sobel_at(const float* image, int W, int H, int x, int y, float* sx, float* sy) {
  *sx = *sy = 0.f;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const float g = grey_at(image, W, H, x + dx, y + dy);
      *sx += sobel_x(dx, dy) * g;
      *sy += sobel_y(dx, dy) * g;
    }
}

/// Edge value at (x, y); also returns the Sobel responses (needed by the backward pass).
DD_HOST_DEVICE float edge_value(const float* grey, int W, int H, int x, int y, float scale, float* gx, float* gy) {
  float sx, sy;
  sobel_at(grey, W, H, x, y, &sx, &sy);
  *gx = sx;
  *gy = sy;
  const float mag = sqrtf(sx * sx + sy * sy);
  return mag / (mag + scale);
}

/// dL/d(Sobel x, Sobel y) at a pixel from dL/dE there.
DD_HOST_DEVICE void edge_value_backward(float gx, float gy, float scale, float g_edge, float* g_gx, float* g_gy) {
  const float mag = sqrtf(gx * gx + gy * gy);
  if (mag <= 1e-12f) {
    *g_gx = *g_gy = 0.f;
    return;
  }
  const float dE_dmag = scale / ((mag + scale) * (mag + scale));
  *g_gx = g_edge * dE_dmag * gx / mag;
  *g_gy = g_edge * dE_dmag * gy / mag;
}

/// One pixel of the edge term, as both backends run it: S * |E_observed - E_render| at (x, y) of the region's
/// grey image, and (when g_sx is non-null) dL/d(Sobel x, y) there for a loss weight k; zero outside S.
DD_HOST_DEVICE float edge_term_step(const float* grey, int W, int H, int x, int y, float scale, float S,
                                    float observed, float k, float* g_sx, float* g_sy) {
  if (g_sx) *g_sx = *g_sy = 0.f;
  if (!(S > 0.f)) return 0.f;
  float gx, gy;
  const float e = edge_value(grey, W, H, x, y, scale, &gx, &gy);
  if (g_sx) edge_value_backward(gx, gy, scale, k * S * signf(e - observed), g_sx, g_sy);
  return S * fabsf(observed - e);
}

/// One pixel of the texture term (LossOptions::weight_texture), as both backends run it: at (x, y) of the
/// region, w * (|obs_x - Sobel_x(L)| + |obs_y - Sobel_y(L)|) with L = log(grey + eps) the render's (W x H array)
/// and obs the observed Sobel of its own log grey. The weight w (taken as constant) is the smallest observed
/// mask and render coverage in the 3x3 window: the term looks inside the object only (silhouettes are the mask
/// and depth terms' business) and fades in and out with the coverage. When g_tx is non-null, receives
/// k * dL/d(Sobel x, y) there. Returns the unscaled value.
DD_HOST_DEVICE float texture_term_step(const float* log_grey, float w, int W, int H, int x, int y,
                                       const float observed[2], float k, float* g_tx, float* g_ty) {
  if (g_tx) *g_tx = *g_ty = 0.f;
  if (!(w > 0.f)) return 0.f;
  float sx, sy;
  sobel_at(log_grey, W, H, x, y, &sx, &sy);
  if (g_tx) {
    *g_tx = k * w * signf(sx - observed[0]);
    *g_ty = k * w * signf(sy - observed[1]);
  }
  return w * (fabsf(observed[0] - sx) + fabsf(observed[1] - sy));
}

/// dL/dgrey at (x, y), gathered from the neighbours' dL/d(Sobel x) and dL/d(Sobel y) (W x H arrays).
DD_HOST_DEVICE float grey_gradient(const float* g_gx, const float* g_gy, int W, int H, int x, int y) {
  float g = 0.f;
  for (int dy = -1; dy <= 1; ++dy)
    for (int dx = -1; dx <= 1; ++dx) {
      const int px = x - dx, py = y - dy;  // the neighbour whose Sobel window sees (x, y) at offset (dx, dy)
      if (px < 0 || py < 0 || px >= W || py >= H) continue;
      g += sobel_x(dx, dy) * g_gx[py * W + px] + sobel_y(dx, dy) * g_gy[py * W + px];
    }
  return g;
}

}  // namespace diffdope
