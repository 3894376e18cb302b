#pragma once
// Discontinuity detection between two neighbouring pixels and the blend (antialias) it implies, plus the
// backward pass of that blend to the pose. Geometry of the blend: see antialias.hpp.
//
// Two kinds of discontinuity edges are blended: silhouettes (coverage, colour and depth jump: a border, an
// edge to a triangle that is not drawn, or a fold) and seams inside the visible surface (colour jumps where
// the UVs, texture or colours of two triangles differ, e.g. box creases). The side that receives the blend
// takes the other side's surface evaluated at its own pixel centre (barycentrics clamped to that triangle),
// so nothing jumps when a pixel centre crosses the edge: the loss stays continuous in the pose.
#include "render/kernels/antialias.hpp"
#include "render/kernels/shade.hpp"

namespace diffdope {

/// Most triangles the search crosses between two neighbouring pixel centres.
constexpr int kMaxSilhouetteWalk = 16;

/// Render attributes of one pixel, premultiplied by coverage so that blends are linear.
struct PixelAttr {
  float cov;   // coverage in [0, 1]
  float c[3];  // coverage * colour
  float d;     // coverage * camera-space depth (metres)
};

/// One blend: pixel `to` moves w of the way towards `from` (surface src_tri at to's centre, or empty).
struct BlendEvent {
  int to;           // pixel index (caller's layout)
  float w;          // blend weight in [0, 0.5]
  float dw_dt;      // +1 (near side spills out) or -1 (far side spills in)
  int tri, edge;    // the triangle owning the discontinuity edge, and the edge (k: v_k -> v_k+1)
  int src_tri;      // triangle whose surface is blended in, -1 = background (nothing)
  Vec2f pf, po;     // pixel centres: near-side pixel and its neighbour (the crossing is on pf -> po)
  Vec2f p_to;       // centre of pixel `to`
  PixelAttr from;   // blended-in attributes (forward value, kept for the backward pass)
  detail::ShadeBary src_bary;  // src_tri's barycentrics and texture derivatives at p_to (for the backward pass)
};

/// Attributes of triangle `tri` at pixel centre p, barycentrics clamped to the triangle (no extrapolation);
/// `bary` receives what shade_pixel_backward needs of them.
DD_HOST_DEVICE PixelAttr surface_attr(const MeshView& M, const ProjectedView& G, const Intrinsics& K, int tri,
                                      Vec2f p, detail::ShadeBary* bary) {
  if (tri < 0) return PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f};
  Vec3f c;
  float d;
  shade_pixel(M, G, K, tri, p.x, p.y, &c, &d, true, bary);
  return PixelAttr{1.f, {c.x, c.y, c.z}, d};
}

#include "render/kernels/silhouette_lanes.inc"

/// The blend a walk found (silhouette_walk_lanes: edge k of triangle C, crossed at t along pf -> po), given the
/// pair: the near side's pixel f (index idx_f) and the other, o (idx_o, its triangle tri_o, -1 = none).
DD_HOST_DEVICE void blend_at_crossing(const MeshView& M, const ProjectedView& G, const Intrinsics& K, int idx_f,
                                      Vec2f pf, int idx_o, int tri_o, Vec2f po, int C, int k, float t,
                                      BlendEvent* ev) {
  if (t > 0.5f) {  // the near side's surface (C, continued to o's centre) covers part of o
    *ev = BlendEvent{idx_o, t - 0.5f, 1.f, C, k, C, pf, po, po, {}, {}};
    ev->from = surface_attr(M, G, K, C, po, &ev->src_bary);
  } else {  // what o shows (its own surface continued to f's centre, or background) covers part of f
    *ev = BlendEvent{idx_f, 0.5f - t, -1.f, C, k, tri_o, pf, po, pf, {}, {}};
    ev->from = surface_attr(M, G, K, tri_o, pf, &ev->src_bary);
  }
}

/// The near side of a pair of neighbouring pixels a and b with different triangles (tri_* = -1: not covered;
/// z_* = depth): a when b is empty or a is nearer.
DD_HOST_DEVICE bool a_in_front(int tri_a, float z_a, int tri_b, float z_b) {
  return tri_b < 0 || (tri_a >= 0 && z_a <= z_b);
}

