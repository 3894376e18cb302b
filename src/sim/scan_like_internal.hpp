#pragma once
// The steps of make_scan_like (procedural.hpp): the print (scan_print.cpp), the shapes (scan_shapes.cpp), the ring
// triangulation (scan_triangulation.cpp), the charts (scan_charts.cpp), the atlas and its texture (scan_atlas.cpp).
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "diffdope/mesh.hpp"
#include "diffdope/procedural.hpp"

namespace diffdope {
namespace scan {

using V2 = Eigen::Vector2d;
using V3 = Eigen::Vector3d;
using Rgb = cv::Vec3f;  // RGB in [0, 1]
constexpr double kPi = 3.14159265358979323846;

/// Index and fraction where an increasing table reaches `value` (linear interpolation between entries).
double invert_table(const std::vector<double>& table, double value);

// ---- Print: panels drawn with OpenCV (8-bit for antialiased text), sampled bilinearly in float ----

constexpr int kPaletteSize = 12;
extern const Rgb kPalette[kPaletteSize];

inline Rgb mix(const Rgb& a, const Rgb& b, float t) { return a * (1.f - t) + b * t; }

struct Brand {
  Rgb bg, bg2, accent, accent2, ink, light;
  std::string name, product;
};

/// A brand: background, accent and ink colours from the palette, a name and a product.
Brand make_brand(std::mt19937& rng);

enum class Design { Front, Back, Side, Plain };

/// One printed panel (a label, a box face, a band) inside rectangle r of `img` (CV_8UC3, RGB).
void draw_design(cv::Mat& img, const cv::Rect& r, Design design, const Brand& b, std::mt19937& rng);

/// A printed area on the object, sampled at (s, t) in [0, 1]^2: s left to right, t bottom to top as seen from
/// outside with the object upright.
class Panel {
 public:
  Panel() = default;
  Panel(const cv::Mat& rgb8) { rgb8.convertTo(img_, CV_32FC3, 1.0 / 255.0); }
  Rgb sample(double s, double t) const {
    const float x = std::clamp(float(s * img_.cols - 0.5), 0.f, float(img_.cols - 1));
    const float y = std::clamp(float((1.0 - t) * img_.rows - 0.5), 0.f, float(img_.rows - 1));
    const int x0 = std::min(int(x), img_.cols - 2), y0 = std::min(int(y), img_.rows - 2);
    const float fx = x - x0, fy = y - y0;
    const Rgb* r0 = img_.ptr<Rgb>(y0) + x0;
    const Rgb* r1 = img_.ptr<Rgb>(y0 + 1) + x0;
    return (r0[0] * (1 - fx) + r0[1] * fx) * (1 - fy) + (r1[0] * (1 - fx) + r1[1] * fx) * fy;
  }

 private:
  cv::Mat img_;
};

/// Panel pixel size for a printed area of w x h metres at `px_per_m`.
cv::Size panel_size(double w, double h, double px_per_m);

/// A panel of `size` pixels printed with `design`.
Panel make_panel(cv::Size size, Design design, const Brand& b, std::mt19937& rng);

// ---- Shapes ----

/// An object made of closed parametric parts: part(u, v) with u periodic in [0, 1) and poles at v = 0 and 1
/// (the point does not depend on u there), in the shape's natural frame; and its print.
class ShapeModel {
 public:
  virtual ~ShapeModel() = default;
  virtual const char* name() const = 0;
  virtual int parts() const = 0;
  virtual V3 surface(int part, double u, double v) const = 0;
  /// Draws the print once the metres per natural unit along each axis are known.
  virtual void prepare_print(const V3& scale, int texture_size, std::mt19937& rng) = 0;
  /// Colour of the surface point p (natural frame) of `part`.
  virtual Rgb colour(int part, const V3& p) const = 0;
};

/// The model of `shape`; throws std::invalid_argument for an unknown one.
std::unique_ptr<ShapeModel> make_shape_model(ScanShape shape);

// ---- Triangulation ----

/// Edge-length multiplier in [0.71, 1.41], smooth over the object: triangle areas vary about 1:4.
struct Density {
  V3 k[3];
  double phase[3];
  double operator()(const V3& p) const {
    double n = 0;
    for (int i = 0; i < 3; ++i) n += std::sin(k[i].dot(p) + phase[i]);
    return std::exp2(0.5 * std::clamp(n / 1.5, -1.0, 1.0));
  }
};

struct Soup {
  std::vector<V3> pos;  // final frame
  std::vector<V3> nat;  // natural frame (for the print)
  std::vector<int> tri;
  std::vector<int> tri_part;
};

/// One closed part sampled ring by ring: rings every ~h (arc length along v, mean over u), ~h apart along each
/// ring, h = h0 * density; random ring phases, jittered vertices, rings stitched greedily by u.
class PartSampler {
 public:
  PartSampler(const ShapeModel& model, int part, std::function<V3(const V3&)> to_final, const Density& density);
  /// Density-weighted area (metres^2 / density^2): about h0^2 / 2 per triangle.
  double weighted_area() const { return area_; }
  /// Triangle count for edge length h0; appends the part to `out` when non-null (same result either way).
  int build(double h0, uint32_t seed, Soup* out) const;

