// The UV charts of scan-like objects: grown over the triangles from farthest-point seeds, small ones merged, and
// regrown until each projects one to one onto its mean plane.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <numeric>
#include <queue>
#include <random>
#include <tuple>
#include <utility>
#include <vector>

#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {
namespace {

/// Grows charts over the triangles whose `chart` is -1 (Dijkstra on centroid distances over the adjacency): a
/// triangle joins a chart when its normal is within 60 degrees of the chart's mean normal so far and it lies
/// within `radius` (metres along the surface) of the chart's seed; first from `seeds` farthest-point seeds,
/// then from each triangle still unassigned, in index order. New charts are numbered from `charts`; returns
/// the new chart count.
int grow_charts(const std::vector<V3>& centroid, const std::vector<V3>& normal, const std::vector<double>& area,
                const std::vector<std::array<int, 3>>& nb, int seeds, double radius, std::mt19937& rng, int charts,
                std::vector<int>& chart) {
  const int nt = int(centroid.size());
  const double cos_max = 0.5;
  std::vector<int> free_tris;
  for (int t = 0; t < nt; ++t)
    if (chart[t] < 0) free_tris.push_back(t);
  if (free_tris.empty()) return charts;
  std::vector<int> seed_tri;
  std::vector<double> mind(free_tris.size(), 1e300);
  size_t s = rng() % free_tris.size();
  for (int c = 0; c < seeds && c < int(free_tris.size()); ++c) {
    seed_tri.push_back(free_tris[s]);
    size_t far = 0;
    for (size_t i = 0; i < free_tris.size(); ++i) {
      mind[i] = std::min(mind[i], (centroid[free_tris[i]] - centroid[free_tris[s]]).squaredNorm());
      if (mind[i] > mind[far]) far = i;
    }
    s = far;
  }
  using Item = std::tuple<double, int, int>;  // distance, triangle, chart
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  std::vector<V3> sum(charts, V3::Zero());  // area-weighted normal sum per chart
  auto grow = [&]() {
    while (!queue.empty()) {
      const auto [d, t, c] = queue.top();
      queue.pop();
      if (chart[t] >= 0 || d > radius || normal[t].dot(sum[c].normalized()) < cos_max) continue;
      chart[t] = c;
      sum[c] += area[t] * normal[t];
      for (int e = 0; e < 3; ++e) {
        const int n = nb[t][e];
        if (n >= 0 && chart[n] < 0) queue.emplace(d + (centroid[n] - centroid[t]).norm(), n, c);
      }
    }
  };
  auto seed = [&](int t) {
    queue.emplace(0.0, t, int(sum.size()));
    sum.push_back(normal[t]);
  };
  for (int t : seed_tri)
    if (chart[t] < 0) seed(t);
  grow();
  for (int t : free_tris) {
    if (chart[t] >= 0) continue;
    seed(t);
    grow();
  }
  return int(sum.size());
}

/// Merges each chart of fewer than `min_size` triangles into the neighbouring chart it shares most edges with,
/// when all its triangles stay within 70 degrees of the merged mean normal (leftovers between charts would
/// otherwise stay tiny charts).
void merge_small_charts(const std::vector<V3>& normal, const std::vector<double>& area,
                        const std::vector<std::array<int, 3>>& nb, int charts, int min_size, std::vector<int>& chart) {
  const int nt = int(normal.size());
  std::vector<V3> sum(charts, V3::Zero());
  std::vector<std::vector<int>> members(charts);
  for (int t = 0; t < nt; ++t) sum[chart[t]] += area[t] * normal[t], members[chart[t]].push_back(t);
  for (int c = 0; c < charts; ++c) {
    if (members[c].empty() || int(members[c].size()) >= min_size) continue;
    std::map<int, int> shared;  // neighbouring chart -> shared edges
    for (int t : members[c])
      for (int e = 0; e < 3; ++e)
        if (nb[t][e] >= 0 && chart[nb[t][e]] != c) ++shared[chart[nb[t][e]]];
    int best = -1, best_edges = 0;
    for (const auto& [other, edges] : shared) {
      const V3 n = (sum[other] + sum[c]).normalized();
      bool fits = true;
      for (int t : members[c]) fits = fits && normal[t].dot(n) >= 0.34;
      if (fits && edges > best_edges) best = other, best_edges = edges;
    }
    if (best < 0) continue;
    for (int t : members[c]) chart[t] = best;
    members[best].insert(members[best].end(), members[c].begin(), members[c].end());
    members[c].clear();
    sum[best] += sum[c];
    sum[c] = V3::Zero();
  }
}

/// True when 2-D triangles a and b overlap with positive area (touching along an edge or at a vertex does not
/// count): no separating axis among their edge normals.
bool triangles_overlap(const V2 a[3], const V2 b[3]) {
  for (int side = 0; side < 2; ++side) {
    const V2* p = side ? b : a;
    for (int e = 0; e < 3; ++e) {
      const V2 d = p[(e + 1) % 3] - p[e], axis(-d.y(), d.x());
      double lo_a = 1e300, hi_a = -1e300, lo_b = 1e300, hi_b = -1e300;
      for (int k = 0; k < 3; ++k) {
        lo_a = std::min(lo_a, axis.dot(a[k])), hi_a = std::max(hi_a, axis.dot(a[k]));
        lo_b = std::min(lo_b, axis.dot(b[k])), hi_b = std::max(hi_b, axis.dot(b[k]));
      }
      const double tol = 1e-9 * axis.squaredNorm();
      if (hi_a <= lo_b + tol || hi_b <= lo_a + tol) return false;
    }
  }
  return true;
}

/// Triangles to take out of their chart so that every chart projects one to one onto its mean plane: those
/// too oblique to it (normal more than 70 degrees off), and of each overlapping pair in the projection the
/// more oblique one.
std::vector<int> unfoldable_triangles(const std::vector<V3>& pos, const std::vector<int>& tri,
                                      const std::vector<V3>& normal, const std::vector<int>& chart,
                                      const std::vector<V3>& chart_normal) {
  const int nt = int(normal.size());
  std::vector<unsigned char> out(nt, 0);
  std::vector<std::vector<int>> members(chart_normal.size());
  for (int t = 0; t < nt; ++t) {
    if (normal[t].dot(chart_normal[chart[t]]) < 0.2)
      out[t] = 1;
    else
      members[chart[t]].push_back(t);
  }
  std::vector<std::array<V2, 3>> proj(nt);
  for (size_t c = 0; c < members.size(); ++c) {
    const auto& list = members[c];
    if (list.size() < 2) continue;
    const auto [t1, t2] = plane_axes(chart_normal[c]);
    V2 lo(1e300, 1e300), hi(-1e300, -1e300);
    double edge = 0;
    for (int t : list) {
      for (int k = 0; k < 3; ++k) {
        const V3& p = pos[tri[3 * t + k]];
        proj[t][k] = V2(p.dot(t1), p.dot(t2));
        lo = lo.cwiseMin(proj[t][k]), hi = hi.cwiseMax(proj[t][k]);
      }
      edge += (proj[t][1] - proj[t][0]).norm();
    }
    // Uniform grid of about two edge lengths; each triangle in the cells its box covers.
    const double cell = std::max(1e-9, 2 * edge / list.size());
    const int gx = std::min(1024, int((hi.x() - lo.x()) / cell) + 1),
              gy = std::min(1024, int((hi.y() - lo.y()) / cell) + 1);
    const double sx = gx / std::max(1e-12, hi.x() - lo.x() + 1e-12), sy = gy / std::max(1e-12, hi.y() - lo.y() + 1e-12);
    std::vector<std::vector<int>> grid(size_t(gx) * gy);
    for (int t : list) {
      V2 a = proj[t][0], b = proj[t][0];
      for (int k = 1; k < 3; ++k) a = a.cwiseMin(proj[t][k]), b = b.cwiseMax(proj[t][k]);
      const int x0 = std::clamp(int((a.x() - lo.x()) * sx), 0, gx - 1),
                x1 = std::clamp(int((b.x() - lo.x()) * sx), 0, gx - 1);
      const int y0 = std::clamp(int((a.y() - lo.y()) * sy), 0, gy - 1),
                y1 = std::clamp(int((b.y() - lo.y()) * sy), 0, gy - 1);
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) grid[size_t(y) * gx + x].push_back(t);
    }
    for (const auto& in_cell : grid)
      for (size_t i = 0; i < in_cell.size(); ++i)
        for (size_t j = i + 1; j < in_cell.size(); ++j) {
          const int a = in_cell[i], b = in_cell[j];
          if (out[a] || out[b] || !triangles_overlap(proj[a].data(), proj[b].data())) continue;
          out[normal[a].dot(chart_normal[c]) < normal[b].dot(chart_normal[c]) ? a : b] = 1;
        }
  }
  std::vector<int> result;
  for (int t = 0; t < nt; ++t)
    if (out[t]) result.push_back(t);
  return result;
}

}  // namespace

