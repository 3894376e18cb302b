#pragma once
// Vertex and triangle set-up for one hypothesis: camera-space positions, pixel positions, and which triangles
// are rasterised.
#include "render/kernels/mesh_view.hpp"
#include "render/kernels/projection.hpp"

namespace diffdope {

/// Transforms and projects vertex i. Vertices behind the near plane get a pixel position but their triangles
/// are dropped by triangle_setup, so it is never used.
DD_HOST_DEVICE void vertex_setup(const MeshView& M, const RigidTransform& T, const Intrinsics& K, float near_z,
                                 int i, Vec3f* cam, Vec2f* pix) {
  const Vec3f X = transform_point(T, M.positions[i]);
  cam[i] = X;
  pix[i] = X.z > near_z ? project(K, X) : Vec2f{0.f, 0.f};
}

/// Signed pixel area of triangle `tri`, or 0 when it must not be rasterised: a vertex at or behind the near
/// plane (near-plane handling: such triangles are dropped whole, so nothing divides by z ~ 0), degenerate in
/// the image, or back-facing with culling on.
DD_HOST_DEVICE float triangle_setup(const MeshView& M, const Vec3f* cam, const Vec2f* pix, float near_z,
                                    bool cull_back_faces, int tri) {
  const int* v = M.triangles + 3 * tri;
  const Vec3f X0 = cam[v[0]], X1 = cam[v[1]], X2 = cam[v[2]];
  if (!(X0.z > near_z && X1.z > near_z && X2.z > near_z)) return 0.f;  // also rejects NaN
  if (cull_back_faces && dot(cross(X1 - X0, X2 - X0), X0) >= 0.f) return 0.f;
  const float area = 0.5f * cross2(pix[v[1]] - pix[v[0]], pix[v[2]] - pix[v[0]]);
  if (!(fabsf(area) > 1e-10f)) return 0.f;
  return area;
}

}  // namespace diffdope
