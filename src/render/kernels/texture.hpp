#pragma once
// Bilinear texture lookup with its derivative w.r.t. the UV coordinate.
// UV convention as in PLY/OBJ/OpenGL (and assimp's output): u to the right, v up, (0,0) = bottom-left of the
// image; texel centres sit at half-integers. Addressing clamps to the edge.
#include "render/kernels/lanes.hpp"
#include "render/kernels/texture_view.hpp"
#include "diffdope/vec.hpp"

namespace diffdope {

/// Fractional mip level for a triangle covering `pixel_area` pixels and `texel_area` level-0 texels: the level
/// whose texels are about one pixel wide, log2(sqrt(texel_area / pixel_area)), in [0, levels - 1]. Sampling a
/// finer level would alias (texel noise instead of the filtered colour a camera sees) and miss the cache on
/// large textures. Levels are blended (trilinear), so colours do not jump when the level changes with the pose.
DD_HOST_DEVICE float mip_level(float texel_area, float pixel_area, int levels) {
  if (!(pixel_area > 0.f) || !(texel_area > pixel_area)) return 0.f;
  const float l = 0.5f * log2f(texel_area / pixel_area);
  return l > float(levels - 1) ? float(levels - 1) : l;
}

/// The lookups over a lane type (sample_bilinear_lanes, sample_trilinear_lanes).
#include "render/kernels/texture_lanes.inc"

/// Samples tex at uv. If d_du / d_dv are non-null they receive d(colour)/du and d(colour)/dv.
DD_HOST_DEVICE Vec3f sample_bilinear(const TextureLevelView& tex, Vec2f uv, Vec3f* d_du, Vec3f* d_dv) {
  float c[3], du[3], dv[3];
  sample_bilinear_lanes<ScalarLanes>(tex, uv.x, uv.y, c, du, dv);
  if (d_du) *d_du = {du[0], du[1], du[2]};
  if (d_dv) *d_dv = {dv[0], dv[1], dv[2]};
  return {c[0], c[1], c[2]};
}

/// Trilinear lookup: bilinear in the two levels around `level`, blended (sample_trilinear_lanes).
DD_HOST_DEVICE Vec3f sample_trilinear(const TextureView& tex, float level, Vec2f uv, Vec3f* d_du, Vec3f* d_dv) {
  float c[3], du[3], dv[3];
  sample_trilinear_lanes<ScalarLanes>(&tex, 0, level, uv.x, uv.y, c, du, dv);
  if (d_du) *d_du = {du[0], du[1], du[2]};
  if (d_dv) *d_dv = {dv[0], dv[1], dv[2]};
  return {c[0], c[1], c[2]};
}

}  // namespace diffdope
