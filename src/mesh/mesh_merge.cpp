// Several meshes placed in one frame as one mesh (mesh.hpp: merge_meshes).
#include <stdexcept>

#include "diffdope/mesh.hpp"

namespace diffdope {

Mesh merge_meshes(const std::vector<MeshPart>& parts, const std::string& name) {
  if (parts.empty()) throw std::runtime_error("merge_meshes '" + name + "': no part");
  Mesh out;
  out.name = name;
  bool any_uvs = false;
  for (const MeshPart& p : parts) {
    if (!p.mesh) throw std::runtime_error("merge_meshes '" + name + "': a part has no mesh");
    if (!p.scale.allFinite() || !p.pose.is_valid(1e-4))
      throw std::runtime_error("merge_meshes '" + name + "': part '" + p.mesh->name + "' has a bad pose or scale");
    any_uvs = any_uvs || !p.mesh->uvs.empty();
  }
  for (const MeshPart& p : parts) {
    const Mesh& m = *p.mesh;
    const int base = out.num_vertices(), texture_base = int(out.textures.size());
    for (const Vec3f& v : m.positions) {
      const Eigen::Vector3d x = p.pose * Eigen::Vector3d(p.scale.x() * v.x, p.scale.y() * v.y, p.scale.z() * v.z);
      out.positions.push_back(Vec3f{float(x.x()), float(x.y()), float(x.z())});
    }
    if (any_uvs) {
      if (m.uvs.empty()) out.uvs.insert(out.uvs.end(), m.positions.size(), Vec2f{0.f, 0.f});
      else out.uvs.insert(out.uvs.end(), m.uvs.begin(), m.uvs.end());
    }
    if (m.colors.size() == m.positions.size()) out.colors.insert(out.colors.end(), m.colors.begin(), m.colors.end());
    else out.colors.insert(out.colors.end(), m.positions.size(), Vec3f{0.7f, 0.7f, 0.7f});
    // A mirroring scale (odd number of negative factors) turns the winding inside out: swap two corners back.
    const bool mirrored = p.scale.x() * p.scale.y() * p.scale.z() < 0;
    for (int t = 0; t < m.num_triangles(); ++t) {
      const int a = m.triangles[size_t(3 * t)], b = m.triangles[size_t(3 * t + 1)], c = m.triangles[size_t(3 * t + 2)];
      out.triangles.push_back(base + a);
      out.triangles.push_back(base + (mirrored ? c : b));
      out.triangles.push_back(base + (mirrored ? b : c));
      const int tex = t < int(m.tri_texture.size()) ? m.tri_texture[size_t(t)] : -1;
      out.tri_texture.push_back(tex >= 0 && !m.uvs.empty() ? texture_base + tex : -1);
    }
    for (const Texture& tx : m.textures) {
      Texture copy;
      copy.width = tx.width, copy.height = tx.height, copy.rgb = tx.rgb, copy.source = tx.source;  // (mips: finalize)
      out.textures.push_back(std::move(copy));
    }
  }
  out.finalize();
  return out;
}

}  // namespace diffdope
