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
#include "diffdope/kernels/raster.hpp"

namespace diffdope {

/// Which edge of triangle s[3] (edge k: s[k] -> s[k+1]) the line pf -> po leaves it through before reaching
/// po, or -1 when po is inside. Each edge whose function decreases along the segment bounds it from above at
/// t_k = ef / (ef - eo); the exit is the smallest such bound. Works for triangles that do not contain pf too
/// (walking across a surface). `orient` = sign of the triangle's signed area.
DD_HOST_DEVICE int exit_edge(const Vec2f s[3], float orient, Vec2f pf, Vec2f po, float* t_out) {
  int best = -1;
  float best_t = 2.f;
  for (int k = 0; k < 3; ++k) {
    const Vec2f a = s[k], b = s[(k + 1) % 3];
    const float ef = orient * edge_function(a, b, pf);
    const float eo = orient * edge_function(a, b, po);
    if (eo < 0.f && eo < ef) {
      const float t = ef / (ef - eo);
      if (t < best_t) {
        best_t = t;
        best = k;
      }
    }
  }
  *t_out = best_t;
  return best;
}

/// True when edge a->b is a contour between triangles whose third vertices are opp_f and opp_n: the surface
/// folds over (both on the same side of the edge line). Independent of winding, so inconsistently wound
/// meshes do not produce false silhouettes.
DD_HOST_DEVICE bool is_fold(Vec2f a, Vec2f b, Vec2f opp_f, Vec2f opp_n) {
  return edge_function(a, b, opp_f) * edge_function(a, b, opp_n) >= 0.f;
}

/// True when the edge should be antialiased along a horizontal (or vertical) pixel pair.
DD_HOST_DEVICE bool edge_matches_pair_direction(Vec2f a, Vec2f b, bool horizontal_pair) {
  const float dx = fabsf(b.x - a.x), dy = fabsf(b.y - a.y);
  return horizontal_pair ? dy >= dx : dx > dy;
}

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
