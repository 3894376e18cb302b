// The CPU's SIMD rows against their one-pixel kernels, bit for bit, over rows of every length around the vector
// width: loss_row() against pixel_loss_step() (every value, gradient and sum, over the cases the formula
// distinguishes), shade_row() against shade_pixel() (triangle, attributes, barycentrics, texture derivatives),
// blend_row() against discontinuity_blend() (every event slot, every field of every event), raster_batch() and
// the 32-bit raster of small triangles against the 64-bit raster (the z-buffer, which triangles are left).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include "render/kernels/vertex_stage.hpp"
#include "diffdope/procedural.hpp"
#include "render/kernel_inputs.hpp"
#include "render/stages.hpp"
#include "render/simd_rows.hpp"

namespace {
using namespace diffdope;

template <class T>
bool same_bits(T a, T b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

struct RowData {
  std::vector<PixelAttr> post;
  std::vector<float> S, I, D;
};

/// Pixels drawn from the cases pixel_loss() tells apart: uncovered, covered and blended coverage; observed mask
/// 0, 1 or partial; no depth reading, a valid one, an occluder far in front, NaN; now and then a NaN colour.
RowData make_row(int n, std::mt19937& rng) {
  std::uniform_real_distribution<float> u(0.f, 1.f);
  const auto pick = [&](std::initializer_list<float> v) { return *(v.begin() + int(u(rng) * float(v.size()) * 0.999f)); };
  const float nan = std::numeric_limits<float>::quiet_NaN();
  RowData r;
  for (int i = 0; i < n; ++i) {
    const float cov = pick({0.f, 1.f, 0.3f, 0.5f, 1.f});
    const float depth = 0.4f + 0.2f * u(rng);
    r.post.push_back(PixelAttr{cov, {cov * u(rng), cov * u(rng), cov * u(rng)}, cov * depth});
    r.S.push_back(pick({0.f, 1.f, 1.f, 0.5f, 0.2f}));
    for (int c = 0; c < 3; ++c) r.I.push_back(u(rng) < 0.03f ? nan : u(rng));
    r.D.push_back(pick({0.f, -1.f, depth + 0.01f, depth - 0.3f, depth + 0.2f, nan}));
  }
  return r;
}

TEST(SimdRows, ARowGivesThePixelKernelsBitsForEveryValueGradientAndSum) {
  std::mt19937 rng(7);
  std::vector<PixelLossParams> params = {{0.3f, 0.2f, 0.1f, 0.5f, 0.05f, 0.02f},   // every term, occlusion on
                                         {0.3f, 0.f, 0.1f, 0.5f, 0.05f, 0.f},      // no depth term, no occlusion
                                         {0.f, 0.2f, 0.f, 0.25f, 0.03f, 0.02f},    // depth alone
                                         {0.3f, 0.2f, 0.1f, 0.5f, 0.05f, 0.02f, 1.f / 0.45f, 2},  // noise ~ z^2
                                         {0.f, 0.2f, 0.f, 0.25f, 0.03f, 0.f, 1.f / 0.55f, 1}};    // noise ~ z
  int rows = 0;
  for (const PixelLossParams& P : params)
    for (int n : {0, 1, 3, 4, 7, 8, 9, 15, 16, 17, 31, 32, 33, 64, 101})
      for (int absent = 0; absent < 8; ++absent)  // bit 0: no S, bit 1: no rgb, bit 2: no depth
        for (bool gradient : {false, true}) {
          const RowData d = make_row(n, rng);
          std::vector<PixelAttr> g(size_t(n), PixelAttr{-7.f, {-7.f, -7.f, -7.f}, -7.f});
          const LossRow row{P, d.post.data(), absent & 1 ? nullptr : d.S.data(), absent & 2 ? nullptr : d.I.data(),
                            absent & 4 ? nullptr : d.D.data(), gradient ? g.data() : nullptr, n};
          double sum[3] = {0.5, 0.25, 0.125};  // loss_row adds to what is there
          const int done = loss_row(row, sum);
          ASSERT_LE(done, n);
          if (n >= 64 && simd_rows_built()) ASSERT_GT(done, 0) << "a vector holds at most 64 floats (2048-bit SVE)";
          double want[3] = {0.5, 0.25, 0.125};
          const float zero3[3] = {0.f, 0.f, 0.f};
          for (int x = 0; x < done; ++x) {
            PixelLossGrad pg;
            const PixelAttr& a = d.post[size_t(x)];
            const PixelLossValue v = pixel_loss_step(P, row.S ? row.S[x] : 1.f, row.I ? row.I + 3 * x : zero3,
                                                     row.D ? row.D[x] : 0.f, a.cov, a.c, a.d, &pg);
            want[0] += double(v.rgb), want[1] += double(v.depth), want[2] += double(v.mask);
            const PixelAttr& got = g[size_t(x)];
            if (gradient) {
              ASSERT_TRUE(same_bits(got.cov, pg.cov) && same_bits(got.d, pg.d) && same_bits(got.c[0], pg.c[0]) &&
                          same_bits(got.c[1], pg.c[1]) && same_bits(got.c[2], pg.c[2]))
                  << "gradient of pixel " << x << " of " << n << ": " << got.cov << " vs " << pg.cov;
            } else {
              ASSERT_EQ(got.cov, -7.f) << "no gradient asked, none written";
            }
          }
          for (int x = done; x < n; ++x) ASSERT_EQ(g[size_t(x)].cov, -7.f) << "the rest is the caller's";
          for (int k = 0; k < 3; ++k)
            ASSERT_TRUE(same_bits(sum[k], want[k])) << "term " << k << ", n " << n << ": " << sum[k] << " vs " << want[k];
          ++rows;
        }
  EXPECT_EQ(rows, int(params.size()) * 15 * 8 * 2);
  std::printf("loss_row runs on %s\n", simd_row_target());
}

/// A scan-like mesh's triangles seen by a camera, with the per-triangle inputs of the shade stage chosen to reach
/// every case of the lookup: mip levels whole, fractional, the last one and beyond what a small texture has; some
/// triangles vertex-coloured; pixel centres inside and far outside their triangle (UVs past the texture's border).
struct ShadeScene {
  Mesh mesh;
  std::vector<TextureView> textures;
  std::vector<Vec3f> cam;
  std::vector<float> area, level;
  std::vector<int> tri_texture;
  MeshView M;
  ProjectedView G;
  Intrinsics K{300.f, 310.f, 160.5f, 120.25f, 320, 240};

  ShadeScene(bool uvs, std::mt19937& rng) : mesh(make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.19), 1500, 128, 3)) {
    std::uniform_real_distribution<float> u(0.f, 1.f);
    M = make_mesh_view(mesh, textures);
    if (!uvs) M.uvs = nullptr;
    const int levels = textures.at(0).levels;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
    for (int i = 0; i < M.num_vertices; ++i) {
      const Eigen::Vector3d p(M.positions[i].x, M.positions[i].y, M.positions[i].z);
      const Eigen::Vector3d X = R * p + Eigen::Vector3d(0.01, -0.02, 0.45);
      cam.push_back(Vec3f{float(X.x()), float(X.y()), float(X.z())});
    }
    tri_texture.assign(M.tri_texture, M.tri_texture + M.num_triangles);
    for (int t = 0; t < M.num_triangles; ++t) {
      if (u(rng) < 0.15f) tri_texture[size_t(t)] = -1;
      const float pick = u(rng);
      level.push_back(pick < 0.2f ? float(int(u(rng) * float(levels))) : pick < 0.3f ? float(levels - 1)
                                                                     : u(rng) * float(levels - 1));
      area.push_back(1.f);
    }
    M.tri_texture = tri_texture.data();
    G = ProjectedView{cam.data(), nullptr, area.data(), level.data()};
  }
};

