#include "diffdope/primitives.hpp"

#include <cmath>
#include <string>
#include <utility>

namespace diffdope {
namespace {

/// Appends a quad (a, b, c, d counter-clockwise seen from outside) with UVs.
void add_quad(Mesh& m, const Eigen::Vector3d q[4], const Vec2f uv[4], int tex) {
  const int base = m.num_vertices();
  for (int i = 0; i < 4; ++i) {
    m.positions.push_back({float(q[i].x()), float(q[i].y()), float(q[i].z())});
    m.uvs.push_back(uv[i]);
    m.colors.push_back({0.7f, 0.7f, 0.7f});
  }
  for (int idx : {0, 1, 2, 0, 2, 3}) m.triangles.push_back(base + idx);
  m.tri_texture.push_back(tex);
  m.tri_texture.push_back(tex);
}

/// Adds the six faces of an axis-aligned box [lo, hi], face f mapped to atlas cell f of a 3x2 grid.
void add_box(Mesh& m, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  // Faces: +x, -x, +y, -y, +z, -z. Corners listed counter-clockwise seen from outside.
  const Eigen::Vector3d c[8] = {{lo.x(), lo.y(), lo.z()}, {hi.x(), lo.y(), lo.z()}, {hi.x(), hi.y(), lo.z()},
                                {lo.x(), hi.y(), lo.z()}, {lo.x(), lo.y(), hi.z()}, {hi.x(), lo.y(), hi.z()},
                                {hi.x(), hi.y(), hi.z()}, {lo.x(), hi.y(), hi.z()}};
  const int faces[6][4] = {{1, 2, 6, 5}, {0, 4, 7, 3}, {3, 7, 6, 2}, {0, 1, 5, 4}, {4, 5, 6, 7}, {0, 3, 2, 1}};
  for (int f = 0; f < 6; ++f) {
    const float u0 = (f % 3) / 3.f, v0 = (f / 3) / 2.f, du = 1.f / 3.f, dv = 0.5f, e = 0.01f;
    const Vec2f uv[4] = {{u0 + e, v0 + e}, {u0 + du - e, v0 + e}, {u0 + du - e, v0 + dv - e}, {u0 + e, v0 + dv - e}};
    const Eigen::Vector3d q[4] = {c[faces[f][0]], c[faces[f][1]], c[faces[f][2]], c[faces[f][3]]};
    add_quad(m, q, uv, 0);
  }
}

Mesh finish(Mesh m, Texture texture, const std::string& name) {
  m.textures.push_back(std::move(texture));
  m.name = name;
  m.finalize();
  return m;
}

}  // namespace

Texture make_flat_texture(const Eigen::Vector3f& rgb, const std::string& source) {
  Texture t;
  t.width = t.height = 1;
  t.rgb = {rgb.x(), rgb.y(), rgb.z()};
  t.source = source;
  return t;
}

Mesh make_box(const Eigen::Vector3d& size, Texture texture) {
  Mesh m;
  add_box(m, -0.5 * size, 0.5 * size);
  return finish(std::move(m), std::move(texture), "box");
}

Mesh make_l_block(double s, Texture texture) {
  Mesh m;
  // A long bar and a short upright: no symmetry. Both boxes touch but are separate closed shells.
  add_box(m, Eigen::Vector3d(-0.5 * s, -0.15 * s, -0.2 * s), Eigen::Vector3d(0.5 * s, 0.15 * s, 0.2 * s));
  add_box(m, Eigen::Vector3d(0.2 * s, -0.15 * s, 0.2 * s), Eigen::Vector3d(0.5 * s, 0.15 * s, 0.6 * s));
  // Recentre on the bounding box.
  Eigen::Vector3f lo(1e9f, 1e9f, 1e9f), hi(-1e9f, -1e9f, -1e9f);
  for (const auto& p : m.positions) lo = lo.cwiseMin(Eigen::Vector3f(p.x, p.y, p.z)), hi = hi.cwiseMax(Eigen::Vector3f(p.x, p.y, p.z));
  const Eigen::Vector3f c = 0.5f * (lo + hi);
  for (auto& p : m.positions) p = {p.x - c.x(), p.y - c.y(), p.z - c.z()};
  return finish(std::move(m), std::move(texture), "l_block");
}

Mesh make_cylinder(double r, double h, int segments, Texture texture) {
  Mesh m;
  const float z0 = float(-0.5 * h), z1 = float(0.5 * h);
  // Side: segments + 1 columns so that the UV seam duplicates the first column.
  for (int i = 0; i <= segments; ++i) {
    const double a = 2 * M_PI * i / segments;
    const float x = float(r * std::cos(a)), y = float(r * std::sin(a)), u = float(i) / segments;
    m.positions.push_back({x, y, z0});
    m.uvs.push_back({u, 0.02f});
    m.positions.push_back({x, y, z1});
    m.uvs.push_back({u, 0.48f});
  }
  for (int i = 0; i < segments; ++i) {
    const int a = 2 * i, b = 2 * i + 1, c = 2 * i + 2, d = 2 * i + 3;
    for (int idx : {a, c, d, a, d, b}) m.triangles.push_back(idx);
  }
  // Caps: fans around a centre vertex, UVs in the upper half of the atlas.
  for (int cap = 0; cap < 2; ++cap) {
    const float z = cap ? z1 : z0;
    const float uc = cap ? 0.75f : 0.25f, vc = 0.75f;
    const int centre = m.num_vertices();
    m.positions.push_back({0.f, 0.f, z});
    m.uvs.push_back({uc, vc});
    for (int i = 0; i < segments; ++i) {
      const double a = 2 * M_PI * i / segments;
      m.positions.push_back({float(r * std::cos(a)), float(r * std::sin(a)), z});
      m.uvs.push_back({uc + 0.23f * float(std::cos(a)), vc + 0.23f * float(std::sin(a))});
    }
    for (int i = 0; i < segments; ++i) {
      const int a = centre + 1 + i, b = centre + 1 + (i + 1) % segments;
      if (cap) {
        for (int idx : {centre, a, b}) m.triangles.push_back(idx);
      } else {
        for (int idx : {centre, b, a}) m.triangles.push_back(idx);
      }
    }
  }
  m.colors.assign(m.positions.size(), {0.7f, 0.7f, 0.7f});
  m.tri_texture.assign(m.triangles.size() / 3, 0);
  return finish(std::move(m), std::move(texture), "cylinder");
}

Mesh make_uv_sphere(double r, int rings, int segments, Texture texture) {
  Mesh m;
  for (int i = 0; i <= rings; ++i) {
    const double th = M_PI * i / rings;
    for (int j = 0; j <= segments; ++j) {
      const double ph = 2 * M_PI * j / segments;
      m.positions.push_back({float(r * std::sin(th) * std::cos(ph)), float(r * std::sin(th) * std::sin(ph)),
                             float(r * std::cos(th))});
      m.uvs.push_back({float(j) / segments, 1.f - float(i) / rings});
    }
  }
  const int row = segments + 1;
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      const int a = i * row + j, b = a + 1, c = a + row, d = c + 1;
      for (int idx : {a, c, d, a, d, b}) m.triangles.push_back(idx);
    }
  }
  m.colors.assign(m.positions.size(), {0.7f, 0.7f, 0.7f});
  m.tri_texture.assign(m.triangles.size() / 3, 0);
  return finish(std::move(m), std::move(texture), "uv_sphere");
}

}  // namespace diffdope
