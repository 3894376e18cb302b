// The texture atlas of scan-like objects: charts laid flat and shelf-packed into one texture, which is painted
// with the object's print from the 3-D surface point of each texel and bled into the gutters.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {
namespace {

constexpr float kUnpainted = 1e30f;

/// The texels that no triangle painted (gap[texel] == kUnpainted) take the colour of the nearest painted texel.
void bleed(Texture& tex, const std::vector<float>& gap) {
  const int N = tex.width;
  cv::Mat unpainted(N, N, CV_8UC1), dist, labels;
  for (int y = 0; y < N; ++y) {
    uint8_t* r = unpainted.ptr<uint8_t>(y);
    for (int x = 0; x < N; ++x) r[x] = gap[size_t(N) * y + x] == kUnpainted ? 255 : 0;
  }
  cv::distanceTransform(unpainted, dist, labels, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  std::vector<int> source(size_t(N) * N + 1, -1);
  for (int y = 0; y < N; ++y) {
    const uint8_t* r = unpainted.ptr<uint8_t>(y);
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < N; ++x)
      if (!r[x]) source[size_t(l[x])] = y * N + x;
  }
  for (int y = 0; y < N; ++y) {
    const uint8_t* r = unpainted.ptr<uint8_t>(y);
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < N; ++x) {
      const int from = r[x] ? source[size_t(l[x])] : -1;
      if (from >= 0) std::copy_n(&tex.rgb[size_t(3) * from], 3, &tex.rgb[size_t(3) * (size_t(y) * N + x)]);
    }
  }
}

}  // namespace

FlatCharts flatten_charts(const Soup& soup, const Charts& charts, Mesh& m) {
  const int nt = int(soup.tri.size() / 3);
  FlatCharts flat;
  std::vector<V3>& vnat = flat.nat;
  std::vector<V2>& vplane = flat.plane;
  std::vector<int>& vchart = flat.chart;
  std::vector<ChartRect>& rect = flat.rect;
  // Each chart projected onto its mean plane (principal axis along x), its vertices duplicated.
  std::vector<std::vector<int>> chart_tris(charts.count());
  for (int t = 0; t < nt; ++t) chart_tris[charts.chart[t]].push_back(t);
  m.triangles.assign(3 * nt, -1);
  std::vector<int> stamp(soup.pos.size(), -1), local(soup.pos.size(), -1);
  rect.resize(charts.count());
  for (int c = 0; c < charts.count(); ++c) {
    const auto [t1, t2] = plane_axes(charts.normal[c]);
    const int first = int(vplane.size());
    for (int t : chart_tris[c])
      for (int e = 0; e < 3; ++e) {
        const int g = soup.tri[3 * t + e];
        if (stamp[g] != c) {
          stamp[g] = c;
          local[g] = int(vplane.size());
          vplane.emplace_back(soup.pos[g].dot(t1), soup.pos[g].dot(t2));
          vnat.push_back(soup.nat[g]);
          vchart.push_back(c);
          m.positions.push_back({float(soup.pos[g].x()), float(soup.pos[g].y()), float(soup.pos[g].z())});
        }
        m.triangles[3 * t + e] = local[g];
      }
    // Principal axis of the chart's vertices along x (a rotation: UVs stay counter-clockwise).
    V2 mean = V2::Zero();
    for (int i = first; i < int(vplane.size()); ++i) mean += vplane[i];
    mean /= double(vplane.size() - first);
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (int i = first; i < int(vplane.size()); ++i) cov += (vplane[i] - mean) * (vplane[i] - mean).transpose();
    const double angle = 0.5 * std::atan2(2 * cov(0, 1), cov(0, 0) - cov(1, 1));
    const double ca = std::cos(angle), sa = std::sin(angle);
    ChartRect& r = rect[c];
    for (int i = first; i < int(vplane.size()); ++i) {
      const V2 q = vplane[i] - mean;
      vplane[i] = V2(ca * q.x() + sa * q.y(), -sa * q.x() + ca * q.y());
      r.xmin = std::min(r.xmin, vplane[i].x()), r.xmax = std::max(r.xmax, vplane[i].x());
      r.ymin = std::min(r.ymin, vplane[i].y()), r.ymax = std::max(r.ymax, vplane[i].y());
    }
  }
  return flat;
}