TEST(PixelLoss, ADepthReadingWeighsAsItsNoiseGrows) {
  // A fully covered, observed pixel whose reading is 1 cm behind the render: with tau = 5 cm fixed it costs 0.2
  // wherever it is; with the noise growing as z^p about z_ref = 1 m, tau is 5 cm * z^p at the reading's depth z,
  // so a reading at 2 m costs about a quarter of that (p = 2) and one at 0.2 m saturates at 1.
  const float I[3] = {0.f, 0.f, 0.f}, C[3] = {0.f, 0.f, 0.f};
  PixelLossParams P{0.f, 1.f, 0.f, 0.5f, 0.05f, 0.f};
  const auto depth_term = [&](float z) { return pixel_loss_step(P, 1.f, I, z + 0.01f, 1.f, C, z, nullptr).depth; };
  EXPECT_NEAR(depth_term(1.f), 0.2f, 1e-5f);
  EXPECT_NEAR(depth_term(2.f), 0.2f, 1e-5f);
  P.depth_noise_scale = 1.f, P.depth_noise_power = 2;
  EXPECT_NEAR(depth_term(1.f), 0.01f / (0.05f * 1.01f * 1.01f), 1e-5f);
  EXPECT_NEAR(depth_term(2.f), 0.01f / (0.05f * 2.01f * 2.01f), 1e-5f);
  EXPECT_FLOAT_EQ(depth_term(0.2f), 1.f);  // beyond its tau (2.2 mm): saturated
  P.depth_noise_scale = 0.5f;  // z_ref = 2 m: the reading at 2 m has the fixed tau again
  EXPECT_NEAR(depth_term(2.f), 0.01f / (0.05f * 1.005f * 1.005f), 1e-5f);
  P.depth_noise_scale = 1.f, P.depth_noise_power = 1;
  EXPECT_NEAR(depth_term(2.f), 0.01f / (0.05f * 2.01f), 1e-5f);
  // Without a reading there is no depth term, whatever the power (a missing reading is no evidence).
  P.depth_noise_power = 2;
  EXPECT_FLOAT_EQ(pixel_loss_step(P, 1.f, I, 0.f, 1.f, C, 1.f, nullptr).depth, 0.f);
}

