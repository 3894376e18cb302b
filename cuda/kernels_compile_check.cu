// Compiles every shared DD_HOST_DEVICE function of src/render/kernels/ as CUDA device code, one pixel or
// vertex per thread, in the shape the CUDA backend will launch them. Nothing here is run yet (the CUDA backend
// is its own issue); building it proves that the maths the CPU backend runs and tests stays device-compatible.
#include "render/kernels/edges.hpp"
#include "render/kernels/pixel_loss.hpp"
#include "render/kernels/shade.hpp"
#include "render/kernels/silhouette.hpp"
#include "render/kernels/vertex_stage.hpp"

namespace diffdope {
namespace cuda_check {

__global__ void vertex_kernel(MeshView M, RigidTransform T, Intrinsics K, float near_z, Vec3f* cam, Vec2f* pix) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < M.num_vertices) vertex_setup(M, T, K, near_z, i, cam, pix);
}

__global__ void triangle_kernel(MeshView M, const Vec3f* cam, const Vec2f* pix, float near_z, bool cull,
                                float* area, float* level) {
  const int t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= M.num_triangles) return;
  area[t] = triangle_setup(M, cam, pix, near_z, cull, t);
  level[t] = triangle_mip_level(M, t, area[t]);
}

__global__ void shade_loss_kernel(MeshView M, ProjectedView G, Intrinsics K, PixelLossParams P, const int* tri,
                                  const float* S, const float* I, const float* Id, int W, int H, PixelAttr* attr,
                                  PixelLossGrad* grad, float* value) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= W * H) return;
  const int x = i % W, y = i / W;
  PixelAttr a{0.f, {0.f, 0.f, 0.f}, 0.f};
  if (tri[i] >= 0) {
    Vec3f c;
    float d;
    shade_pixel(M, G, K, tri[i], float(x), float(y), &c, &d);
    a = PixelAttr{1.f, {c.x, c.y, c.z}, d};
  }
  attr[i] = a;
  const PixelLossValue v = pixel_loss(P, S[i], I + 3 * i, Id[i], Id[i] > 0.f, a.cov, a.c, a.d, &grad[i]);
  value[i] = v.rgb + v.depth + v.mask;
}

__global__ void blend_kernel(MeshView M, ProjectedView G, Intrinsics K, const int* tri, const PixelAttr* pre,
                             int W, int H, BlendEvent* events, int* has_event) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= W * H) return;
  const int x = i % W, y = i / W;
  has_event[i] = 0;
  if (x + 1 < W)
    has_event[i] = discontinuity_blend(M, G, K, i, tri[i], pre[i].d, Vec2f{float(x), float(y)}, i + 1, tri[i + 1],
                                       pre[i + 1].d, Vec2f{float(x + 1), float(y)}, true, &events[i]);
}

__global__ void backward_kernel(MeshView M, ProjectedView G, Intrinsics K, const int* tri, const BlendEvent* events,
                                const int* has_event, const PixelAttr* pre, const PixelAttr* g_post, int W, int H,
                                float* grad6_per_pixel) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= W * H) return;
  float g6[6] = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
  PixelAttr g_to = g_post[i];
  if (has_event[i]) blend_backward(M, G, K, events[i], pre[events[i].to], g_post[events[i].to], &g_to, g6);
  if (tri[i] >= 0)
    shade_pixel_backward(M, G, K, tri[i], float(i % W), float(i / W), Vec3f{g_to.c[0], g_to.c[1], g_to.c[2]},
                         g_to.d, g6);
  for (int k = 0; k < 6; ++k) grad6_per_pixel[6 * i + k] = g6[k];
}

__global__ void edge_kernel(const float* grey, const float* g_gx, const float* g_gy, int W, int H, float scale,
                            float* e, float* g_grey) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= W * H) return;
  float gx, gy, a, b;
  e[i] = edge_value(grey, W, H, i % W, i / W, scale, &gx, &gy);
  edge_value_backward(gx, gy, scale, 1.f, &a, &b);
  g_grey[i] = grey_gradient(g_gx, g_gy, W, H, i % W, i / W) + a + b;
}

}  // namespace cuda_check
}  // namespace diffdope
