#include "diffdope/mesh.hpp"

#include <atomic>
#include <Eigen/Geometry>
#include <algorithm>
#include <sstream>
#include <cmath>
#include <stdexcept>
#include <opencv2/imgproc.hpp>
#include <unordered_map>

#ifdef DIFFDOPE_WITH_MESHOPTIMIZER
#include <meshoptimizer.h>
#endif

// The texture sampling the renderer uses (header-only kernel maths): seams and plainness are judged on the
// colours it will actually draw.
#include "render/kernels/texture.hpp"

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

/// Largest colour difference (any channel, colours in [0, 1]) across a shared edge that is not a colour seam.
/// The two sides of a baked UV atlas's chart border resample the same print and differ by a few percent at sharp
/// print features; a crease between differently printed faces differs by far more. Blending a jump this small
/// would keep the loss continuous to within 5 % of one pixel's colour, not worth its cost.
constexpr float kSeamColourTolerance = 0.05f;

/// Edge adjacency, colour seams and closedness of `triangles` (with their texture indices) over the mesh's vertices.
void surface_topology(const std::vector<Vec3f>& positions, const std::vector<Vec2f>& uvs,
                      const std::vector<Vec3f>& colors, const std::vector<Texture>& textures,
                      const std::vector<int>& triangles, const std::vector<int>& tri_texture, double eps,
                      std::vector<int>& neighbors_,
                      std::vector<int>& opposite_, std::vector<unsigned char>& seams_, bool& closed_outward_) {
  const int nt = static_cast<int>(triangles.size() / 3);
  // Weld by position: seams duplicate vertices (same position, different UVs) and must not become borders.
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
  // Attributes differ across a shared edge when a shared (welded) corner carries different UVs or colours, or
  // the two triangles use different textures.
  auto same_corner = [&](int i, int j) {
    if (!uvs.empty() && (uvs[i].x != uvs[j].x || uvs[i].y != uvs[j].y)) return false;
    return colors[i].x == colors[j].x && colors[i].y == colors[j].y && colors[i].z == colors[j].z;
  };
  // The colour triangle `tri` shows at fraction f of the way from its corner i to its corner j (vertex
  // indices), as the renderer shades it (level 0 of its texture, else vertex colours).
  auto colour_on_edge = [&](int tri, int i, int j, float f) {
    const int tex = tri_texture[size_t(tri)];
    if (tex >= 0 && size_t(tex) < textures.size() && !uvs.empty()) {
      const Texture& T = textures[size_t(tex)];
      const Vec2f uv{(1.f - f) * uvs[i].x + f * uvs[j].x, (1.f - f) * uvs[i].y + f * uvs[j].y};
      return sample_bilinear(TextureLevelView{T.rgb.data(), T.width, T.height}, uv, nullptr, nullptr);
    }
    return (1.f - f) * colors[i] + f * colors[j];
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
    const int a0 = triangles[3 * ta + a % 3], a1 = triangles[3 * ta + (a % 3 + 1) % 3];
    const int b0 = corner_in(tb, weld[a0]), b1 = corner_in(tb, weld[a1]);
    bool seam = false;
    if (tri_texture[ta] != tri_texture[tb] || !same_corner(a0, b0) || !same_corner(a1, b1)) {
      // The attributes differ; a colour seam only where the colour itself jumps (a UV atlas's chart borders
      // carry the same colour on both sides, and blending them would only cost time).
      for (float f : {0.f, 0.25f, 0.5f, 0.75f, 1.f}) {
        const Vec3f d = colour_on_edge(ta, a0, a1, f) - colour_on_edge(tb, b0, b1, f);
        seam |= std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)}) > kSeamColourTolerance;
      }
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


/// Area in UV units of each triangle (0 without UVs): the texture's mip level follows texels per pixel.
std::vector<float> uv_areas(const std::vector<Vec2f>& uvs, const std::vector<int>& triangles) {
  std::vector<float> area(triangles.size() / 3, 0.f);
  if (uvs.empty()) return area;
  for (size_t t = 0; t < area.size(); ++t) {
    const Vec2f a = uvs[triangles[3 * t]], b = uvs[triangles[3 * t + 1]], c = uvs[triangles[3 * t + 2]];
    area[t] = 0.5f * std::fabs((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x));
  }
  return area;
}

double weld_epsilon(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) { return std::max(1e-9, 1e-6 * (hi - lo).norm()); }

}  // namespace