TEST(SimdRows, AShadeRowGivesThePixelKernelsBitsForTriangleAttributesAndBarycentrics) {
  std::mt19937 rng(11);
  int rows = 0, covered = 0;
  for (bool uvs : {true, false}) {
    ShadeScene sc(uvs, rng);
    std::uniform_int_distribution<int> tri(0, sc.M.num_triangles - 1);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (int n : {0, 1, 3, 7, 8, 9, 15, 16, 17, 31, 32, 33, 64, 101})
      for (int rep = 0; rep < 4; ++rep) {
        // Runs of one triangle (neighbouring pixels of a real raster), empty pixels now and then.
        std::vector<unsigned long long> key(static_cast<size_t>(n));
        int t = tri(rng);
        for (auto& k : key) {
          if (u(rng) < 0.3f) t = tri(rng);
          k = u(rng) < 0.15f ? pipeline::kEmptyKey : (0x3f000000ull << 32) | unsigned(t);
        }
        const PixelAttr stale{-7.f, {-7.f, -7.f, -7.f}, -7.f};
        std::vector<int> tri_out(size_t(n), -9);
        std::vector<PixelAttr> pre(size_t(n), stale), post(size_t(n), stale);
        std::vector<detail::ShadeBary> bary(static_cast<size_t>(n));
        const int x = 40 + 13 * rep, y = 30 + 41 * rep;
        const ShadeRow row{sc.M, sc.G, sc.K, key.data(), tri_out.data(), pre.data(), post.data(), bary.data(), x,
                           float(y), n};
        const int done = shade_row(row);
        ASSERT_LE(done, n);
        if (n >= 64 && simd_rows_built()) ASSERT_GT(done, 0) << "a vector holds at most 64 floats (2048-bit SVE)";
        for (int i = 0; i < done; ++i) {
          const int want_t = pipeline::key_triangle(key[size_t(i)]);
          ASSERT_EQ(tri_out[size_t(i)], want_t);
          PixelAttr want{0.f, {0.f, 0.f, 0.f}, 0.f};
          detail::ShadeBary wb{};
          if (want_t >= 0) {
            Vec3f c;
            float d;
            shade_pixel(sc.M, sc.G, sc.K, want_t, float(x + i), float(y), &c, &d, false, &wb);
            want = PixelAttr{1.f, {c.x, c.y, c.z}, d};
            ++covered;
            const detail::ShadeBary& gb = bary[size_t(i)];
            for (int k = 0; k < 3; ++k)
              ASSERT_TRUE(same_bits(gb.raw[k], wb.raw[k]) && same_bits(gb.b[k], wb.b[k]))
                  << "barycentric " << k << " of pixel " << i << " of " << n;
            ASSERT_TRUE(same_bits(gb.s, wb.s));
            ASSERT_EQ(gb.clamped, wb.clamped);
            const float g[6] = {gb.dcdu.x, gb.dcdu.y, gb.dcdu.z, gb.dcdv.x, gb.dcdv.y, gb.dcdv.z};
            const float w[6] = {wb.dcdu.x, wb.dcdu.y, wb.dcdu.z, wb.dcdv.x, wb.dcdv.y, wb.dcdv.z};
            for (int k = 0; k < 6; ++k)
              ASSERT_TRUE(same_bits(g[k], w[k])) << "texture derivative " << k << " of pixel " << i << ": " << g[k]
                                                 << " vs " << w[k];
          }
          for (const PixelAttr* got : {&pre[size_t(i)], &post[size_t(i)]}) {
            ASSERT_TRUE(same_bits(got->cov, want.cov) && same_bits(got->d, want.d)) << "pixel " << i << " of " << n;
            for (int ch = 0; ch < 3; ++ch)
              ASSERT_TRUE(same_bits(got->c[ch], want.c[ch]))
                  << "colour " << ch << " of pixel " << i << " of " << n << ": " << got->c[ch] << " vs " << want.c[ch];
          }
        }
        for (int i = done; i < n; ++i)
          ASSERT_TRUE(tri_out[size_t(i)] == -9 && pre[size_t(i)].cov == -7.f && post[size_t(i)].cov == -7.f)
              << "the rest is the caller's";
        ++rows;
      }
  }
  EXPECT_EQ(rows, 2 * 14 * 4);
  if (simd_rows_built()) EXPECT_GT(covered, 1000);  // (without Highway the rows do no pixel)
}

