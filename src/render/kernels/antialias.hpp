#pragma once
// Analytic silhouette antialiasing and its gradient (the idea of nvdiffrast's antialias op, our own code).
//
// For two neighbouring pixel centres f (covered by the nearer triangle F) and o (its neighbour), if the
// segment f->o leaves F through a silhouette edge at fraction t (0 at f, 1 at o), a 1-pixel box filter along
// that segment says: when t > 0.5 the foreground spills into o by (t - 0.5); when t < 0.5 the background
// spills into f by (0.5 - t). The blended pixel is x' = x + w (x_other - x). Because t is a ratio of edge
// functions it is differentiable w.r.t. the edge's end points: that is the silhouette (visibility) gradient
// without which the mask term has none. Only edges more perpendicular to the pair's direction are used
// (steep edges for horizontal pairs, flat ones for vertical pairs) so that each edge counts once and the
// area gradient equals the edge's swept area.
#include "render/kernels/raster.hpp"

namespace diffdope {

/// Backward of t = ef / (ef - eo) (edge functions of a->b at pf and po): adds dL/da, dL/db given dL/dt.
DD_HOST_DEVICE void crossing_backward(Vec2f a, Vec2f b, Vec2f pf, Vec2f po, float g_t, Vec2f* g_a, Vec2f* g_b) {
  const float ef = edge_function(a, b, pf);
  const float eo = edge_function(a, b, po);
  const float den = ef - eo;
  if (den == 0.f) return;
  const float inv2 = 1.f / (den * den);
  const float dt_def = -eo * inv2, dt_deo = ef * inv2;  // (orientation sign cancels in the ratio)
  Vec2f fa, fb, oa, ob;
  edge_function_grad(a, b, pf, &fa, &fb);
  edge_function_grad(a, b, po, &oa, &ob);
  *g_a = *g_a + (g_t * dt_def) * fa + (g_t * dt_deo) * oa;
  *g_b = *g_b + (g_t * dt_def) * fb + (g_t * dt_deo) * ob;
}

}  // namespace diffdope
