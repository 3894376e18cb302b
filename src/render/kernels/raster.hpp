#pragma once
// Triangle coverage, depth and perspective-correct barycentrics, with their backward passes.
#include "render/kernels/lanes.hpp"
#include "diffdope/vec.hpp"

namespace diffdope {

/// Watertight coverage: vertex positions snapped to 1/256 pixel and edge functions evaluated exactly in 64-bit
/// integers, so two triangles sharing an edge decide a pixel centre on it the same way (float edge functions
/// of a->b and b->a may both round below zero and leave a hole along a diagonal).
constexpr int kSubpixelBits = 8;
/// Pixel coordinates are clamped to +-1e6 before they become fixed-point (products of coordinates stay far
/// inside 64 bits; the values inside 32 bits) and to +-2^30 before they become pixel indices.
constexpr float kMaxFixedCoordinate = 1e6f;
constexpr float kMaxCoordinate = 1073741824.f;

#include "render/kernels/raster_lanes.inc"

/// Edge function of directed edge a->b at point p: (b - a) x (p - a) (edge_function_lanes()). Linear in p; zero
/// on the edge line.
DD_HOST_DEVICE float edge_function(Vec2f a, Vec2f b, Vec2f p) {
  return edge_function_lanes<ScalarLanes>(a.x, a.y, b.x, b.y, p.x, p.y);
}

/// Gradients of edge_function w.r.t. a and b (p held fixed).
DD_HOST_DEVICE void edge_function_grad(Vec2f a, Vec2f b, Vec2f p, Vec2f* d_a, Vec2f* d_b) {
  *d_a = {b.y - p.y, p.x - b.x};
  *d_b = {p.y - a.y, a.x - p.x};
}

struct FixedPoint2 {
  long long x, y;
};

/// to_fixed_lanes() of a point.
DD_HOST_DEVICE FixedPoint2 to_fixed(Vec2f p) { return {to_fixed_lanes<ScalarLanes>(p.x), to_fixed_lanes<ScalarLanes>(p.y)}; }

DD_HOST_DEVICE long long edge_function_fixed(FixedPoint2 a, FixedPoint2 b, long long px, long long py) {
  return (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x);
}

/// Top-left fill rule for pixel centres exactly on an edge, so that triangles sharing an edge never both (or
/// neither) cover a pixel: an edge counts when the interior lies below a horizontal edge or right of it.
/// `orient` = sign of the fixed-point area.
DD_HOST_DEVICE bool edge_is_top_left_fixed(FixedPoint2 a, FixedPoint2 b, long long orient) {
  const long long ex = orient * (b.x - a.x), ey = orient * (b.y - a.y);
  return (ey == 0 && ex > 0) || ey < 0;
}

/// Per-triangle set-up of the watertight z-buffer raster, shared by the CPU loop and the CUDA kernel so that
/// both decide coverage and depth bit for bit alike.
struct TriangleRaster {
  FixedPoint2 f[3];     // vertices in fixed point
  long long orient;     // sign of the fixed-point area
  long long dx[3];      // change of edge function k per pixel step in x (fixed-point units)
  long long dy[3];      // ... and per pixel step in y
  long long fill[3];    // fill rule of edge k (v_k -> v_k+1): 0 when it is top-left (a centre on it counts), else -1
  float inv2a;          // 1 / |2 area| (fixed-point units)
  float iz[3];          // 1/z of the vertex edge k weighs (edge k weighs vertex k+2): depth is linear in 1/z
  int x0, x1, y0, y1;   // pixel bounding box (inclusive, not clipped to the image)
};

/// raster_bounds_lanes() of one triangle (s: its pixel positions).
DD_HOST_DEVICE void raster_bounds(const Vec2f s[3], int* x0, int* x1, int* y0, int* y1) {
  const float sx[3] = {s[0].x, s[1].x, s[2].x}, sy[3] = {s[0].y, s[1].y, s[2].y};
  raster_bounds_lanes<ScalarLanes>(sx, sy, x0, x1, y0, y1);
}

/// s: pixel positions, z: camera depths of the three vertices; r's x0 .. y1 must hold raster_bounds(s) already
/// (the caller computes them first to skip triangles between pixel centres). False when the triangle has no
/// fixed-point area.
DD_HOST_DEVICE bool triangle_raster_setup(const Vec2f s[3], const float z[3], TriangleRaster* r) {
  constexpr long long kOne = 1LL << kSubpixelBits;
  for (int k = 0; k < 3; ++k) r->f[k] = to_fixed(s[k]);
  const long long area2 = edge_function_fixed(r->f[0], r->f[1], r->f[2].x, r->f[2].y);
  if (area2 == 0) return false;
  r->orient = area2 > 0 ? 1 : -1;
  r->inv2a = 1.f / static_cast<float>(r->orient * area2);
  r->iz[0] = 1.f / z[2];
  r->iz[1] = 1.f / z[0];
  r->iz[2] = 1.f / z[1];
  for (int k = 0; k < 3; ++k) {
    r->fill[k] = edge_is_top_left_fixed(r->f[k], r->f[(k + 1) % 3], r->orient) ? 0 : -1;
    r->dx[k] = -r->orient * (r->f[(k + 1) % 3].y - r->f[k].y) * kOne;
    r->dy[k] = r->orient * (r->f[(k + 1) % 3].x - r->f[k].x) * kOne;
  }
  return true;
}

/// The three (orientation-corrected) edge functions at pixel centre (x, y), exact integers.
DD_HOST_DEVICE void raster_edges_at(const TriangleRaster& r, int x, int y, long long e[3]) {
  constexpr long long kOne = 1LL << kSubpixelBits;
  for (int k = 0; k < 3; ++k) e[k] = r.orient * edge_function_fixed(r.f[k], r.f[(k + 1) % 3], x * kOne, y * kOne);
}

/// Narrows the row's pixels [*lo, *hi] (e: the edge functions at x = *lo) to the span the triangle's half-planes
/// can cover, by exact integer division, and moves e to the new *lo: wide triangles then skip the pixels left
/// and right of them. The per-pixel test still decides coverage (ties on an edge). False when nothing is left.
DD_HOST_DEVICE bool raster_row_span(const TriangleRaster& r, int xs, long long e[3], int* lo, int* hi) {
  if (*hi - *lo <= 8) return true;  // not worth three divisions
  for (int k = 0; k < 3; ++k) {
    if (r.dx[k] > 0 && e[k] < 0) {
      const long long first = xs + (-e[k] + r.dx[k] - 1) / r.dx[k];
      if (first > *lo) *lo = first > *hi ? *hi + 1 : static_cast<int>(first);
    } else if (r.dx[k] < 0 && e[k] >= 0) {
      const long long last = xs + e[k] / -r.dx[k];
      if (last < *hi) *hi = static_cast<int>(last);
    } else if (r.dx[k] < 0 && e[k] < 0) {
      *hi = xs - 1;
    }
  }
  if (*lo > *hi) return false;
  for (int k = 0; k < 3; ++k) e[k] += r.dx[k] * (*lo - xs);
  return true;
}

/// Whether the pixel centre with edge functions e0..e2 is covered: each e_k > 0, or = 0 on a top-left edge. The
/// edge functions are integers, so that is e_k + fill_k >= 0 for all three, one sign test of their OR (no
/// branch per edge: a small triangle's pixels are a coin toss for a branch predictor).
DD_HOST_DEVICE bool raster_inside(const TriangleRaster& r, long long e0, long long e1, long long e2) {
  return ((e0 + r.fill[0]) | (e1 + r.fill[1]) | (e2 + r.fill[2])) >= 0;
}

/// 1 / camera depth at the pixel whose edge functions are e0..e2 (1/z is linear in the image). The z-buffer
/// orders by it (nearer = larger), which spares a division per pixel.
DD_HOST_DEVICE float raster_inverse_depth(const TriangleRaster& r, long long e0, long long e1, long long e2) {
  return (float(e0) * r.iz[0] + float(e1) * r.iz[1] + float(e2) * r.iz[2]) * r.inv2a;
}

/// Backward of ray_barycentrics_lanes (shade_lanes.inc): given dL/db (g_b) and the forward's b and s, adds dL/dX_i
/// into g_X[i].
DD_HOST_DEVICE void ray_barycentrics_backward(Vec3f d, const Vec3f X[3], const float b[3], float s,
                                              const float g_b[3], Vec3f g_X[3]) {
  if (s == 0.f) return;
  // b_i = c_i / S  =>  dL/dc_i = (g_b_i - sum_m g_b_m b_m) / S
  const float mean = g_b[0] * b[0] + g_b[1] * b[1] + g_b[2] * b[2];
  const float is = 1.f / s;
  for (int i = 0; i < 3; ++i) {
    const float gc = (g_b[i] - mean) * is;
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    // c_i = d . (X_j x X_k) = X_j . (X_k x d) = X_k . (d x X_j)
    g_X[j] += gc * cross(X[k], d);
    g_X[k] += gc * cross(d, X[j]);
  }
}

/// Clamps barycentrics to the triangle (negative weights to 0, renormalised): the nearest-edge continuation
/// used when a triangle's surface is evaluated just outside it. Returns false if nothing remains.
DD_HOST_DEVICE bool clamp_barycentrics(const float b[3], float out[3]) {
  const float p0 = b[0] > 0.f ? b[0] : 0.f, p1 = b[1] > 0.f ? b[1] : 0.f, p2 = b[2] > 0.f ? b[2] : 0.f;
  const float sum = p0 + p1 + p2;
  if (!(sum > 0.f)) return false;
  out[0] = p0 / sum, out[1] = p1 / sum, out[2] = p2 / sum;
  return true;
}

/// Backward of clamp_barycentrics: turns dL/d(clamped) into dL/d(raw), in place.
DD_HOST_DEVICE void clamp_barycentrics_backward(const float b[3], const float clamped[3], float g[3]) {
  const float sum = (b[0] > 0.f ? b[0] : 0.f) + (b[1] > 0.f ? b[1] : 0.f) + (b[2] > 0.f ? b[2] : 0.f);
  const float mean = g[0] * clamped[0] + g[1] * clamped[1] + g[2] * clamped[2];
  for (int i = 0; i < 3; ++i) g[i] = b[i] > 0.f ? (g[i] - mean) / sum : 0.f;
}

}  // namespace diffdope
