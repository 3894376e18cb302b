#pragma once
// Kernels written over a lane type: the same source runs one pixel at a time (ScalarLanes: a float, an int, a
// bool; the CUDA kernels and the CPU's leftovers) and many pixels at once (src/render/simd_rows.cpp: Highway
// vectors, the CPU's rows). A kernel uses only what a lane type provides below, and in place of a branch on a
// per-pixel condition it computes both sides and keeps one with select(): `x = select(m, x - y, x)` leaves x
// exactly as a skipped `if (m) x -= y` does, so both instantiations give the same bits per pixel. any(m) lets a
// kernel skip work no lane needs (for one pixel: the branch itself).
//
// Memory: gather() reads base[index] per lane. Textures are read through level(), one mip level of one texture
// per lane, and texel(), the RGB texel at an index of that level.
#include <cmath>

#include "diffdope/host_device.hpp"
#include "render/kernels/texture_view.hpp"

namespace diffdope {

struct ScalarLanes {
  using V = float;
  using I = int;
  using M = bool;
  DD_HOST_DEVICE static V set(float x) { return x; }
  DD_HOST_DEVICE static V zero() { return 0.f; }
  DD_HOST_DEVICE static V abs(V a) { return fabsf(a); }
  DD_HOST_DEVICE static M lt(V a, V b) { return a < b; }
  DD_HOST_DEVICE static M gt(V a, V b) { return a > b; }
  DD_HOST_DEVICE static M le(V a, V b) { return a <= b; }
  DD_HOST_DEVICE static M eq(V a, V b) { return a == b; }
  DD_HOST_DEVICE static M both(M a, M b) { return a && b; }
  DD_HOST_DEVICE static M either(M a, M b) { return a || b; }
  DD_HOST_DEVICE static M negate(M a) { return !a; }
  DD_HOST_DEVICE static bool any(M a) { return a; }
  /// Every lane b.
  DD_HOST_DEVICE static M uniform(bool b) { return b; }
  DD_HOST_DEVICE static V select(M m, V a, V b) { return m ? a : b; }
  /// +1, -1 or 0 (NaN: 0).
  DD_HOST_DEVICE static V sign(V a) { return a > 0.f ? 1.f : (a < 0.f ? -1.f : 0.f); }

  DD_HOST_DEVICE static I seti(int x) { return x; }
  DD_HOST_DEVICE static M lti(I a, I b) { return a < b; }
  DD_HOST_DEVICE static M eqi(I a, I b) { return a == b; }
  DD_HOST_DEVICE static I ori(I a, I b) { return a | b; }
  DD_HOST_DEVICE static I selecti(M m, I a, I b) { return m ? a : b; }
  DD_HOST_DEVICE static V to_float(I a) { return float(a); }
  /// Rounds toward zero; the caller keeps a within the int range.
  DD_HOST_DEVICE static I truncate(V a) { return static_cast<int>(a); }
  /// Rounds to nearest, ties to even (the default rounding mode); the caller keeps a within the int range.
  DD_HOST_DEVICE static I round(V a) { return static_cast<int>(lrintf(a)); }

  DD_HOST_DEVICE static V gather(const float* base, I i) { return base[i]; }
  DD_HOST_DEVICE static I gather(const int* base, I i) { return base[i]; }
  DD_HOST_DEVICE static I gather(const unsigned char* base, I i) { return base[i]; }

  using Level = TextureLevelView;
  DD_HOST_DEVICE static Level level(const TextureView* textures, I tex, I lv) { return textures[tex].level[lv]; }
  DD_HOST_DEVICE static I levels(const TextureView* textures, I tex) { return textures[tex].levels; }
  DD_HOST_DEVICE static I width(const Level& l) { return l.width; }
  DD_HOST_DEVICE static I height(const Level& l) { return l.height; }
  DD_HOST_DEVICE static void texel(const Level& l, I i, V rgb[3]) {
    const float* p = l.rgb + 3 * i;
    rgb[0] = p[0], rgb[1] = p[1], rgb[2] = p[2];
  }
};

/// Helpers every lane type shares (clamp_lanes, floor_lanes, ceil_lanes).
#include "render/kernels/lane_math.inc"

}  // namespace diffdope