std::pair<V3, V3> plane_axes(const V3& n) {
  const V3 t1 = (std::fabs(n.x()) < 0.9 ? V3::UnitX() : V3::UnitY()).cross(n).normalized();
  return {t1, n.cross(t1)};
}

TriangleGeometry triangle_geometry(const Soup& soup) {
  const int nt = int(soup.tri.size() / 3);
  // Triangle normals, centroids, adjacency (each part is a closed manifold: every edge has two triangles).
  std::vector<V3> normal(nt), centroid(nt);
  std::vector<double> tri_area(nt);
  std::vector<std::pair<uint64_t, int>> edges;
  edges.reserve(3 * nt);
  for (int t = 0; t < nt; ++t) {
    const V3 &a = soup.pos[soup.tri[3 * t]], &b = soup.pos[soup.tri[3 * t + 1]], &c = soup.pos[soup.tri[3 * t + 2]];
    const V3 n = (b - a).cross(c - a);
    tri_area[t] = 0.5 * n.norm();
    normal[t] = n.norm() > 0 ? V3(n.normalized()) : V3::UnitZ();
    centroid[t] = (a + b + c) / 3;
    for (int e = 0; e < 3; ++e) {
      const uint64_t i = uint64_t(soup.tri[3 * t + e]), j = uint64_t(soup.tri[3 * t + (e + 1) % 3]);
      edges.emplace_back(std::min(i, j) << 32 | std::max(i, j), 3 * t + e);
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<std::array<int, 3>> nb(nt, {-1, -1, -1});
  for (size_t i = 0; i + 1 < edges.size(); ++i)
    if (edges[i].first == edges[i + 1].first) {
      const int a = edges[i].second, b = edges[i + 1].second;
      nb[a / 3][a % 3] = b / 3;
      nb[b / 3][b % 3] = a / 3;
    }
  return {std::move(normal), std::move(centroid), std::move(tri_area), std::move(nb)};
}

Charts make_charts(const Soup& soup, const TriangleGeometry& geometry, std::mt19937& rng) {
  const int nt = int(soup.tri.size() / 3);
  const std::vector<V3>& normal = geometry.normal;
  const std::vector<V3>& centroid = geometry.centroid;
  const std::vector<double>& tri_area = geometry.area;
  const std::vector<std::array<int, 3>>& nb = geometry.nb;

  // Charts, then until each projects one to one onto its mean plane: triangles that fold or are too oblique
  // are taken out and re-charted (in the end, alone).
  std::vector<int> chart(nt, -1);
  constexpr int kSeeds = 24;
  const double radius = 1.5 * std::sqrt(std::accumulate(tri_area.begin(), tri_area.end(), 0.0) / kSeeds);
  int charts = grow_charts(centroid, normal, tri_area, nb, kSeeds, radius, rng, 0, chart);
  std::vector<V3> chart_normal;
  for (int round = 0;; ++round) {
    merge_small_charts(normal, tri_area, nb, charts, 24, chart);
    chart_normal.assign(charts, V3::Zero());
    for (int t = 0; t < nt; ++t) chart_normal[chart[t]] += tri_area[t] * normal[t];
    for (int c = 0; c < charts; ++c)
      chart_normal[c] = chart_normal[c].norm() > 0 ? V3(chart_normal[c].normalized()) : V3::UnitZ();
    const std::vector<int> redo = unfoldable_triangles(soup.pos, soup.tri, normal, chart, chart_normal);
    if (redo.empty()) break;
    if (round == 3) {
      for (int t : redo) chart[t] = charts++, chart_normal.push_back(normal[t]);
      break;
    }
    for (int t : redo) chart[t] = -1;
    charts = grow_charts(centroid, normal, tri_area, nb, 0, radius, rng, charts, chart);
  }
  // Drop chart numbers left empty.
  {
    std::vector<int> renumber(charts, -1);
    int used = 0;
    for (int t = 0; t < nt; ++t)
      if (renumber[chart[t]] < 0) renumber[chart[t]] = used++;
    std::vector<V3> normals(used);
    for (int c = 0; c < charts; ++c)
      if (renumber[c] >= 0) normals[renumber[c]] = chart_normal[c];
    for (int& c : chart) c = renumber[c];
    chart_normal = normals;
  }
  return {std::move(chart), std::move(chart_normal)};
}

}  // namespace scan
}  // namespace diffdope
