#include "diffdope/mesh.hpp"

#include <atomic>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <opencv2/imgproc.hpp>
#include <unordered_map>

namespace diffdope {
namespace {

Eigen::Vector3d to_eigen(const Vec3f& v) { return Eigen::Vector3d(v.x, v.y, v.z); }

// Largest distance between two vertices. Exact for small meshes; for large ones, exact among the extreme
// vertices along many directions (the farthest pair is always extreme along the direction joining them, so
// the result is within a tiny fraction of the true diameter).
double compute_diameter(const std::vector<Vec3f>& pts) {
  std::vector<int> cand;
  if (pts.size() <= 3000) {
    cand.resize(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) cand[i] = static_cast<int>(i);
  } else {
    const int n_dir = 500;
    for (int d = 0; d < n_dir; ++d) {  // Fibonacci sphere directions
      const double z = 1.0 - (2.0 * d + 1.0) / n_dir, r = std::sqrt(1 - z * z), phi = d * 2.399963229728653;
      const Eigen::Vector3d dir(r * std::cos(phi), r * std::sin(phi), z);
      int lo = 0, hi = 0;
      double vlo = 1e300, vhi = -1e300;
      for (size_t i = 0; i < pts.size(); ++i) {
        const double v = to_eigen(pts[i]).dot(dir);
        if (v < vlo) vlo = v, lo = static_cast<int>(i);
        if (v > vhi) vhi = v, hi = static_cast<int>(i);
      }
      cand.push_back(lo);
      cand.push_back(hi);
    }
    std::sort(cand.begin(), cand.end());
    cand.erase(std::unique(cand.begin(), cand.end()), cand.end());
  }
  double best = 0;
  for (size_t i = 0; i < cand.size(); ++i)
    for (size_t j = i + 1; j < cand.size(); ++j)
      best = std::max(best, (to_eigen(pts[cand[i]]) - to_eigen(pts[cand[j]])).squaredNorm());
  return std::sqrt(best);
}

}  // namespace

void Mesh::finalize() {
  const std::string who = "mesh '" + name + "': ";
  if (positions.empty() || triangles.size() < 3) throw std::runtime_error(who + "has no triangles");
  if (triangles.size() % 3 != 0) throw std::runtime_error(who + "triangle index count is not a multiple of 3");
  const int nv = num_vertices(), nt = num_triangles();
  for (int idx : triangles)
    if (idx < 0 || idx >= nv) throw std::runtime_error(who + "triangle index " + std::to_string(idx) + " out of range");
  for (const Vec3f& p : positions)
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw std::runtime_error(who + "vertex position is not finite");
  if (!uvs.empty() && static_cast<int>(uvs.size()) != nv) throw std::runtime_error(who + "uv count != vertex count");
  if (colors.empty()) colors.assign(nv, Vec3f{0.7f, 0.7f, 0.7f});
  if (static_cast<int>(colors.size()) != nv) throw std::runtime_error(who + "colour count != vertex count");
  if (tri_texture.empty()) tri_texture.assign(nt, -1);
  if (static_cast<int>(tri_texture.size()) != nt) throw std::runtime_error(who + "tri_texture count != triangle count");
  for (int& t : tri_texture) {
    if (t >= static_cast<int>(textures.size())) throw std::runtime_error(who + "texture index out of range");
    if (uvs.empty()) t = -1;
  }
  for (const Texture& t : textures)
    if (t.width <= 0 || t.height <= 0 || t.rgb.size() != static_cast<size_t>(3 * t.width * t.height))
      throw std::runtime_error(who + "texture '" + t.source + "' is empty or inconsistent");

  bbox_min_ = bbox_max_ = to_eigen(positions[0]);
  for (const Vec3f& p : positions) {
    bbox_min_ = bbox_min_.cwiseMin(to_eigen(p));
    bbox_max_ = bbox_max_.cwiseMax(to_eigen(p));
  }
  diameter_ = compute_diameter(positions);
  build_adjacency();
  build_mipmaps();
  static std::atomic<uint64_t> next_id{1};  // renderers key their uploads on it (an address can be reused)
  content_id_ = next_id++;
}

void Mesh::build_mipmaps() {
  for (Texture& t : textures) {
    t.mips.clear();
    cv::Mat prev(t.height, t.width, CV_32FC3, t.rgb.data());
    while ((prev.cols > 1 || prev.rows > 1) && int(t.mips.size()) + 1 < kMaxTextureLevels) {
      cv::Mat next;
      cv::resize(prev, next, cv::Size(std::max(1, prev.cols / 2), std::max(1, prev.rows / 2)), 0, 0, cv::INTER_AREA);
      TextureImage img;
      img.width = next.cols;
      img.height = next.rows;
      img.rgb.assign(next.ptr<float>(0), next.ptr<float>(0) + 3 * next.cols * next.rows);
      t.mips.push_back(std::move(img));
      prev = cv::Mat(t.mips.back().height, t.mips.back().width, CV_32FC3, t.mips.back().rgb.data());
    }
  }
  tri_uv_area_.assign(num_triangles(), 0.f);
  if (uvs.empty()) return;
  for (int t = 0; t < num_triangles(); ++t) {
    const Vec2f a = uvs[triangles[3 * t]], b = uvs[triangles[3 * t + 1]], c = uvs[triangles[3 * t + 2]];
    tri_uv_area_[t] = 0.5f * std::fabs((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x));
  }
}

void Mesh::build_adjacency() {
  const int nt = num_triangles();
  // Weld by position: seams duplicate vertices (same position, different UVs) and must not become borders.
  const double eps = std::max(1e-9, 1e-6 * (bbox_max_ - bbox_min_).norm());
  struct KeyHash {
    size_t operator()(const std::array<long long, 3>& k) const {
      return std::hash<long long>()(k[0] * 73856093LL ^ k[1] * 19349663LL ^ k[2] * 83492791LL);
    }
  };
  std::unordered_map<std::array<long long, 3>, int, KeyHash> weld_map;
  std::vector<int> weld(positions.size());
  for (size_t i = 0; i < positions.size(); ++i) {
    const std::array<long long, 3> key{std::llround(positions[i].x / eps), std::llround(positions[i].y / eps),
                                       std::llround(positions[i].z / eps)};
    weld[i] = weld_map.emplace(key, static_cast<int>(weld_map.size())).first->second;
  }
  // Undirected welded edge -> the (triangle, edge) pairs that use it.
  std::unordered_map<unsigned long long, std::vector<int>> edges;
  edges.reserve(3 * nt);
  auto edge_key = [](int a, int b) {
    if (a > b) std::swap(a, b);
    return (static_cast<unsigned long long>(a) << 32) | static_cast<unsigned>(b);
  };
  for (int t = 0; t < nt; ++t) {
    const int* v = &triangles[3 * t];
    const int w0 = weld[v[0]], w1 = weld[v[1]], w2 = weld[v[2]];
    if (w0 == w1 || w1 == w2 || w0 == w2) continue;  // degenerate: never drawn, never a neighbour
    for (int k = 0; k < 3; ++k) edges[edge_key(weld[v[k]], weld[v[(k + 1) % 3]])].push_back(3 * t + k);
  }
  neighbors_.assign(3 * nt, -1);
  opposite_.assign(3 * nt, -1);
  seams_.assign(3 * nt, 0);
  // Attributes jump across a shared edge when a shared (welded) corner carries different UVs or colours, or
  // the two triangles use different textures.
  auto same_corner = [&](int i, int j) {
    if (!uvs.empty() && (uvs[i].x != uvs[j].x || uvs[i].y != uvs[j].y)) return false;
    return colors[i].x == colors[j].x && colors[i].y == colors[j].y && colors[i].z == colors[j].z;
  };
  auto corner_in = [&](int tri, int welded) {
    for (int c = 0; c < 3; ++c)
      if (weld[triangles[3 * tri + c]] == welded) return triangles[3 * tri + c];
    return -1;
  };
  for (const auto& [key, uses] : edges) {
    if (uses.size() != 2) continue;  // border (1) or non-manifold (>2): treated as a border
    const int a = uses[0], b = uses[1];
    const int ta = a / 3, tb = b / 3;
    if (ta == tb) continue;
    neighbors_[a] = tb;
    neighbors_[b] = ta;
    opposite_[a] = triangles[3 * tb + (b % 3 + 2) % 3];
    opposite_[b] = triangles[3 * ta + (a % 3 + 2) % 3];
    bool seam = tri_texture[ta] != tri_texture[tb];
    for (int c : {a % 3, (a % 3 + 1) % 3}) {
      const int va = triangles[3 * ta + c];
      seam |= !same_corner(va, corner_in(tb, weld[va]));
    }
    seams_[a] = seams_[b] = seam ? 1 : 0;
  }
  // Closed and consistently wound outward: every drawn triangle has three neighbours that traverse each shared
  // edge the other way round, and the enclosed volume is positive. Then back faces are never visible from
  // outside and culling them changes nothing.
  bool closed = true;
  double volume = 0;
  for (int t = 0; t < nt && closed; ++t) {
    const int* v = &triangles[3 * t];
    if (weld[v[0]] == weld[v[1]] || weld[v[1]] == weld[v[2]] || weld[v[0]] == weld[v[2]]) continue;
    for (int k = 0; k < 3 && closed; ++k) {
      const int n = neighbors_[3 * t + k];
      if (n < 0) {
        closed = false;
        break;
      }
      const int start = weld[v[k]], end = weld[v[(k + 1) % 3]];
      bool reversed = false;
      for (int c = 0; c < 3; ++c)
        reversed |= weld[triangles[3 * n + c]] == end && weld[triangles[3 * n + (c + 1) % 3]] == start;
      closed = reversed;
    }
    const Eigen::Vector3d p0 = to_eigen(positions[v[0]]), p1 = to_eigen(positions[v[1]]), p2 = to_eigen(positions[v[2]]);
    volume += p0.dot(p1.cross(p2)) / 6.0;
  }
  closed_outward_ = closed && volume > 0;
}

std::vector<Eigen::Vector3d> Mesh::bbox_corners() const {
  std::vector<Eigen::Vector3d> c;
  for (int i = 0; i < 8; ++i)
    c.emplace_back(i & 1 ? bbox_max_.x() : bbox_min_.x(), i & 2 ? bbox_max_.y() : bbox_min_.y(),
                   i & 4 ? bbox_max_.z() : bbox_min_.z());
  return c;
}

std::vector<Eigen::Vector3d> Mesh::bbox_corners(const Pose& pose) const {
  std::vector<Eigen::Vector3d> c = bbox_corners();
  for (auto& p : c) p = pose * p;
  return c;
}

MeshView Mesh::view(std::vector<TextureView>& storage) const {
  storage.clear();
  for (const Texture& t : textures) {
    TextureView tv{};
    tv.level[0] = TextureLevelView{t.rgb.data(), t.width, t.height};
    tv.levels = 1;
    for (const TextureImage& m : t.mips) tv.level[tv.levels++] = TextureLevelView{m.rgb.data(), m.width, m.height};
    storage.push_back(tv);
  }
  MeshView v;
  v.positions = positions.data();
  v.uvs = uvs.empty() ? nullptr : uvs.data();
  v.colors = colors.data();
  v.triangles = triangles.data();
  v.tri_texture = tri_texture.data();
  v.neighbors = neighbors_.data();
  v.opposite = opposite_.data();
  v.seams = seams_.data();
  v.textures = storage.empty() ? nullptr : storage.data();
  v.tri_uv_area = tri_uv_area_.data();
  v.num_vertices = num_vertices();
  v.num_triangles = num_triangles();
  v.num_textures = static_cast<int>(storage.size());
  return v;
}

}  // namespace diffdope
