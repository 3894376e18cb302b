#pragma once
// Kernels written over a lane type: the same source runs one pixel at a time (ScalarLanes: a float, a bool; the
// CUDA kernels and the CPU's leftovers) and many pixels at once (src/core/simd_lanes.hpp: Highway vectors, the
// CPU's rows). A kernel uses only what a lane type provides below, and in place of a branch on a per-pixel
// condition it computes both sides and keeps one with select(): `x = select(m, x - y, x)` leaves x exactly as a
// skipped `if (m) x -= y` does, so both instantiations give the same bits per pixel.
#include <cmath>

#include "diffdope/kernels/host_device.hpp"

namespace diffdope {

struct ScalarLanes {
  using V = float;
  using M = bool;
  DD_HOST_DEVICE static V set(float x) { return x; }
  DD_HOST_DEVICE static V zero() { return 0.f; }
  DD_HOST_DEVICE static V abs(V a) { return fabsf(a); }
  DD_HOST_DEVICE static M lt(V a, V b) { return a < b; }
  DD_HOST_DEVICE static M gt(V a, V b) { return a > b; }
  DD_HOST_DEVICE static M both(M a, M b) { return a && b; }
  DD_HOST_DEVICE static M negate(M a) { return !a; }
  DD_HOST_DEVICE static V select(M m, V a, V b) { return m ? a : b; }
  /// +1, -1 or 0 (NaN: 0).
  DD_HOST_DEVICE static V sign(V a) { return a > 0.f ? 1.f : (a < 0.f ? -1.f : 0.f); }
};

}  // namespace diffdope