/// A scan-like bottle drawn by a brute-force z-buffer (nearest triangle whose interior holds the pixel centre,
/// back faces too) in a region that cuts it, with the per-triangle inputs of the blend detection: projected vertices, areas (a few set
/// to 0: undrawn neighbours), mip levels, and extra colour seams. `focal`: small ones make most triangles
/// smaller than a pixel (long walks between pixel centres).
struct BlendScene {
  Mesh mesh;
  std::vector<TextureView> textures;
  std::vector<Vec3f> cam;
  std::vector<Vec2f> pix;
  std::vector<float> area, level;
  std::vector<unsigned char> seams;
  MeshView M;
  ProjectedView G;
  Intrinsics K;
  int x0 = 0, y0 = 0, w = 0, h = 0;
  std::vector<int> tri;
  std::vector<PixelAttr> pre;

  BlendScene(float focal, std::mt19937& rng)
      : mesh(make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.19), 1500, 128, 3)),
        K{focal, focal * 1.03f, 160.5f, 120.25f, 320, 240} {
    std::uniform_real_distribution<float> u(0.f, 1.f);
    M = make_mesh_view(mesh, textures);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
    float lx = 1e9f, hx = -1e9f, ly = 1e9f, hy = -1e9f;
    for (int i = 0; i < M.num_vertices; ++i) {
      const Eigen::Vector3d X = R * Eigen::Vector3d(M.positions[i].x, M.positions[i].y, M.positions[i].z) +
                                Eigen::Vector3d(0.01, -0.02, 0.45);
      cam.push_back(Vec3f{float(X.x()), float(X.y()), float(X.z())});
      pix.push_back(project(K, cam.back()));
      lx = std::min(lx, pix.back().x), hx = std::max(hx, pix.back().x);
      ly = std::min(ly, pix.back().y), hy = std::max(hy, pix.back().y);
    }
    seams.assign(M.seams, M.seams + 3 * M.num_triangles);
    for (int t = 0; t < M.num_triangles; ++t) {
      area.push_back(u(rng) < 0.03f ? 0.f : triangle_setup(M, cam.data(), pix.data(), 0.01f, false, t));
      level.push_back(triangle_mip_level(M, t, area.back()));
      for (int k = 0; k < 3; ++k) seams[size_t(3 * t + k)] |= u(rng) < 0.1f ? 1 : 0;
    }
    M.seams = seams.data();
    G = ProjectedView{cam.data(), pix.data(), area.data(), level.data()};
    // The region cuts the object on every side (as the image border may): pairs at its last column and row.
    x0 = int(lx + 0.2f * (hx - lx)), y0 = int(ly + 0.2f * (hy - ly));
    w = int(hx - 0.2f * (hx - lx)) - x0, h = int(hy - 0.2f * (hy - ly)) - y0;
    tri.assign(size_t(w * h), -1);
    pre.assign(size_t(w * h), PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f});
    std::vector<float> depth(size_t(w * h), 1e9f);
    for (int t = 0; t < M.num_triangles; ++t) {
      if (area[size_t(t)] == 0.f) continue;
      const int* v = M.triangles + 3 * t;
      const Vec2f s[3] = {pix[size_t(v[0])], pix[size_t(v[1])], pix[size_t(v[2])]};
      const float z = (cam[size_t(v[0])].z + cam[size_t(v[1])].z + cam[size_t(v[2])].z) / 3.f;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
          const Vec2f c{float(x0 + x), float(y0 + y)};
          const float sign = area[size_t(t)] > 0.f ? 1.f : -1.f;
          bool inside = true;
          for (int k = 0; k < 3; ++k) inside = inside && sign * edge_function(s[k], s[(k + 1) % 3], c) >= 0.f;
          const size_t q = size_t(y * w + x);
          if (inside && z < depth[q]) depth[q] = z, tri[q] = t, pre[q] = PixelAttr{1.f, {0.5f, 0.5f, 0.5f}, z};
        }
    }
  }
};

