// make_scan_like(): the scan-like procedural objects (irregular closed triangulation, chart atlas with seams,
// printed texture continuous across the seams), for each shape.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>
#include <set>
#include <stdexcept>
#include <utility>
#include <vector>

#include "diffdope/procedural.hpp"

using diffdope::Mesh;
using diffdope::ScanShape;
using diffdope::Vec2f;
using diffdope::Vec3f;

namespace {

struct ShapeCase {
  ScanShape shape;
  Eigen::Vector3d size;  // metres
  const char* name;
};

const ShapeCase kShapes[] = {{ScanShape::Bottle, {0.095, 0.058, 0.19}, "Bottle"},
                             {ScanShape::Mug, {0.117, 0.085, 0.1}, "Mug"},
                             {ScanShape::Box, {0.16, 0.06, 0.21}, "Box"}};

constexpr int kTriangles = 8000;
constexpr int kTextureSize = 512;

bool same(const Vec3f& a, const Vec3f& b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

double tri_area(const Mesh& m, int t) {
  const Vec3f a = m.positions[m.triangles[3 * t]], b = m.positions[m.triangles[3 * t + 1]],
              c = m.positions[m.triangles[3 * t + 2]];
  const Eigen::Vector3d A(a.x, a.y, a.z), B(b.x, b.y, b.z), C(c.x, c.y, c.z);
  return 0.5 * (B - A).cross(C - A).norm();
}

Eigen::Vector3d normal(const Mesh& m, int t) {
  const Vec3f a = m.positions[m.triangles[3 * t]], b = m.positions[m.triangles[3 * t + 1]],
              c = m.positions[m.triangles[3 * t + 2]];
  const Eigen::Vector3d A(a.x, a.y, a.z), B(b.x, b.y, b.z), C(c.x, c.y, c.z);
  return (B - A).cross(C - A).normalized();
}

/// A UV seam: edge k of triangle t, shared with triangle n (> t), whose twin corners an / bn (same positions
/// as the edge's a / b) carry other UVs.
struct UvSeam {
  int t, k, n, a, b, an, bn;
};
std::vector<UvSeam> uv_seams(const Mesh& m) {
  std::vector<UvSeam> out;
  for (int t = 0; t < m.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int n = m.neighbors()[3 * t + k];
      if (n < t) continue;
      const int a = m.triangles[3 * t + k], b = m.triangles[3 * t + (k + 1) % 3];
      int an = -1, bn = -1;
      for (int j = 0; j < 3; ++j) {
        const int v = m.triangles[3 * n + j];
        if (same(m.positions[v], m.positions[a])) an = v;
        if (same(m.positions[v], m.positions[b])) bn = v;
      }
      if (an < 0 || bn < 0) ADD_FAILURE() << "shared edge without its twin corners";
      else if (m.uvs[a].x != m.uvs[an].x || m.uvs[a].y != m.uvs[an].y || m.uvs[b].x != m.uvs[bn].x ||
               m.uvs[b].y != m.uvs[bn].y)
        out.push_back(UvSeam{t, k, n, a, b, an, bn});
    }
  return out;
}

double uv_area2(const Mesh& m, int t) {
  const Vec2f a = m.uvs[m.triangles[3 * t]], b = m.uvs[m.triangles[3 * t + 1]], c = m.uvs[m.triangles[3 * t + 2]];
  return double(b.x - a.x) * (c.y - a.y) - double(b.y - a.y) * (c.x - a.x);
}

/// Level-0 bilinear texture lookup with the renderer's convention (v = 0 at the bottom row, texel centres at
/// half-integers, clamped addressing).
Eigen::Vector3d sample(const diffdope::Texture& t, Vec2f uv) {
  const double x = std::clamp(uv.x * t.width - 0.5, 0.0, t.width - 1.0);
  const double y = std::clamp((1.0 - uv.y) * t.height - 0.5, 0.0, t.height - 1.0);
  const int x0 = std::min(int(x), t.width - 2), y0 = std::min(int(y), t.height - 2);
  const double fx = x - x0, fy = y - y0;
  auto at = [&](int xx, int yy) {
    const float* p = &t.rgb[3 * (size_t(yy) * t.width + xx)];
    return Eigen::Vector3d(p[0], p[1], p[2]);
  };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) +
         fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

/// Charts = connected components of triangles sharing an edge by vertex index (a seam duplicates vertices).
int count_charts(const Mesh& m) {
  std::vector<int> parent(m.num_triangles());
  std::iota(parent.begin(), parent.end(), 0);
  std::function<int(int)> find = [&](int x) { return parent[x] == x ? x : parent[x] = find(parent[x]); };
  std::map<std::pair<int, int>, int> first_use;
  for (int t = 0; t < m.num_triangles(); ++t)
    for (int e = 0; e < 3; ++e) {
      const int a = m.triangles[3 * t + e], b = m.triangles[3 * t + (e + 1) % 3];
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = first_use.find(key);
      if (it == first_use.end())
        first_use.emplace(key, t);
      else
        parent[find(t)] = find(it->second);
    }
  std::set<int> roots;
  for (int t = 0; t < m.num_triangles(); ++t) roots.insert(find(t));
  return int(roots.size());
}

class ScanLikeTest : public ::testing::TestWithParam<ShapeCase> {};

TEST_P(ScanLikeTest, MeetsTheRequest) {
  const ShapeCase& c = GetParam();
  const Mesh m = diffdope::make_scan_like(c.shape, c.size, kTriangles, kTextureSize, 3);
  // About the requested number of triangles; closed and wound outward.
  EXPECT_NEAR(m.num_triangles(), kTriangles, 0.1 * kTriangles);
  EXPECT_TRUE(m.closed_and_outward());
  // Exact bounding box, centred on the origin; finite positions.
  for (const Vec3f& p : m.positions) ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(m.bbox_max()[i] - m.bbox_min()[i], c.size[i], 1e-6) << "axis " << i;
    EXPECT_NEAR(m.center()[i], 0.0, 1e-6) << "axis " << i;
  }
  // One texture of the requested size, UVs in it, every triangle textured.
  ASSERT_EQ(m.textures.size(), 1u);
  EXPECT_EQ(m.textures[0].width, kTextureSize);
  EXPECT_EQ(m.textures[0].height, kTextureSize);
  ASSERT_EQ(m.uvs.size(), m.positions.size());
  for (const Vec2f& uv : m.uvs) ASSERT_TRUE(uv.x > 0 && uv.x < 1 && uv.y > 0 && uv.y < 1);
  for (int t : m.tri_texture) ASSERT_EQ(t, 0);
  // A chart atlas: many charts, seams between them, vertices duplicated along them.
  const int charts = count_charts(m);
  EXPECT_GE(charts, 15);
  EXPECT_LE(charts, 90);
  const int seams = int(uv_seams(m).size());
  EXPECT_GT(seams, 150);
  EXPECT_GT(m.num_vertices(), m.num_triangles() / 2 + 100);
  // Irregular, not a regular grid: triangle areas spread (about 1:4 between the 10th and 90th percentiles),
  // without slivers of near-zero area.
  std::vector<double> areas(m.num_triangles());
  for (int t = 0; t < m.num_triangles(); ++t) areas[t] = tri_area(m, t);
  std::sort(areas.begin(), areas.end());
  const double p10 = areas[areas.size() / 10], p90 = areas[areas.size() * 9 / 10];
  EXPECT_GT(p90 / p10, 2.0);
  EXPECT_LT(p90 / p10, 10.0);
  EXPECT_GT(areas.front(), 1e-4 * areas[areas.size() / 2]);
  std::printf("%s: %d triangles, %d vertices, %d charts, %d seam edges, area p90/p10 %.2f\n", c.name, m.num_triangles(),
              m.num_vertices(), charts, seams, p90 / p10);
}

TEST_P(ScanLikeTest, AtlasChartsAreUnfoldedAndDisjoint) {
  const ShapeCase& c = GetParam();
  const Mesh m = diffdope::make_scan_like(c.shape, c.size, kTriangles, kTextureSize, 5);
  // Every triangle keeps its orientation in UV space (counter-clockwise as seen from outside).
  for (int t = 0; t < m.num_triangles(); ++t) ASSERT_GT(uv_area2(m, t), 0.0) << "triangle " << t;
  // No texel centre strictly inside two triangles: charts do not overlap in the atlas.
  const int n = 1024;
  std::vector<unsigned char> hits(size_t(n) * n, 0);
  int overlaps = 0;
  for (int t = 0; t < m.num_triangles(); ++t) {
    Eigen::Vector2d p[3];
    for (int k = 0; k < 3; ++k)
      p[k] = Eigen::Vector2d(m.uvs[m.triangles[3 * t + k]].x, m.uvs[m.triangles[3 * t + k]].y) * n;
    const double a2 = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    const int x0 = std::max(0, int(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
    const int x1 = std::min(n - 1, int(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
    const int y0 = std::max(0, int(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
    const int y1 = std::min(n - 1, int(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d q(x + 0.5, y + 0.5);
        bool inside = true;
        for (int k = 0; k < 3 && inside; ++k) {
          const Eigen::Vector2d e = p[(k + 1) % 3] - p[k], d = q - p[k];
          inside = (e.x() * d.y() - e.y() * d.x()) / a2 > 1e-3 * e.norm();  // strictly inside, with a margin
        }
        if (inside && hits[size_t(y) * n + x]++) ++overlaps;
      }
  }
  EXPECT_EQ(overlaps, 0);
}

TEST_P(ScanLikeTest, PrintIsContinuousAcrossSeams) {
  // The texture is painted from the 3-D surface point, so both sides of a seam on a smooth part of the surface
  // show the same colour there (texels just outside a chart continue its surface, so filtering agrees too).
  // Such UV seams are then no colour seams (Mesh::seams()): the renderer need not blend across them.
  const ShapeCase& c = GetParam();
  const Mesh m = diffdope::make_scan_like(c.shape, c.size, kTriangles, 1024, 7);
  int edges = 0, matching = 0, smooth_seams = 0, colour_seams = 0;
  for (const UvSeam& e : uv_seams(m)) {
    if (normal(m, e.t).dot(normal(m, e.n)) < 0.87) continue;  // a crease (cap, rim, box edge) may change colour
    ++smooth_seams;
    colour_seams += m.seams()[3 * e.t + e.k];
    for (double f : {0.25, 0.5, 0.75}) {
      const Vec2f u0 = {float((1 - f) * m.uvs[e.a].x + f * m.uvs[e.b].x), float((1 - f) * m.uvs[e.a].y + f * m.uvs[e.b].y)};
      const Vec2f u1 = {float((1 - f) * m.uvs[e.an].x + f * m.uvs[e.bn].x),
                        float((1 - f) * m.uvs[e.an].y + f * m.uvs[e.bn].y)};
      ++edges;
      matching += (sample(m.textures[0], u0) - sample(m.textures[0], u1)).cwiseAbs().maxCoeff() < 0.1;
    }
  }
  std::printf("%s: %d of %d samples on smooth seams match; %d of %d smooth UV seams are colour seams\n", c.name,
              matching, edges, colour_seams, smooth_seams);
  ASSERT_GT(edges, 300);
  EXPECT_GT(double(matching) / edges, 0.97) << matching << " of " << edges << " seam samples match";
  EXPECT_LT(colour_seams, smooth_seams / 4);
}

TEST_P(ScanLikeTest, DeterministicForASeed) {
  const ShapeCase& c = GetParam();
  const Mesh a = diffdope::make_scan_like(c.shape, c.size, 3000, 256, 11);
  const Mesh b = diffdope::make_scan_like(c.shape, c.size, 3000, 256, 11);
  const Mesh other = diffdope::make_scan_like(c.shape, c.size, 3000, 256, 12);
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.triangles, b.triangles);
  for (int i = 0; i < a.num_vertices(); ++i) {
    ASSERT_TRUE(same(a.positions[i], b.positions[i]));
    ASSERT_TRUE(a.uvs[i].x == b.uvs[i].x && a.uvs[i].y == b.uvs[i].y);
  }
  EXPECT_EQ(a.textures[0].rgb, b.textures[0].rgb);
  EXPECT_TRUE(a.num_vertices() != other.num_vertices() || a.triangles != other.triangles ||
              a.textures[0].rgb != other.textures[0].rgb);
}

INSTANTIATE_TEST_SUITE_P(Shapes, ScanLikeTest, ::testing::ValuesIn(kShapes),
                         [](const ::testing::TestParamInfo<ShapeCase>& info) { return std::string(info.param.name); });

TEST(ScanLike, DefaultsGiveAbout15000TrianglesAnd2048Texture) {
  const Mesh m = diffdope::make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.095, 0.058, 0.19));
  EXPECT_NEAR(m.num_triangles(), 15000, 1500);
  EXPECT_TRUE(m.closed_and_outward());
  ASSERT_EQ(m.textures.size(), 1u);
  EXPECT_EQ(m.textures[0].width, 2048);
  EXPECT_EQ(m.textures[0].height, 2048);
}

TEST(ScanLike, RejectsBadArguments) {
  EXPECT_THROW(diffdope::make_scan_like(ScanShape::Box, Eigen::Vector3d(0.1, 0.0, 0.1)), std::invalid_argument);
  EXPECT_THROW(diffdope::make_scan_like(ScanShape::Box, Eigen::Vector3d(0.1, 0.1, 0.1), 100), std::invalid_argument);
  EXPECT_THROW(diffdope::make_scan_like(ScanShape::Box, Eigen::Vector3d(0.1, 0.1, 0.1), 2000, 32),
               std::invalid_argument);
}

}  // namespace