void Mesh::finalize() {
  const std::string who = "mesh '" + name + "': ";
  if (positions.empty() || triangles.size() < 3) throw std::runtime_error(who + "has no triangles");
  if (triangles.size() % 3 != 0) throw std::runtime_error(who + "triangle index count is not a multiple of 3");
  const int nv = num_vertices(), nt = num_triangles();
  for (int idx : triangles)
    if (idx < 0 || idx >= nv) throw std::runtime_error(who + "triangle index " + std::to_string(idx) + " out of range");
  for (size_t v = 0; v < positions.size(); ++v) {
    const Vec3f& p = positions[v];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
      throw std::runtime_error(who + "vertex position is not finite");
    // Far beyond any object or robot: a wrong unit or a corrupt value, whose squares would overflow later.
    if (std::max({std::abs(p.x), std::abs(p.y), std::abs(p.z)}) > kMaxVertexCoordinate) {
      std::ostringstream m;
      m << who << "vertex " << v << " is at (" << p.x << ", " << p.y << ", " << p.z << ") m: more than "
        << kMaxVertexCoordinate << " m from the model's origin (a wrong unit or a corrupt value)";
      throw std::runtime_error(m.str());
    }
  }
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
  // A mesh whose every triangle has no area draws nothing: refining it would "converge" on nothing.
  const double min_area2 = 1e-12 * (bbox_max_ - bbox_min_).squaredNorm();
  bool any_area = false;
  for (int t = 0; t < nt && !any_area; ++t) {
    const Eigen::Vector3d a = to_eigen(positions[size_t(triangles[3 * t])]);
    const Eigen::Vector3d b = to_eigen(positions[size_t(triangles[3 * t + 1])]);
    const Eigen::Vector3d c = to_eigen(positions[size_t(triangles[3 * t + 2])]);
    any_area = (b - a).cross(c - a).norm() > min_area2;
  }
  if (!any_area) throw std::runtime_error(who + "every triangle is degenerate (no area)");
  diameter_ = compute_diameter(positions);
  {  // one colour over the whole surface: the drawn vertex colours and the used textures' texels
    Eigen::Array3f lo = Eigen::Array3f::Constant(1e9f), hi = Eigen::Array3f::Constant(-1e9f);
    const auto see = [&](float r, float g, float b) {
      lo = lo.min(Eigen::Array3f(r, g, b));
      hi = hi.max(Eigen::Array3f(r, g, b));
    };
    std::vector<bool> used_texture(textures.size(), false);
    for (int t = 0; t < nt; ++t) {
      if (tri_texture[size_t(t)] >= 0) {
        used_texture[size_t(tri_texture[size_t(t)])] = true;
        continue;
      }
      for (int k = 0; k < 3; ++k) {
        const Vec3f& c = colors[size_t(triangles[3 * size_t(t) + k])];
        see(c.x, c.y, c.z);
      }
    }
    for (size_t i = 0; i < textures.size(); ++i)
      if (used_texture[i])
        for (size_t j = 0; j + 2 < textures[i].rgb.size(); j += 3)
          see(textures[i].rgb[j], textures[i].rgb[j + 1], textures[i].rgb[j + 2]);
    plain_ = ((hi - lo) <= kPlainColourSpread).all();
  }
  build_adjacency();
  build_mipmaps();
  build_lods();
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
  tri_uv_area_ = uv_areas(uvs, triangles);
}

void Mesh::build_adjacency() {
  surface_topology(positions, uvs, colors, textures, triangles, tri_texture, weld_epsilon(bbox_min_, bbox_max_), neighbors_,
                   opposite_, seams_, closed_outward_);
}

bool lods_built() {
#ifdef DIFFDOPE_WITH_MESHOPTIMIZER
  return true;
#else
  return false;
#endif
}