bool same_event(const BlendEvent& a, const BlendEvent& b) {
  const auto& x = a.src_bary;
  const auto& y = b.src_bary;
  bool same = a.to == b.to && same_bits(a.w, b.w) && same_bits(a.dw_dt, b.dw_dt) && a.tri == b.tri &&
              a.edge == b.edge && a.src_tri == b.src_tri && x.clamped == y.clamped && same_bits(x.s, y.s);
  for (const auto& [p, q] : {std::make_pair(a.pf, b.pf), std::make_pair(a.po, b.po), std::make_pair(a.p_to, b.p_to)})
    same = same && same_bits(p.x, q.x) && same_bits(p.y, q.y);
  same = same && same_bits(a.from.cov, b.from.cov) && same_bits(a.from.d, b.from.d);
  for (int k = 0; k < 3; ++k)
    same = same && same_bits(a.from.c[k], b.from.c[k]) && same_bits(x.raw[k], y.raw[k]) && same_bits(x.b[k], y.b[k]);
  const float g[6] = {x.dcdu.x, x.dcdu.y, x.dcdu.z, x.dcdv.x, x.dcdv.y, x.dcdv.z};
  const float f[6] = {y.dcdu.x, y.dcdu.y, y.dcdu.z, y.dcdv.x, y.dcdv.y, y.dcdv.z};
  for (int k = 0; k < 6; ++k) same = same && same_bits(g[k], f[k]);
  return same;
}