/// Decides whether pixels a and b (neighbours; `horizontal` = a is left of b, else a is above b) straddle a
/// discontinuity edge, and fills the blend event if so (nothing written otherwise). tri_* = -1 means not
/// covered; z_* = depth.
DD_HOST_DEVICE bool discontinuity_blend(const MeshView& M, const ProjectedView& G, const Intrinsics& K, int idx_a,
                                        int tri_a, float z_a, Vec2f pa, int idx_b, int tri_b, float z_b, Vec2f pb,
                                        bool horizontal, BlendEvent* ev) {
  if (tri_a == tri_b) return false;
  const bool a_front = a_in_front(tri_a, z_a, tri_b, z_b);
  const Vec2f pf = a_front ? pa : pb, po = a_front ? pb : pa;
  const int tri_o = a_front ? tri_b : tri_a;
  // Small triangles make a walk across the surface necessary: the edge between the two centres may belong to
  // a triangle neither of them lies in.
  int C, k;
  float t;
  bool unfinished;
  if (!silhouette_walk_lanes<ScalarLanes>(M, G, a_front ? tri_a : tri_b, tri_o, pf.x, pf.y, po.x, po.y, true,
                                          horizontal, 0, kMaxSilhouetteWalk, &C, &k, &t, &unfinished))
    return false;
  blend_at_crossing(M, G, K, a_front ? idx_a : idx_b, pf, a_front ? idx_b : idx_a, tri_o, po, C, k, t, ev);
  return true;
}

/// Applies a blend to the accumulated output: out_to += w * (from - to), with `to` the pre-blend attributes.
DD_HOST_DEVICE void apply_blend(const BlendEvent& e, const PixelAttr& to, PixelAttr* out_to) {
  out_to->cov += e.w * (e.from.cov - to.cov);
  for (int ch = 0; ch < 3; ++ch) out_to->c[ch] += e.w * (e.from.c[ch] - to.c[ch]);
  out_to->d += e.w * (e.from.d - to.d);
}

/// Backward of a blend. g_out_to = dL/d(blended `to`). Adds dL/d(pre-blend `to`) into g_to, and the pose
/// gradient of the blended-in surface and of the edge position (the silhouette gradient) into grad6.
template <typename Acc>
DD_HOST_DEVICE void blend_backward(const MeshView& M, const ProjectedView& G, const Intrinsics& K,
                                   const BlendEvent& e, const PixelAttr& to, const PixelAttr& g_out_to,
                                   PixelAttr* g_to, Acc* grad6) {
  float g_w = g_out_to.cov * (e.from.cov - to.cov) + g_out_to.d * (e.from.d - to.d);
  for (int ch = 0; ch < 3; ++ch) g_w += g_out_to.c[ch] * (e.from.c[ch] - to.c[ch]);
  g_to->cov -= e.w * g_out_to.cov;
  g_to->d -= e.w * g_out_to.d;
  for (int ch = 0; ch < 3; ++ch) g_to->c[ch] -= e.w * g_out_to.c[ch];
  if (e.src_tri >= 0) {
    const Vec3f gc{e.w * g_out_to.c[0], e.w * g_out_to.c[1], e.w * g_out_to.c[2]};
    shade_pixel_backward(M, G, K, e.src_tri, e.p_to.x, e.p_to.y, gc, e.w * g_out_to.d, grad6, true, &e.src_bary);
  }
  if (g_w == 0.f) return;
  const int* v = M.triangles + 3 * e.tri;
  const int ia = v[e.edge], ib = v[(e.edge + 1) % 3];
  Vec2f g_a{0.f, 0.f}, g_b{0.f, 0.f};
  crossing_backward(G.pix[ia], G.pix[ib], e.pf, e.po, g_w * e.dw_dt, &g_a, &g_b);
  accumulate_pose_gradient(G.cam[ia], project_backward(K, G.cam[ia], g_a), grad6);
  accumulate_pose_gradient(G.cam[ib], project_backward(K, G.cam[ib], g_b), grad6);
}

}  // namespace diffdope
