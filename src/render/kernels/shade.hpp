#pragma once
// Per-pixel shading (colour and depth of a triangle's surface at a pixel centre) and its backward pass to the
// 6-D pose gradient. `clamp` evaluates the surface at the nearest point of the triangle when the pixel centre
// lies outside it (used by the discontinuity blends).
#include "render/kernels/mesh_view.hpp"
#include "render/kernels/projection.hpp"
#include "render/kernels/raster.hpp"

namespace diffdope {

/// The shading over a lane type (ray_barycentrics_lanes, shade_surface_lanes).
#include "render/kernels/shade_lanes.inc"

namespace detail {
/// Barycentrics used for shading (raw or clamped) plus what the backward pass needs: the texture's derivatives
/// at the sampled UV (kept by the forward pass, so the backward pass does not sample the texture again).
struct ShadeBary {
  float raw[3], b[3], s;
  bool clamped;
  Vec3f dcdu, dcdv;
};
DD_HOST_DEVICE ShadeBary shade_barycentrics(Vec3f d, const Vec3f X[3], bool clamp) {
  ShadeBary r;
  const float dv[3] = {d.x, d.y, d.z};
  const float X0[3] = {X[0].x, X[0].y, X[0].z}, X1[3] = {X[1].x, X[1].y, X[1].z}, X2[3] = {X[2].x, X[2].y, X[2].z};
  r.s = ray_barycentrics_lanes<ScalarLanes>(dv, X0, X1, X2, r.raw);
  r.clamped = clamp && (r.raw[0] < 0.f || r.raw[1] < 0.f || r.raw[2] < 0.f) && clamp_barycentrics(r.raw, r.b);
  if (!r.clamped) r.b[0] = r.raw[0], r.b[1] = r.raw[1], r.b[2] = r.raw[2];
  r.dcdu = r.dcdv = Vec3f{0.f, 0.f, 0.f};
  return r;
}
}  // namespace detail

/// Colour and camera-space depth of triangle `tri` seen through pixel centre (px, py). `bary_out` (optional)
/// receives the barycentrics, so the backward pass need not recompute them.
DD_HOST_DEVICE void shade_pixel(const MeshView& M, const ProjectedView& G, const Intrinsics& K, int tri, float px,
                                float py, Vec3f* colour, float* depth, bool clamp = false,
                                detail::ShadeBary* bary_out = nullptr) {
  const int* v = M.triangles + 3 * tri;
  const Vec3f X[3] = {G.cam[v[0]], G.cam[v[1]], G.cam[v[2]]};
  detail::ShadeBary sb = detail::shade_barycentrics(pixel_ray(K, px, py), X, clamp);
  const int vi[3] = {v[0], v[1], v[2]};
  const float z[3] = {X[0].z, X[1].z, X[2].z};
  float c[3], du[3], dv[3];
  shade_surface_lanes<ScalarLanes>(M, G, tri, vi, sb.b, z, depth, c, du, dv);
  *colour = Vec3f{c[0], c[1], c[2]};
  if (bary_out) {
    sb.dcdu = Vec3f{du[0], du[1], du[2]};
    sb.dcdv = Vec3f{dv[0], dv[1], dv[2]};
    *bary_out = sb;
  }
}

/// Backward of shade_pixel: given dL/dcolour and dL/ddepth, accumulates dL/d(pose update) into grad6.
/// `bary` (optional): the forward pass's barycentrics for this pixel and triangle.
template <typename Acc>
DD_HOST_DEVICE void shade_pixel_backward(const MeshView& M, const ProjectedView& G, const Intrinsics& K, int tri,
                                         float px, float py, Vec3f g_colour, float g_depth, Acc* grad6,
                                         bool clamp = false, const detail::ShadeBary* bary = nullptr) {
  const int* v = M.triangles + 3 * tri;
  const Vec3f X[3] = {G.cam[v[0]], G.cam[v[1]], G.cam[v[2]]};
  const Vec3f d = pixel_ray(K, px, py);
  const detail::ShadeBary sb = bary ? *bary : detail::shade_barycentrics(d, X, clamp);
  if (sb.s == 0.f) return;
  const float* b = sb.b;
  float g_b[3];
  Vec3f g_X[3] = {{0.f, 0.f, g_depth * b[0]}, {0.f, 0.f, g_depth * b[1]}, {0.f, 0.f, g_depth * b[2]}};
  const int tex = M.tri_texture[tri];
  if (tex >= 0 && M.uvs) {
    Vec3f dcdu = sb.dcdu, dcdv = sb.dcdv;
    if (!bary) {
      const Vec2f uv = b[0] * M.uvs[v[0]] + b[1] * M.uvs[v[1]] + b[2] * M.uvs[v[2]];
      sample_trilinear(M.textures[tex], G.tri_level[tri], uv, &dcdu, &dcdv);
    }
    const float gu = dot(g_colour, dcdu), gv = dot(g_colour, dcdv);
    for (int i = 0; i < 3; ++i) g_b[i] = gu * M.uvs[v[i]].x + gv * M.uvs[v[i]].y + g_depth * X[i].z;
  } else {
    for (int i = 0; i < 3; ++i) g_b[i] = dot(g_colour, M.colors[v[i]]) + g_depth * X[i].z;
  }
  if (sb.clamped) clamp_barycentrics_backward(sb.raw, sb.b, g_b);
  ray_barycentrics_backward(d, X, sb.raw, sb.s, g_b, g_X);
  for (int i = 0; i < 3; ++i) accumulate_pose_gradient(X[i], g_X[i], grad6);
}

}  // namespace diffdope