TEST(SimdRows, ABlendRowGivesThePixelKernelsEventsBitForBit) {
  std::mt19937 rng(13);
  long pairs = 0, events = 0, rows = 0;
  for (float focal : {300.f, 180.f, 110.f}) {
    BlendScene sc(focal, rng);
    const size_t n_px = sc.tri.size();
    // The one-pixel kernel's events (BlendDetectStage::pixel()).
    std::vector<BlendEvent> want(2 * n_px);
    std::vector<unsigned char> want_has(2 * n_px, 0);
    for (int y = 0; y < sc.h; ++y)
      for (int x = 0; x < sc.w; ++x)
        for (int dir = 0; dir < 2; ++dir) {
          const int a = y * sc.w + x, b = dir == 0 ? a + 1 : a + sc.w;
          if (dir == 0 ? x + 1 >= sc.w : y + 1 >= sc.h) continue;
          const Vec2f pa{float(sc.x0 + x), float(sc.y0 + y)};
          const Vec2f pb = dir == 0 ? Vec2f{pa.x + 1.f, pa.y} : Vec2f{pa.x, pa.y + 1.f};
          pairs += sc.tri[size_t(a)] != sc.tri[size_t(b)];
          want_has[size_t(2 * a + dir)] =
              discontinuity_blend(sc.M, sc.G, sc.K, a, sc.tri[size_t(a)], sc.pre[size_t(a)].d, pa, b,
                                  sc.tri[size_t(b)], sc.pre[size_t(b)].d, pb, dir == 0, &want[size_t(2 * a + dir)]);
          events += want_has[size_t(2 * a + dir)];
        }
    // Spans of every row: those ending at the region's last column, of every length up to 70 (so that whole
    // vectors reach that column, whatever their width), and three more anywhere.
    for (int y = 0; y < sc.h; ++y) {
      std::uniform_int_distribution<int> lo_of(0, sc.w - 1);
      for (int rep = 0; rep < std::min(sc.w, 70) + 3; ++rep) {
        const int lo = rep < std::min(sc.w, 70) ? sc.w - 1 - rep : lo_of(rng);
        const int hi = rep < std::min(sc.w, 70) ? sc.w - 1 : std::uniform_int_distribution<int>(lo, sc.w - 1)(rng);
        std::vector<BlendEvent> got(2 * n_px);
        std::vector<unsigned char> has(2 * n_px, 7);
        const BlendRow r{sc.M, sc.G, sc.K, sc.tri.data(), sc.pre.data(), got.data(), has.data(), y * sc.w + lo,
                         sc.w, sc.w - 1 - lo, y + 1 < sc.h, sc.x0 + lo, float(sc.y0 + y), hi - lo + 1};
        const int done = blend_row(r);
        ASSERT_LE(done, hi - lo + 1);
        for (int i = 0; i < hi - lo + 1; ++i)
          for (int dir = 0; dir < 2; ++dir) {
            const size_t slot = size_t(2 * (y * sc.w + lo + i) + dir);
            if (i >= done) {
              ASSERT_EQ(has[slot], 7) << "the rest is the caller's";
              continue;
            }
            ASSERT_EQ(has[slot], want_has[slot]) << "pixel " << lo + i << ", row " << y << ", direction " << dir;
            if (has[slot]) ASSERT_TRUE(same_event(got[slot], want[slot])) << "pixel " << lo + i << ", row " << y;
          }
        ++rows;
      }
    }
  }
  EXPECT_GT(pairs, 2500);
  EXPECT_GT(events, 600);
  std::printf("%ld rows, %ld pairs of different triangles, %ld events\n", rows, pairs, events);
}

/// The 64-bit raster of raster.hpp for one triangle (as RasterStage::draw() for triangles that are not small)
/// into a region's z-buffer.
void raster_64bit(const Vec2f s[3], const float z[3], int t, int rx0, int rx1, int ry0, int ry1,
                  std::vector<unsigned long long>& key) {
  TriangleRaster R;
  raster_bounds(s, &R.x0, &R.x1, &R.y0, &R.y1);
  if (!triangle_raster_setup(s, z, &R)) return;
  for (int y = std::max(ry0, R.y0); y <= std::min(ry1, R.y1); ++y)
    for (int x = std::max(rx0, R.x0); x <= std::min(rx1, R.x1); ++x) {
      long long e[3];
      raster_edges_at(R, x, y, e);
      if (!raster_inside(R, e[0], e[1], e[2])) continue;
      const float iz = raster_inverse_depth(R, e[0], e[1], e[2]);
      if (!(iz > 0.f)) continue;
      pipeline::key_min(&key[size_t((y - ry0) * (rx1 - rx0 + 1) + x - rx0)],
                        (static_cast<unsigned long long>(pipeline::depth_key(iz)) << 32) | unsigned(t));
    }
}