 private:
  static constexpr int kNU = 256, kNV = 512;
  const ShapeModel& model_;
  int part_;
  std::function<V3(const V3&)> to_final_;
  std::vector<V3> grid_;
  std::vector<double> rho_;
  std::vector<double> sigma_;
  double area_ = 0;
};

/// All parts of `model` triangulated with about `triangles` triangles in all, in the final frame (`to_final`).
Soup triangulate(const ShapeModel& model, const std::function<V3(const V3&)>& to_final, const Density& density,
                 int triangles, uint32_t seed);

// ---- Charts ----

/// Per triangle of a Soup: unit normal, centroid, area, and the triangle across each edge (-1: none).
struct TriangleGeometry {
  std::vector<V3> normal, centroid;
  std::vector<double> area;
  std::vector<std::array<int, 3>> nb;
};
TriangleGeometry triangle_geometry(const Soup& soup);

/// The UV charts: per triangle its chart (0 .. count - 1, none empty), per chart its mean normal.
struct Charts {
  std::vector<int> chart;
  std::vector<V3> normal;
  int count() const { return int(normal.size()); }
};
/// Charts grown from farthest-point seeds, small ones merged, until each projects one to one onto its mean plane.
Charts make_charts(const Soup& soup, const TriangleGeometry& geometry, std::mt19937& rng);

/// Orthonormal chart-plane axes (t1, t2) with t1 x t2 = n.
std::pair<V3, V3> plane_axes(const V3& n);

// ---- Atlas ----

/// A chart's extent in its plane (metres) and, once packed, the corner of its rectangle in the atlas (texels).
struct ChartRect {
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  int px = 0, py = 0;
};

/// The charts laid flat: one vertex per surface vertex and chart it is in (vertices on chart borders duplicated).
struct FlatCharts {
  std::vector<V3> nat;    // natural frame (for the print)
  std::vector<V2> plane;  // chart-plane coordinates, metres
  std::vector<int> chart;
  std::vector<ChartRect> rect;  // per chart
};

/// Each chart projected onto its mean plane (principal axis along x); the mesh's positions and triangles over
/// the flat vertices go into `m`.
FlatCharts flatten_charts(const Soup& soup, const Charts& charts, Mesh& m);

/// Packs the charts into a texture_size² atlas: their rectangles placed (flat.rect), the mesh's UVs appended to
/// `m`. Returns each flat vertex's texel coordinates (x right, y down, row 0 = top).
std::vector<V2> pack_atlas(FlatCharts& flat, int texture_size, Mesh& m);

/// The atlas texture: the print of `model` painted over the charts and bled into the space between them.
Texture paint_texture(const ShapeModel& model, const Soup& soup, const Mesh& m, const FlatCharts& flat,
                      const std::vector<V2>& atlas, int texture_size, const std::string& source);

}  // namespace scan
}  // namespace diffdope