void Mesh::build_lods() {
  lods_.clear();
#ifdef DIFFDOPE_WITH_MESHOPTIMIZER  // (without it, no levels: lods_built())
  if (num_triangles() <= kLodMinTriangles) return;
  // meshoptimizer keeps vertices shared by triangles of different textures apart by simplifying each texture's
  // triangles on their own, with their outline locked (colour seams between textures stay where they are).
  // Meshes are often stored as triangle soups (3 vertices per triangle, as many PLY exporters write them):
  // corners with the same position, UV and colour are one vertex for the simplifier, else every vertex would
  // look like a seam and stay locked. Each triangle then refers to one representative of its corners.
  struct Corner {
    Vec3f p;
    Vec2f uv;
    Vec3f c;
  };
  std::vector<Corner> corners(positions.size());
  for (size_t i = 0; i < positions.size(); ++i)
    corners[i] = Corner{positions[i], uvs.empty() ? Vec2f{0.f, 0.f} : uvs[i], colors[i]};
  // The simplifier sees only these unique vertices (an unused duplicate would make its twin look like a seam).
  std::vector<unsigned> remap(positions.size());
  const size_t unique = meshopt_generateVertexRemap(remap.data(), nullptr, positions.size(), corners.data(),
                                                    corners.size(), sizeof(Corner));
  std::vector<unsigned> representative(unique, ~0u);
  std::vector<Vec3f> unique_positions(unique);
  for (size_t i = 0; i < positions.size(); ++i)
    if (representative[remap[i]] == ~0u) representative[remap[i]] = unsigned(i), unique_positions[remap[i]] = positions[i];
  std::vector<unsigned> all(triangles.size());
  for (size_t i = 0; i < triangles.size(); ++i) all[i] = remap[size_t(triangles[i])];
  const float scale = meshopt_simplifyScale(&unique_positions[0].x, unique, sizeof(Vec3f));
  // Each level is simplified from the full mesh (so its error is measured against the full surface), to
  // 1 / kLodStep of the triangles of the level before, down to about kLodMinTriangles / 4 triangles.
  std::vector<int> texture_ids(tri_texture);
  std::sort(texture_ids.begin(), texture_ids.end());
  texture_ids.erase(std::unique(texture_ids.begin(), texture_ids.end()), texture_ids.end());
  std::vector<std::vector<unsigned>> groups(texture_ids.size());  // each texture's triangles
  for (size_t t = 0; t < tri_texture.size(); ++t) {
    const size_t g = std::lower_bound(texture_ids.begin(), texture_ids.end(), tri_texture[t]) - texture_ids.begin();
    groups[g].insert(groups[g].end(), &all[3 * t], &all[3 * t] + 3);
  }
  const unsigned options = texture_ids.size() > 1 ? meshopt_SimplifyLockBorder : 0;
  std::vector<unsigned> next(all.size());
  size_t previous = all.size() / 3;
  // A triangle soup first gets a level of all its triangles over the merged vertices (error 0, fewer vertices
  // to transform).
  const bool soup = unique * 4 < positions.size() * 3;
  for (double divisor = soup ? 1 : kLodStep; previous > size_t(kLodMinTriangles) / 4; divisor *= kLodStep) {
    MeshLod lod;
    float error = 0;
    for (size_t g = 0; g < groups.size(); ++g) {
      float e = 0;
      const size_t target = size_t(double(groups[g].size() / 3) / divisor) * 3;
      const size_t n = divisor == 1 ? groups[g].size()
                                    : meshopt_simplify(next.data(), groups[g].data(), groups[g].size(),
                                                       &unique_positions[0].x, unique, sizeof(Vec3f), target,
                                                       0.05f, options, &e);
      if (divisor == 1) std::copy(groups[g].begin(), groups[g].end(), next.begin());
      // Triangles in an order that reuses vertices soon (neighbours near each other in memory): the raster,
      // the silhouette walks and the backward pass then read vertices the cache still holds.
      meshopt_optimizeVertexCache(next.data(), next.data(), n, unique);
      error = std::max(error, e);
      for (size_t i = 0; i < n; ++i) lod.triangles.push_back(int(representative[next[i]]));
      lod.tri_texture.insert(lod.tri_texture.end(), n / 3, texture_ids[g]);
    }
    const size_t count = size_t(lod.num_triangles());
    if (count == 0 || (divisor > 1 && double(count) > double(previous) * 0.85)) break;  // stuck (topology, error cap)
    previous = count;
    lod.error = double(error) * scale;
    // Only the vertices this level uses, in the order its triangles first use them (cache locality).
    std::vector<int> index(positions.size(), -1);
    for (int& v : lod.triangles) {
      if (index[size_t(v)] < 0) {
        index[size_t(v)] = lod.num_vertices();
        lod.positions.push_back(positions[size_t(v)]);
        lod.colors.push_back(colors[size_t(v)]);
        if (!uvs.empty()) lod.uvs.push_back(uvs[size_t(v)]);
      }
      v = index[size_t(v)];
    }
    surface_topology(lod.positions, lod.uvs, lod.colors, textures, lod.triangles, lod.tri_texture,
                     weld_epsilon(bbox_min_, bbox_max_), lod.neighbors, lod.opposite, lod.seams, lod.closed_outward);
    lod.tri_uv_area = uv_areas(lod.uvs, lod.triangles);
    lods_.push_back(std::move(lod));
  }
#endif
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

}  // namespace diffdope