TEST(SimdRows, TheSmallTriangleRasterCoversAndDepthsAsThe64BitOne) {
  // Random triangles of bounds up to kSmallTriangleCentres centres a side, half of them with vertices on the
  // fixed-point grid near pixel centres (edges through centres: the fill rule decides), some degenerate.
  std::mt19937 rng(19);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  long centres = 0, covered = 0;
  for (int rep = 0; rep < 20000; ++rep) {
    const float cx = 100.f + 400.f * u(rng), cy = 50.f + 300.f * u(rng), size = 0.3f + 4.6f * u(rng);
    Vec2f s[3];
    for (Vec2f& v : s) {
      v = Vec2f{cx + size * u(rng), cy + size * u(rng)};
      if (rep % 2) v = Vec2f{std::round(v.x * 4.f) / 4.f, std::round(v.y * 2.f) / 2.f};
    }
    if (rep % 50 == 0) s[2] = s[1];
    const float z[3] = {0.4f + u(rng), 0.4f + u(rng), 0.4f + u(rng)};
    int x0, x1, y0, y1;
    raster_bounds(s, &x0, &x1, &y0, &y1);
    if (x1 - x0 >= kSmallTriangleCentres || y1 - y0 >= kSmallTriangleCentres) continue;
    const float sx[3] = {s[0].x, s[1].x, s[2].x}, sy[3] = {s[0].y, s[1].y, s[2].y};
    const SmallTriangleLanes<ScalarLanes> T = raster_small_setup_lanes<ScalarLanes>(sx, sy, z);
    TriangleRaster R;
    R.x0 = x0, R.x1 = x1, R.y0 = y0, R.y1 = y1;
    const bool drawn = triangle_raster_setup(s, z, &R);
    ASSERT_EQ(T.drawn, drawn);
    if (!drawn) continue;
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        long long e[3];
        raster_edges_at(R, x, y, e);
        float iz;
        const bool in = raster_small_centre_lanes<ScalarLanes>(T, x, y, &iz);
        ASSERT_EQ(in, raster_inside(R, e[0], e[1], e[2])) << "triangle " << rep << ", centre " << x << ", " << y;
        if (in) ASSERT_TRUE(same_bits(iz, raster_inverse_depth(R, e[0], e[1], e[2])));
        ++centres, covered += in;
      }
  }
  EXPECT_GT(centres, 20000);
  EXPECT_GT(covered, 5000);
}

