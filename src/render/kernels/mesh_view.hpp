#pragma once
// Plain-pointer view of a Mesh for kernels (host memory for the CPU backend, device memory for CUDA).
#include "render/kernels/texture.hpp"

namespace diffdope {

struct MeshView {
  const Vec3f* positions;    // model frame, metres
  const Vec2f* uvs;          // per vertex, or nullptr
  const Vec3f* colors;       // per vertex RGB in [0, 1] (always present)
  const int* triangles;      // 3 vertex indices per triangle
  const int* tri_texture;    // per triangle texture index, -1 = vertex colours
  const int* neighbors;      // 3 per triangle: triangle across edge k (v_k -> v_k+1), -1 = border
  const int* opposite;       // 3 per triangle: the neighbour's vertex opposite edge k
  const unsigned char* seams;  // 3 per triangle: 1 where UVs, texture or colours jump across edge k
  const TextureView* textures;
  const float* tri_uv_area;  // per triangle: area in UV units (0 when untextured)
  int num_vertices, num_triangles, num_textures;
};

/// Per-hypothesis geometry after the vertex stage: camera-space and pixel positions of every vertex, and for
/// every triangle its signed pixel area (0 = not rasterised: behind the near plane, degenerate or culled) and
/// the mip level its texture is sampled at.
struct ProjectedView {
  const Vec3f* cam;
  const Vec2f* pix;
  const float* tri_area;
  const float* tri_level;  // fractional mip level of the triangle's texture
};

/// Mip level of triangle `tri` for its current pixel area.
DD_HOST_DEVICE float triangle_mip_level(const MeshView& M, int tri, float pixel_area) {
  const int tex = M.tri_texture[tri];
  if (tex < 0) return 0.f;
  const TextureLevelView& l0 = M.textures[tex].level[0];
  return mip_level(M.tri_uv_area[tri] * float(l0.width) * float(l0.height), fabsf(pixel_area), M.textures[tex].levels);
}

}  // namespace diffdope
