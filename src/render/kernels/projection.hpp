#pragma once
// Rigid transform and pinhole projection, with the Jacobians the backward pass needs.
// Frame: OpenCV optical (x right, y down, z forward); integer pixel coordinates are pixel centres.
#include "diffdope/vec.hpp"

namespace diffdope {

/// Pinhole intrinsics as plain floats for kernels (the host-side type is diffdope::Camera).
struct Intrinsics {
  float fx, fy, cx, cy;
  int width, height;
};

/// Row-major rotation + translation (model -> camera), plain floats for kernels.
struct RigidTransform {
  float r[9];
  float t[3];
};

DD_HOST_DEVICE Vec3f transform_point(const RigidTransform& T, Vec3f p) {
  return {T.r[0] * p.x + T.r[1] * p.y + T.r[2] * p.z + T.t[0],
          T.r[3] * p.x + T.r[4] * p.y + T.r[5] * p.z + T.t[1],
          T.r[6] * p.x + T.r[7] * p.y + T.r[8] * p.z + T.t[2]};
}

/// Pixel position of a camera-space point (z > 0 assumed by the caller).
DD_HOST_DEVICE Vec2f project(const Intrinsics& K, Vec3f X) {
  const float iz = 1.f / X.z;
  return {K.fx * X.x * iz + K.cx, K.fy * X.y * iz + K.cy};
}

/// Chain rule through project(): given dL/dpixel, returns dL/dX.
DD_HOST_DEVICE Vec3f project_backward(const Intrinsics& K, Vec3f X, Vec2f g_pix) {
  const float iz = 1.f / X.z;
  const float gu = g_pix.x * K.fx * iz;
  const float gv = g_pix.y * K.fy * iz;
  return {gu, gv, -(gu * X.x + gv * X.y) * iz};
}

/// Viewing ray through pixel centre (px, py), scaled so that its z component is 1.
DD_HOST_DEVICE Vec3f pixel_ray(const Intrinsics& K, float px, float py) {
  return {(px - K.cx) / K.fx, (py - K.cy) / K.fy, 1.f};
}

/// 6-D pose gradient layout: [0..2] translation (dL/drho, per metre), [3..5] rotation (dL/dphi, per radian)
/// of the left update X' = X + rho + phi x X (first order of exp(delta) * T, camera frame).
/// Accumulates the contribution of a camera-space point's gradient g (dL/dX) into grad6.
template <typename Acc>
DD_HOST_DEVICE void accumulate_pose_gradient(Vec3f X, Vec3f g, Acc* grad6) {
  grad6[0] += g.x;
  grad6[1] += g.y;
  grad6[2] += g.z;
  const Vec3f m = cross(X, g);  // d(g . (phi x X))/dphi = X x g
  grad6[3] += m.x;
  grad6[4] += m.y;
  grad6[5] += m.z;
}

}  // namespace diffdope