TEST(SimdRows, ARasterBatchDrawsTheSmallTrianglesAndLeavesTheOthersThatMeetTheRegion) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  long left = 0, looked_at = 0;
  for (float focal : {900.f, 300.f, 110.f}) {  // triangles of several pixels, of about one, mostly between centres
    BlendScene sc(focal, rng);
    std::vector<float> area = sc.area;
    for (float& a : area) a = u(rng) < 0.2f ? 0.f : a;  // culled or clipped
    std::vector<Vec2f> pix = sc.pix;
    for (Vec2f& p : pix)  // now and then far outside the image (clamped to +-2^30 when made ints)
      if (u(rng) < 0.01f) p.x = u(rng) < 0.5f ? -3e9f : 5e9f;
    for (int rep = 0; rep < 40; ++rep) {
      const int rx0 = sc.x0 - 5 + int(u(rng) * float(sc.w)), ry0 = sc.y0 - 5 + int(u(rng) * float(sc.h));
      const int rx1 = rx0 + int(u(rng) * float(sc.w)), ry1 = ry0 + int(u(rng) * float(sc.h));
      const int first = int(u(rng) * 40.f), end = rep % 4 == 0 ? sc.M.num_triangles : first + int(u(rng) * 300.f);
      const size_t pixels = size_t((rx1 - rx0 + 1) * (ry1 - ry0 + 1));
      std::vector<unsigned long long> key(pixels, pipeline::kEmptyKey), want_key(pixels, pipeline::kEmptyKey);
      const RasterBatch b{sc.M.triangles, pix.data(), sc.cam.data(), area.data(), first, end, rx0, rx1, ry0, ry1,
                          key.data()};
      const size_t room = size_t(end - first);
      std::vector<int> t(room), x0(room), x1(room), y0(room), y1(room);
      int rest = -1;
      const int n = raster_batch(b, t.data(), x0.data(), x1.data(), y0.data(), y1.data(), &rest);
      ASSERT_TRUE(rest >= first && rest <= end && (end - rest < 64 || !simd_rows_built()))
          << "at most one partial vector is left whole (without Highway: all)";
      int k = 0;
      for (int tri = first; tri < rest; ++tri) {  // as RasterStage::operator() picks and draws them
        if (area[size_t(tri)] == 0.f) continue;
        const int* v = sc.M.triangles + 3 * tri;
        const Vec2f s[3] = {pix[size_t(v[0])], pix[size_t(v[1])], pix[size_t(v[2])]};
        int bd[4];
        raster_bounds(s, &bd[0], &bd[1], &bd[2], &bd[3]);
        if (std::max(rx0, bd[0]) > std::min(rx1, bd[1]) || std::max(ry0, bd[2]) > std::min(ry1, bd[3])) continue;
        const float z[3] = {sc.cam[size_t(v[0])].z, sc.cam[size_t(v[1])].z, sc.cam[size_t(v[2])].z};
        raster_64bit(s, z, tri, rx0, rx1, ry0, ry1, want_key);
        const bool small = bd[1] - bd[0] < kSmallTriangleCentres && bd[3] - bd[2] < kSmallTriangleCentres;
        if (k < n && t[size_t(k)] == tri) {
          ASSERT_FALSE(small) << "small triangle " << tri << " left to the caller";
          ASSERT_TRUE(x0[size_t(k)] == bd[0] && x1[size_t(k)] == bd[1] && y0[size_t(k)] == bd[2] && y1[size_t(k)] == bd[3])
              << "bounds of triangle " << tri;
          ++k;
        } else {
          ASSERT_TRUE(small) << "triangle " << tri << " is neither drawn nor left";
        }
      }
      ASSERT_EQ(n, k) << "left: triangles that do not meet the region";
      // The caller draws the triangles left and those not looked at (64-bit here); then the z-buffer is the one of
      // drawing every triangle.
      std::vector<int> caller(t.begin(), t.begin() + n);
      for (int tri = rest; tri < end; ++tri) caller.push_back(tri);
      for (int tri = first; tri < end; ++tri)
        for (int pass = 0; pass < 2; ++pass) {
          if (area[size_t(tri)] == 0.f || (pass == 0 && tri < rest) ||
              (pass == 1 && std::find(caller.begin(), caller.end(), tri) == caller.end()))
            continue;
          const int* v = sc.M.triangles + 3 * tri;
          const Vec2f s[3] = {pix[size_t(v[0])], pix[size_t(v[1])], pix[size_t(v[2])]};
          const float z[3] = {sc.cam[size_t(v[0])].z, sc.cam[size_t(v[1])].z, sc.cam[size_t(v[2])].z};
          raster_64bit(s, z, tri, rx0, rx1, ry0, ry1, pass == 0 ? want_key : key);
        }
      for (size_t q = 0; q < pixels; ++q) ASSERT_EQ(key[q], want_key[q]) << "pixel " << q;
      left += n;
      looked_at += end - first;
    }
  }
  if (simd_rows_built()) EXPECT_GT(left, 100);  // (without Highway every triangle is the caller's)
  EXPECT_LT(left, looked_at / 3);
}

}  // namespace
