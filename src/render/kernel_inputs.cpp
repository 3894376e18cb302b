#include "render/kernel_inputs.hpp"

namespace diffdope {

RigidTransform to_rigid_transform(const Pose& pose) {
  RigidTransform k;
  for (int i = 0; i < 9; ++i) k.r[i] = static_cast<float>(pose.R(i / 3, i % 3));
  for (int i = 0; i < 3; ++i) k.t[i] = static_cast<float>(pose.t(i));
  return k;
}

MeshView make_mesh_view(const Mesh& mesh, std::vector<TextureView>& storage, int lod) {
  storage.clear();
  for (const Texture& t : mesh.textures) {
    TextureView tv{};
    tv.level[0] = TextureLevelView{t.rgb.data(), t.width, t.height};
    tv.levels = 1;
    for (const TextureImage& m : t.mips) tv.level[tv.levels++] = TextureLevelView{m.rgb.data(), m.width, m.height};
    storage.push_back(tv);
  }
  MeshView v;
  v.positions = mesh.positions.data();
  v.uvs = mesh.uvs.empty() ? nullptr : mesh.uvs.data();
  v.colors = mesh.colors.data();
  v.triangles = mesh.triangles.data();
  v.tri_texture = mesh.tri_texture.data();
  v.neighbors = mesh.neighbors().data();
  v.opposite = mesh.opposite_vertices().data();
  v.seams = mesh.seams().data();
  v.textures = storage.empty() ? nullptr : storage.data();
  v.tri_uv_area = mesh.tri_uv_area().data();
  v.num_vertices = mesh.num_vertices();
  v.num_triangles = mesh.num_triangles();
  v.num_textures = static_cast<int>(storage.size());
  if (lod > 0) {
    const MeshLod& l = mesh.lods().at(size_t(lod - 1));
    v.positions = l.positions.data();
    v.colors = l.colors.data();
    v.uvs = l.uvs.empty() ? nullptr : l.uvs.data();
    v.num_vertices = l.num_vertices();
    v.triangles = l.triangles.data();
    v.tri_texture = l.tri_texture.data();
    v.neighbors = l.neighbors.data();
    v.opposite = l.opposite.data();
    v.seams = l.seams.data();
    v.tri_uv_area = l.tri_uv_area.data();
    v.num_triangles = l.num_triangles();
  }
  return v;
}

}  // namespace diffdope
