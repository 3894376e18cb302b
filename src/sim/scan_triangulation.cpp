// The triangulation of scan-like objects: each closed part sampled ring by ring at a target edge length that
// varies over the surface, rings stitched greedily, the edge length adjusted to the requested triangle count.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <random>
#include <utility>
#include <vector>

#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {
namespace {

/// Triangles between ring a (lower v) and ring b, counter-clockwise in (u, v).
template <class Ring, class AddTri>
void stitch(const Ring& a, const Ring& b, AddTri& add_tri) {
  const int na = int(a.u.size()), nb = int(b.u.size());
  int b0 = 0;  // b's vertex nearest (cyclically) to a's first
  double best = 2;
  for (int k = 0; k < nb; ++k) {
    double d = std::fabs(b.u[k] - a.u[0]);
    d = std::min(d, 1 - d);
    if (d < best) best = d, b0 = k;
  }
  double ub0 = b.u[b0];
  if (ub0 - a.u[0] > 0.5) ub0 -= 1;
  if (ub0 - a.u[0] < -0.5) ub0 += 1;
  auto ua = [&](int i) { return i < na ? a.u[i] : a.u[i - na] + 1; };
  auto ub = [&](int k) {
    if (k >= nb) return ub0 + 1;
    double d = b.u[(b0 + k) % nb] - b.u[b0];
    if (d < 0) d += 1;
    return ub0 + d;
  };
  auto B = [&](int k) { return b.idx[(b0 + k) % nb]; };
  int i = 0, k = 0;
  while (i < na || k < nb) {
    if (k >= nb || (i < na && ua(i + 1) <= ub(k + 1))) {
      add_tri(a.idx[i % na], a.idx[(i + 1) % na], B(k));
      ++i;
    } else {
      add_tri(a.idx[i % na], B(k + 1), B(k));
      ++k;
    }
  }
}

}  // namespace

PartSampler::PartSampler(const ShapeModel& model, int part, std::function<V3(const V3&)> to_final,
                         const Density& density)
    : model_(model), part_(part), to_final_(std::move(to_final)) {
  grid_.resize(size_t(kNV + 1) * kNU);
  rho_.resize(grid_.size());
  for (int k = 0; k <= kNV; ++k)
    for (int i = 0; i < kNU; ++i) {
      grid_[k * kNU + i] = to_final_(model_.surface(part_, double(i) / kNU, double(k) / kNV));
      rho_[k * kNU + i] = density(grid_[k * kNU + i]);
    }
  sigma_.assign(kNV + 1, 0.0);
  area_ = 0;
  for (int k = 1; k <= kNV; ++k) {
    double sum = 0;
    for (int i = 0; i < kNU; ++i) {
      const int a = (k - 1) * kNU + i, b = k * kNU + i, c = (k - 1) * kNU + (i + 1) % kNU;
      const double r = 0.5 * (rho_[a] + rho_[b]);
      sum += (grid_[b] - grid_[a]).norm() / r;
      area_ += (grid_[b] - grid_[a]).cross(grid_[c] - grid_[a]).norm() / (r * r);
    }
    sigma_[k] = sigma_[k - 1] + sum / kNU;
  }
}

int PartSampler::build(double h0, uint32_t seed, Soup* out) const {
  std::mt19937 rng(seed * 2654435761u + uint32_t(part_) * 40503u + 12345u);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double total = sigma_[kNV];
  const int m = std::max(2, int(std::lround(total / h0)));
  std::vector<double> ring_v(m + 1, 0.0);
  ring_v[m] = 1.0;
  for (int j = 1; j < m; ++j) ring_v[j] = invert_table(sigma_, (j + 0.4 * (U(rng) - 0.5)) * total / m) / kNV;
  const int base = out ? int(out->pos.size()) : 0;
  int next = base;
  auto add_vertex = [&](double u, double v) {
    if (out) {
      const V3 nat = model_.surface(part_, u - std::floor(u), v);
      out->nat.push_back(nat);
      out->pos.push_back(to_final_(nat));
    }
    return next++;
  };
  auto add_tri = [&](int a, int b, int c) {
    if (!out) return;
    out->tri.insert(out->tri.end(), {a, b, c});
    out->tri_part.push_back(part_);
  };
  struct Ring {
    std::vector<int> idx;
    std::vector<double> u;  // ascending, in [0, 1)
  };
  int triangles = 0;
  const int pole0 = add_vertex(0.0, 0.0);
  Ring prev;
  std::vector<double> tau(kNU + 1);
  for (int j = 1; j < m; ++j) {
    const double v = ring_v[j], dv = std::min(ring_v[j + 1] - v, v - ring_v[j - 1]);
    const int k = std::min(kNV - 1, int(v * kNV));
    const double f = v * kNV - k;
    auto at = [&](int i) { return (1 - f) * grid_[k * kNU + i % kNU] + f * grid_[(k + 1) * kNU + i % kNU]; };
    auto rho = [&](int i) { return (1 - f) * rho_[k * kNU + i % kNU] + f * rho_[(k + 1) * kNU + i % kNU]; };
    tau[0] = 0;
    for (int i = 0; i < kNU; ++i) tau[i + 1] = tau[i] + (at(i + 1) - at(i)).norm() / (0.5 * (rho(i) + rho(i + 1)));
    const double T = tau[kNU];
    const int n = std::max(3, int(std::lround(T / h0)));
    const double phase = U(rng);
    std::vector<std::pair<double, int>> verts(n);
    for (int i = 0; i < n; ++i) {
      double x = (i + phase + 0.6 * (U(rng) - 0.5)) * T / n;
      const double wrap = std::floor(x / T);
      x -= wrap * T;
      double u = invert_table(tau, x) / kNU;
      u -= std::floor(u);
      const double vi = v + 0.4 * (U(rng) - 0.5) * dv;
      verts[i] = {u, add_vertex(u, vi)};
    }
    std::sort(verts.begin(), verts.end());
    Ring ring;
    for (const auto& [u, id] : verts) ring.u.push_back(u), ring.idx.push_back(id);
    triangles += 2 * n;
    if (j == 1) {
      for (int i = 0; i < n; ++i) add_tri(pole0, ring.idx[(i + 1) % n], ring.idx[i]);
    } else {
      stitch(prev, ring, add_tri);
    }
    prev = std::move(ring);
  }
  const int pole1 = add_vertex(0.0, 1.0);
  const int n = int(prev.idx.size());
  for (int i = 0; i < n; ++i) add_tri(prev.idx[i], prev.idx[(i + 1) % n], pole1);
  return triangles;
}

Soup triangulate(const ShapeModel& model, const std::function<V3(const V3&)>& to_final, const Density& density,
                 int triangles, uint32_t seed) {
  // Adjusting the edge length until the count is within 1 % of the request.
  std::vector<PartSampler> samplers;
  double area = 0;
  for (int part = 0; part < model.parts(); ++part) {
    samplers.emplace_back(model, part, to_final, density);
    area += samplers.back().weighted_area();
  }
  double h0 = std::sqrt(2 * area / triangles);
  for (int iter = 0; iter < 8; ++iter) {
    int count = 0;
    for (const auto& s : samplers) count += s.build(h0, seed, nullptr);
    if (std::abs(count - triangles) <= 0.01 * triangles) break;
    h0 *= std::sqrt(double(count) / triangles);
  }
  Soup soup;
  for (const auto& s : samplers) s.build(h0, seed, &soup);
  return soup;
}

}  // namespace scan
}  // namespace diffdope
