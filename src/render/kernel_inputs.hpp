#pragma once
// The plain structs the kernels read, made from the public types: a camera's intrinsics and a pose in float, and
// a mesh's arrays as pointers (host memory here; the CUDA executor makes the same views over its device copies).
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/pose.hpp"
#include "render/kernels/mesh_view.hpp"
#include "render/kernels/projection.hpp"

namespace diffdope {

inline Intrinsics to_intrinsics(const Camera& camera) {
  return {static_cast<float>(camera.fx), static_cast<float>(camera.fy), static_cast<float>(camera.cx),
          static_cast<float>(camera.cy), camera.width, camera.height};
}

RigidTransform to_rigid_transform(const Pose& pose);

/// A view of `mesh` over host memory; valid while the mesh and `texture_storage` live and are not modified.
/// `lod` > 0: the triangles of mesh.lods()[lod - 1] over the same textures.
MeshView make_mesh_view(const Mesh& mesh, std::vector<TextureView>& texture_storage, int lod = 0);

}  // namespace diffdope