std::vector<V2> pack_atlas(FlatCharts& flat, int texture_size, Mesh& m) {
  const int charts = int(flat.rect.size());
  const std::vector<V2>& vplane = flat.plane;
  const std::vector<int>& vchart = flat.chart;
  std::vector<ChartRect>& rect = flat.rect;
  // Shelf packing (tallest first) at the largest texels-per-metre that fits, a gutter of `pad` texels around
  // each chart.
  const int N = texture_size, pad = std::max(2, N / 256);
  std::vector<int> order(charts);
  for (int c = 0; c < charts; ++c) order[c] = c;
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const double ha = rect[a].ymax - rect[a].ymin, hb = rect[b].ymax - rect[b].ymin;
    return ha != hb ? ha > hb : a < b;
  });
  auto pack = [&](double s, bool place) {
    int x = 0, y = 0, shelf = 0;
    for (int c : order) {
      const int w = int(std::ceil((rect[c].xmax - rect[c].xmin) * s)) + 2 * pad + 1;
      const int h = int(std::ceil((rect[c].ymax - rect[c].ymin) * s)) + 2 * pad + 1;
      if (w > N) return false;
      if (x + w > N) x = 0, y += shelf, shelf = 0;
      if (place) rect[c].px = x, rect[c].py = y;
      x += w;
      shelf = std::max(shelf, h);
      if (y + shelf > N) return false;
    }
    return true;
  };
  double s_lo = 0, s_hi = N / 1e-6;
  for (const ChartRect& r : rect)
    s_hi = std::min(s_hi, N / std::max(1e-9, std::max(r.xmax - r.xmin, r.ymax - r.ymin)));
  for (int it = 0; it < 40; ++it) {
    const double s = 0.5 * (s_lo + s_hi);
    (pack(s, false) ? s_lo : s_hi) = s;
  }
  pack(s_lo, true);
  std::vector<V2> atlas(vplane.size());  // texel coordinates: x right, y down (row 0 = top)
  for (size_t i = 0; i < vplane.size(); ++i) {
    const ChartRect& r = rect[vchart[i]];
    atlas[i] =
        V2(r.px + pad + 0.5 + (vplane[i].x() - r.xmin) * s_lo, r.py + pad + 0.5 + (r.ymax - vplane[i].y()) * s_lo);
    m.uvs.push_back({float(atlas[i].x() / N), float(1.0 - atlas[i].y() / N)});
  }
  return atlas;
}

Texture paint_texture(const ShapeModel& model, const Soup& soup, const Mesh& m, const FlatCharts& flat,
                      const std::vector<V2>& atlas, int texture_size, const std::string& source) {
  const int nt = int(soup.tri.size() / 3), N = texture_size;
  const std::vector<V3>& vnat = flat.nat;
  // Paint: every texel centre inside a triangle gets the colour of its surface point, and so does a ring of
  // 1.5 texels around each chart (the surface continued over the triangle's plane from the nearest triangle),
  // so that filtering at a seam reads the same print on both sides. The rest takes the colour of the nearest
  // painted texel.
  Texture tex;
  tex.width = tex.height = N;
  tex.source = source;
  tex.rgb.assign(size_t(3) * N * N, 0.f);
  constexpr float kRing = 1.5f;
  std::vector<float> gap(size_t(N) * N, kUnpainted);  // texels from the triangle that painted the texel
  for (int t = 0; t < nt; ++t) {
    const int* v = &m.triangles[3 * t];
    const V2 P[3] = {atlas[v[0]], atlas[v[1]], atlas[v[2]]};
    const double area2 = (P[1] - P[0]).x() * (P[2] - P[0]).y() - (P[1] - P[0]).y() * (P[2] - P[0]).x();
    if (std::fabs(area2) < 1e-12) continue;
    double altitude[3];  // distance from each vertex to the opposite edge, texels
    for (int k = 0; k < 3; ++k)
      altitude[k] = std::fabs(area2) / std::max(1e-12, (P[(k + 2) % 3] - P[(k + 1) % 3]).norm());
    const int x0 = std::max(0, int(std::floor(std::min({P[0].x(), P[1].x(), P[2].x()}) - 0.5 - kRing)));
    const int x1 = std::min(N - 1, int(std::ceil(std::max({P[0].x(), P[1].x(), P[2].x()}) - 0.5 + kRing)));
    const int y0 = std::max(0, int(std::floor(std::min({P[0].y(), P[1].y(), P[2].y()}) - 0.5 - kRing)));
    const int y1 = std::min(N - 1, int(std::ceil(std::max({P[0].y(), P[1].y(), P[2].y()}) - 0.5 + kRing)));
    const int part = soup.tri_part[t];
    for (int y = y0; y <= y1; ++y) {
      const double py = y + 0.5;
      float* row = &tex.rgb[size_t(3) * N * y];
      float* grow = &gap[size_t(N) * y];
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5;
        double w[3];
        for (int k = 0; k < 3; ++k) {
          const V2 &a = P[(k + 1) % 3], &b = P[(k + 2) % 3];
          w[k] = ((a.x() - px) * (b.y() - py) - (a.y() - py) * (b.x() - px)) / area2;
        }
        const float d = float(std::max({0.0, -w[0] * altitude[0], -w[1] * altitude[1], -w[2] * altitude[2]}));
        if (d >= kRing || d >= grow[x]) continue;
        grow[x] = d;
        const Rgb col = model.colour(part, w[0] * vnat[v[0]] + w[1] * vnat[v[1]] + w[2] * vnat[v[2]]);
        for (int ch = 0; ch < 3; ++ch) row[3 * x + ch] = std::clamp(col[ch], 0.f, 1.f);
      }
    }
  }
  bleed(tex, gap);
  return tex;
}

}  // namespace scan
}  // namespace diffdope
