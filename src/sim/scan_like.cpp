// make_scan_like: parametric parts -> jittered ring triangulation -> charts -> packed atlas -> painted texture.
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "diffdope/procedural.hpp"
#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {
namespace {

/// Natural frame -> metres (the final frame).
struct NaturalFrame {
  V3 scale, centre;
  V3 operator()(const V3& p) const { return V3((p - centre).cwiseProduct(scale)); }
};

/// The sampled natural bounding box of `model` onto `size`, centred on the origin.
NaturalFrame natural_frame(const ShapeModel& model, const V3& size) {
  V3 lo = V3::Constant(1e300), hi = V3::Constant(-1e300);
  for (int part = 0; part < model.parts(); ++part)
    for (int k = 0; k <= 256; ++k)
      for (int i = 0; i < 128; ++i) {
        const V3 p = model.surface(part, i / 128.0, k / 256.0);
        lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
      }
  return {size.cwiseQuotient(hi - lo), 0.5 * (lo + hi)};
}

/// Edge-length density from three plane waves in random directions, their wavelength 0.7 of the size's diagonal.
Density random_density(const V3& size, std::mt19937& rng) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  Density density;
  const double wavelength = 0.7 * size.norm();
  for (int i = 0; i < 3; ++i) {
    const double z = 2 * U(rng) - 1, a = 2 * kPi * U(rng), r = std::sqrt(1 - z * z);
    density.k[i] = (2 * kPi / wavelength) * V3(r * std::cos(a), r * std::sin(a), z);
    density.phase[i] = 2 * kPi * U(rng);
  }
  return density;
}

/// Each part outward: its enclosed volume positive.
void orient_outward(Soup& soup, int parts) {
  const int nt = int(soup.tri.size() / 3);
  for (int part = 0; part < parts; ++part) {
    double volume = 0;
    for (int t = 0; t < nt; ++t)
      if (soup.tri_part[t] == part)
        volume += soup.pos[soup.tri[3 * t]].dot(soup.pos[soup.tri[3 * t + 1]].cross(soup.pos[soup.tri[3 * t + 2]]));
    if (volume < 0)
      for (int t = 0; t < nt; ++t)
        if (soup.tri_part[t] == part) std::swap(soup.tri[3 * t + 1], soup.tri[3 * t + 2]);
  }
}

/// The exact bounding box: positions moved and scaled onto `size`, centred on the origin.
void fit_to_size(Soup& soup, const V3& size) {
  V3 lo = V3::Constant(1e300), hi = V3::Constant(-1e300);
  for (const V3& p : soup.pos) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  for (V3& p : soup.pos) p = (p - 0.5 * (lo + hi)).cwiseProduct(size.cwiseQuotient(hi - lo));
}

}  // namespace
}  // namespace scan

Mesh make_scan_like(ScanShape shape, const Eigen::Vector3d& size, int triangles, int texture_size, uint32_t seed) {
  using namespace scan;
  if (!(size.minCoeff() > 0) || !size.allFinite())
    throw std::invalid_argument("make_scan_like: size must be positive (metres)");
  if (triangles < 200) throw std::invalid_argument("make_scan_like: triangles must be >= 200");
  if (texture_size < 64) throw std::invalid_argument("make_scan_like: texture_size must be >= 64");
  const std::unique_ptr<ShapeModel> model = make_shape_model(shape);
  std::mt19937 rng(seed ^ (uint32_t(shape) * 0x9E3779B9u));  // shapes of one seed get different prints

  const NaturalFrame to_final = natural_frame(*model, size);
  model->prepare_print(to_final.scale, texture_size, rng);
  const Density density = random_density(size, rng);

  Soup soup = triangulate(*model, to_final, density, triangles, seed);
  orient_outward(soup, model->parts());
  fit_to_size(soup, size);

  // UV charts, laid flat (the mesh's vertices, duplicated along chart borders) and packed into the atlas, which
  // is painted with the print.
  const Charts charts = make_charts(soup, triangle_geometry(soup), rng);
  Mesh m;
  FlatCharts flat = flatten_charts(soup, charts, m);
  const std::vector<V2> atlas = pack_atlas(flat, texture_size, m);
  Texture tex =
      paint_texture(*model, soup, m, flat, atlas, texture_size, std::string(model->name()) + std::to_string(seed));

  m.colors.assign(m.positions.size(), {0.7f, 0.7f, 0.7f});
  m.tri_texture.assign(soup.tri.size() / 3, 0);
  m.textures.push_back(std::move(tex));
  m.name = model->name();
  m.finalize();
  return m;
}

}  // namespace diffdope
