#pragma once
// Bilinear texture lookup with its derivative w.r.t. the UV coordinate.
// UV convention as in PLY/OBJ/OpenGL (and assimp's output): u to the right, v up, (0,0) = bottom-left of the
// image; texel centres sit at half-integers. Addressing clamps to the edge.
#include "diffdope/kernels/vec.hpp"

namespace diffdope {

/// Read-only view of one RGB float image, row 0 = top image row, 3 floats per texel in [0, 1].
struct TextureLevelView {
  const float* rgb;
  int width, height;
};

/// A texture with its mip pyramid (level 0 = full size, each next level half the size).
constexpr int kMaxTextureLevels = 16;
struct TextureView {
  TextureLevelView level[kMaxTextureLevels];
  int levels;
};

/// Fractional mip level for a triangle covering `pixel_area` pixels and `texel_area` level-0 texels: the level
/// whose texels are about one pixel wide, log2(sqrt(texel_area / pixel_area)), in [0, levels - 1]. Sampling a
/// finer level would alias (texel noise instead of the filtered colour a camera sees) and miss the cache on
/// large textures. Levels are blended (trilinear), so colours do not jump when the level changes with the pose.
DD_HOST_DEVICE float mip_level(float texel_area, float pixel_area, int levels) {
  if (!(pixel_area > 0.f) || !(texel_area > pixel_area)) return 0.f;
  const float l = 0.5f * log2f(texel_area / pixel_area);
  return l > float(levels - 1) ? float(levels - 1) : l;
}

/// Samples tex at uv. If d_du / d_dv are non-null they receive d(colour)/du and d(colour)/dv.
DD_HOST_DEVICE Vec3f sample_bilinear(const TextureLevelView& tex, Vec2f uv, Vec3f* d_du, Vec3f* d_dv) {
  // Clamping to one texel beyond the border changes nothing (addressing clamps) and keeps the int casts safe.
  const float x = clampf(uv.x * tex.width - 0.5f, -1.f, float(tex.width));
  const float y = clampf((1.f - uv.y) * tex.height - 0.5f, -1.f, float(tex.height));
  int x0i = static_cast<int>(x), y0i = static_cast<int>(y);  // floor without a libm call (hot path)
  x0i -= float(x0i) > x;
  y0i -= float(y0i) > y;
  const float fx = x - float(x0i), fy = y - float(y0i);
  const int x0 = x0i < 0 ? 0 : (x0i >= tex.width ? tex.width - 1 : x0i);
  const int x1 = x0i + 1 < 0 ? 0 : (x0i + 1 >= tex.width ? tex.width - 1 : x0i + 1);
  const int y0 = y0i < 0 ? 0 : (y0i >= tex.height ? tex.height - 1 : y0i);
  const int y1 = y0i + 1 < 0 ? 0 : (y0i + 1 >= tex.height ? tex.height - 1 : y0i + 1);
  const float* p00 = tex.rgb + 3 * (y0 * tex.width + x0);
  const float* p01 = tex.rgb + 3 * (y0 * tex.width + x1);
  const float* p10 = tex.rgb + 3 * (y1 * tex.width + x0);
  const float* p11 = tex.rgb + 3 * (y1 * tex.width + x1);
  float c[3], gx[3], gy[3];
  for (int ch = 0; ch < 3; ++ch) {
    const float top = p00[ch] + fx * (p01[ch] - p00[ch]);
    const float bot = p10[ch] + fx * (p11[ch] - p10[ch]);
    c[ch] = top + fy * (bot - top);
    gx[ch] = (1.f - fy) * (p01[ch] - p00[ch]) + fy * (p11[ch] - p10[ch]);
    gy[ch] = bot - top;
  }
  // Clamped addressing is flat outside the texture: no derivative there.
  const float sx = (x0i < 0 || x0i + 1 >= tex.width) ? 0.f : 1.f;
  const float sy = (y0i < 0 || y0i + 1 >= tex.height) ? 0.f : 1.f;
  if (d_du) *d_du = {sx * gx[0] * tex.width, sx * gx[1] * tex.width, sx * gx[2] * tex.width};
  if (d_dv) *d_dv = {-sy * gy[0] * tex.height, -sy * gy[1] * tex.height, -sy * gy[2] * tex.height};
  return {c[0], c[1], c[2]};
}

/// Trilinear lookup: bilinear in the two levels around `level`, blended. The blend weight's own dependence on
/// the pose is not differentiated (it follows the triangle's size, a slow effect).
DD_HOST_DEVICE Vec3f sample_trilinear(const TextureView& tex, float level, Vec2f uv, Vec3f* d_du, Vec3f* d_dv) {
  const int l0 = static_cast<int>(level);
  const int l1 = l0 + 1 < tex.levels ? l0 + 1 : l0;
  const float f = level - float(l0);
  if (f <= 0.f || l1 == l0) return sample_bilinear(tex.level[l0], uv, d_du, d_dv);
  Vec3f du0, dv0, du1, dv1;
  const bool grad = d_du != nullptr;
  const Vec3f c0 = sample_bilinear(tex.level[l0], uv, grad ? &du0 : nullptr, grad ? &dv0 : nullptr);
  const Vec3f c1 = sample_bilinear(tex.level[l1], uv, grad ? &du1 : nullptr, grad ? &dv1 : nullptr);
  if (grad) {
    *d_du = (1.f - f) * du0 + f * du1;
    *d_dv = (1.f - f) * dv0 + f * dv1;
  }
  return (1.f - f) * c0 + f * c1;
}

}  // namespace diffdope
