// loss_row(), shade_row() and blend_row() for every instruction set Highway targets, one chosen at run time (foreach_target.h
// compiles this file once per target). Built without FMA contraction (CMakeLists.txt), so each lane computes what
// the one-pixel kernels compute, bit for bit.
// Not SVE: its vectors are sizeless types, which the lane kernels cannot keep in arrays and structs (V c[3]). On
// aarch64 the rows run on NEON (checked by cross-compiling this file, see docs/design.md).
#ifndef HWY_DISABLED_TARGETS
#define HWY_DISABLED_TARGETS (HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128)
#endif
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "simd_rows.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <algorithm>
#include <vector>

#include "render/stages.hpp"  // (the z-buffer key)
#include "render/simd_rows.hpp"

HWY_BEFORE_NAMESPACE();
namespace diffdope {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;

/// The lane type of lanes.hpp on this target's float vectors.
struct HwyLanes {
  using V = hn::Vec<DF>;
  using M = hn::Mask<DF>;
  static V set(float x) { return hn::Set(DF(), x); }
  static V zero() { return hn::Zero(DF()); }
  static V abs(V a) { return hn::Abs(a); }
  static M lt(V a, V b) { return hn::Lt(a, b); }
  static M gt(V a, V b) { return hn::Gt(a, b); }
  static M le(V a, V b) { return hn::Le(a, b); }
  static M eq(V a, V b) { return hn::Eq(a, b); }
  static M both(M a, M b) { return hn::And(a, b); }
  static M either(M a, M b) { return hn::Or(a, b); }
  static M negate(M a) { return hn::Not(a); }
  static bool any(M a) { return !hn::AllFalse(DF(), a); }
  static M uniform(bool b) { return hn::Eq(zero(), set(b ? 0.f : 1.f)); }
  static V select(M m, V a, V b) { return hn::IfThenElse(m, a, b); }
  static V sign(V a) {
    return hn::IfThenElse(hn::Gt(a, zero()), set(1.f), hn::IfThenElse(hn::Lt(a, zero()), set(-1.f), zero()));
  }

  using I = hn::Vec<DI>;
  static constexpr size_t kMaxLanes = hn::MaxLanes(DF());
  static I seti(int x) { return hn::Set(DI(), x); }
  static M lti(I a, I b) { return hn::RebindMask(DF(), hn::Lt(a, b)); }
  static M eqi(I a, I b) { return hn::RebindMask(DF(), hn::Eq(a, b)); }
  static I ori(I a, I b) { return hn::Or(a, b); }
  static I selecti(M m, I a, I b) { return hn::IfThenElse(hn::RebindMask(DI(), m), a, b); }
  static V to_float(I a) { return hn::ConvertTo(DF(), a); }
  static I truncate(V a) { return hn::ConvertTo(DI(), a); }
  static I round(V a) { return hn::NearestInt(a); }
  static V gather(const float* base, I i) { return hn::GatherIndex(DF(), base, i); }
  static I gather(const int* base, I i) { return hn::GatherIndex(DI(), base, i); }
  static I gather(const unsigned char* base, I i) {  // (no byte gather: one lane at a time)
    HWY_ALIGN int idx[kMaxLanes];
    hn::Store(i, DI(), idx);
    for (size_t j = 0; j < hn::Lanes(DF()); ++j) idx[j] = base[idx[j]];
    return hn::Load(DI(), idx);
  }

  // Texture levels differ per lane (each lane's triangle has its own texture and mip level): per-lane pointers,
  // and texels read one lane at a time (the levels are separate arrays, out of reach of one gather's base).
  struct Level {
    const float* rgb[kMaxLanes];
    I w, h;
  };
  static Level level(const TextureView* textures, I tex, I lv) {
    HWY_ALIGN int t[kMaxLanes], l[kMaxLanes], w[kMaxLanes], h[kMaxLanes];
    hn::Store(tex, DI(), t);
    hn::Store(lv, DI(), l);
    Level out;
    for (size_t j = 0; j < hn::Lanes(DF()); ++j) {
      const TextureLevelView& v = textures[t[j]].level[l[j]];
      out.rgb[j] = v.rgb, w[j] = v.width, h[j] = v.height;
    }
    out.w = hn::Load(DI(), w);
    out.h = hn::Load(DI(), h);
    return out;
  }
  static I levels(const TextureView* textures, I tex) {
    HWY_ALIGN int t[kMaxLanes];
    hn::Store(tex, DI(), t);
    for (size_t j = 0; j < hn::Lanes(DF()); ++j) t[j] = textures[t[j]].levels;
    return hn::Load(DI(), t);
  }
  static I width(const Level& l) { return l.w; }
  static I height(const Level& l) { return l.h; }
  static void texel(const Level& l, I i, V rgb[3]) {
    HWY_ALIGN int idx[kMaxLanes];
    HWY_ALIGN float r[kMaxLanes], g[kMaxLanes], b[kMaxLanes];
    hn::Store(i, DI(), idx);
    for (size_t j = 0; j < hn::Lanes(DF()); ++j) {
      const float* p = l.rgb[j] + 3 * idx[j];
      r[j] = p[0], g[j] = p[1], b[j] = p[2];
    }
    rgb[0] = hn::Load(DF(), r), rgb[1] = hn::Load(DF(), g), rgb[2] = hn::Load(DF(), b);
  }
};

// The kernels built for this target (their definitions must lie inside the target's region).
#include "render/kernels/lane_math.inc"
#include "render/kernels/pixel_loss_lanes.inc"
#include "render/kernels/raster_lanes.inc"
#include "render/kernels/texture_lanes.inc"
#include "render/kernels/shade_lanes.inc"
#include "render/kernels/silhouette_lanes.inc"

int LossRowImpl(const LossRow& r, double* sum) {
  const DF d;
  const DI di;
  constexpr int kFields = sizeof(PixelAttr) / sizeof(float);
  static_assert(sizeof(PixelAttr) == kFields * sizeof(float), "PixelAttr is floats only");
  const size_t N = hn::Lanes(d);
  const auto field_index = hn::Mul(hn::Iota(di, 0), hn::Set(di, kFields));  // lane j: float j * kFields
  HWY_ALIGN float rgb[hn::MaxLanes(d)], depth[hn::MaxLanes(d)], mask[hn::MaxLanes(d)];
  using V = HwyLanes::V;
  int x = 0;
  for (; x + int(N) <= r.n; x += int(N)) {
    const float* post = &r.post[x].cov;
    const V cov = hn::GatherIndex(d, post, field_index);
    const V C[3] = {hn::GatherIndex(d, post + 1, field_index), hn::GatherIndex(d, post + 2, field_index),
                    hn::GatherIndex(d, post + 3, field_index)};
    const V D = hn::GatherIndex(d, post + 4, field_index);
    const V S = r.S ? hn::LoadU(d, r.S + x) : hn::Set(d, 1.f);
    V I[3] = {hn::Zero(d), hn::Zero(d), hn::Zero(d)};
    if (r.I) hn::LoadInterleaved3(d, r.I + 3 * x, I[0], I[1], I[2]);
    const V Id = r.D ? hn::LoadU(d, r.D + x) : hn::Zero(d);
    const PixelLossLanes<HwyLanes> v = HWY_NAMESPACE::pixel_loss_lanes<HwyLanes>(r.P, S, I, Id, hn::Gt(Id, hn::Zero(d)), cov, C, D);
    if (r.g_post) {
      float* g = &r.g_post[x].cov;
      hn::ScatterIndex(v.g_cov, d, g, field_index);
      for (int ch = 0; ch < 3; ++ch) hn::ScatterIndex(v.g_c[ch], d, g + 1 + ch, field_index);
      hn::ScatterIndex(v.g_d, d, g + 4, field_index);
    }
    hn::Store(v.rgb, d, rgb);
    hn::Store(v.depth, d, depth);
    hn::Store(v.mask, d, mask);
    for (size_t j = 0; j < N; ++j) {
      sum[0] += double(rgb[j]);
      sum[1] += double(depth[j]);
      sum[2] += double(mask[j]);
    }
  }
  return x;
}

int ShadeRowImpl(const ShadeRow& r) {
  const DF d;
  const DI di;
  using V = HwyLanes::V;
  using I = HwyLanes::I;
  constexpr size_t kMax = HwyLanes::kMaxLanes;
  const int N = int(hn::Lanes(d));
  const PixelAttr empty{0.f, {0.f, 0.f, 0.f}, 0.f};
  const V ray_y = hn::Set(d, pixel_ray(r.K, 0.f, r.y).y);  // the same for the whole row
  HWY_ALIGN int tri[kMax];
  HWY_ALIGN float b[3][kMax], s[kMax], depth[kMax], c[3][kMax], du[3][kMax], dv[3][kMax];
  for (int x = 0; x < r.n; x += N) {
    const int lanes = std::min(N, r.n - x);  // the last vector's lanes past the row: empty, not kept
    bool any = false;
    for (int j = 0; j < N; ++j) {
      tri[j] = j < lanes ? pipeline::key_triangle(r.key[x + j]) : -1;
      if (j < lanes) r.tri[x + j] = tri[j];
      any |= tri[j] >= 0;
    }
    if (!any) {
      std::fill(r.pre + x, r.pre + x + lanes, empty);
      std::fill(r.post + x, r.post + x + lanes, empty);
      continue;
    }
    const I t_raw = hn::Load(di, tri);
    const I t = hn::IfThenElse(hn::Lt(t_raw, hn::Zero(di)), hn::Zero(di), t_raw);  // empty lanes: triangle 0, not kept
    const I three = hn::Set(di, 3), one = hn::Set(di, 1), two = hn::Set(di, 2);
    I corner[3];
    HWY_NAMESPACE::triangle_corners_lanes<HwyLanes>(r.M.triangles, t, corner);
    const float* cam = &r.G.cam[0].x;
    V X[3][3];
    for (int k = 0; k < 3; ++k) {
      const I base = three * corner[k];
      X[k][0] = HwyLanes::gather(cam, base), X[k][1] = HwyLanes::gather(cam, base + one);
      X[k][2] = HwyLanes::gather(cam, base + two);
    }
    const V px = hn::ConvertTo(d, hn::Add(hn::Set(di, r.x + x), hn::Iota(di, 0)));
    const V ray[3] = {(px - hn::Set(d, r.K.cx)) / hn::Set(d, r.K.fx), ray_y, hn::Set(d, 1.f)};
    V bv[3];
    const V sv = HWY_NAMESPACE::ray_barycentrics_lanes<HwyLanes>(ray, X[0], X[1], X[2], bv);
    const V z[3] = {X[0][2], X[1][2], X[2][2]};
    V dep, cv[3], duv[3], dvv[3];
    HWY_NAMESPACE::shade_surface_lanes<HwyLanes>(r.M, r.G, t, corner, bv, z, &dep, cv, duv, dvv);
    hn::Store(sv, d, s);
    hn::Store(dep, d, depth);
    for (int k = 0; k < 3; ++k) {
      hn::Store(bv[k], d, b[k]);
      hn::Store(cv[k], d, c[k]);
      hn::Store(duv[k], d, du[k]);
      hn::Store(dvv[k], d, dv[k]);
    }
    for (int j = 0; j < lanes; ++j) {
      if (tri[j] < 0) {
        r.pre[x + j] = r.post[x + j] = empty;
        continue;
      }
      const PixelAttr a{1.f, {c[0][j], c[1][j], c[2][j]}, depth[j]};
      r.pre[x + j] = r.post[x + j] = a;
      detail::ShadeBary& sb = r.bary[x + j];
      for (int k = 0; k < 3; ++k) sb.raw[k] = sb.b[k] = b[k][j];
      sb.s = s[j];
      sb.clamped = false;
      sb.dcdu = Vec3f{du[0][j], du[1][j], du[2][j]};
      sb.dcdv = Vec3f{dv[0][j], dv[1][j], dv[2][j]};
    }
  }
  return r.n;
}

/// Steps of a silhouette walk taken on vectors. Most walks end within one or two triangles, but a vector waits
/// for its longest walk: those longer than this go on one pair at a time.
constexpr int kVectorWalkSteps = 3;

int BlendRowImpl(const BlendRow& r) {
  const DF d;
  const DI di;
  using V = HwyLanes::V;
  using I = HwyLanes::I;
  constexpr size_t kMax = HwyLanes::kMaxLanes;
  const int N = int(hn::Lanes(d));
  // The row's pairs of different triangles, packed so that every vector walks as many pairs as it holds. (Per
  // thread, grown to the longest row seen: no allocation per row.)
  struct Pairs {
    std::vector<int> F, other, horizontal, slot, f, o;
    std::vector<float> pfx, pfy, pox, poy;
  };
  thread_local Pairs q;
  const size_t most = size_t(2 * r.n + N);
  if (q.F.size() < most)
    for (auto* v : {&q.F, &q.other, &q.horizontal, &q.slot, &q.f, &q.o}) v->resize(most);
  if (q.pfx.size() < most)
    for (auto* v : {&q.pfx, &q.pfy, &q.pox, &q.poy}) v->resize(most);
  int m = 0;
  for (int i = 0; i < r.n; ++i)
    for (int dir = 0; dir < 2; ++dir) {  // as BlendDetectStage::pixel() and discontinuity_blend() set it up
      const bool horizontal = dir == 0;
      const int a = r.q + i;
      r.has_event[2 * a + dir] = 0;
      if (horizontal ? i >= r.right : !r.below) continue;
      const int b = horizontal ? a + 1 : a + r.stride;
      const int ta = r.tri[a], tb = r.tri[b];
      if (ta == tb) continue;
      const bool front = a_in_front(ta, r.pre[a].d, tb, r.pre[b].d);
      const Vec2f pa{float(r.x + i), r.y};
      const Vec2f pb = horizontal ? Vec2f{pa.x + 1.f, pa.y} : Vec2f{pa.x, pa.y + 1.f};
      const Vec2f pf = front ? pa : pb, po = front ? pb : pa;
      q.F[size_t(m)] = front ? ta : tb, q.other[size_t(m)] = front ? tb : ta;
      q.f[size_t(m)] = front ? a : b, q.o[size_t(m)] = front ? b : a;
      q.horizontal[size_t(m)] = horizontal ? 1 : 0, q.slot[size_t(m)] = 2 * a + dir;
      q.pfx[size_t(m)] = pf.x, q.pfy[size_t(m)] = pf.y, q.pox[size_t(m)] = po.x, q.poy[size_t(m)] = po.y;
      ++m;
    }
  for (int j = m; j < m + N; ++j) {  // the last vector's unused lanes (not walked)
    q.F[size_t(j)] = q.other[size_t(j)] = q.horizontal[size_t(j)] = 0;
    q.pfx[size_t(j)] = q.pfy[size_t(j)] = q.pox[size_t(j)] = q.poy[size_t(j)] = 0.f;
  }
  HWY_ALIGN int C[kMax], k[kMax], found[kMax], unfinished[kMax];
  HWY_ALIGN float t[kMax];
  for (int j0 = 0; j0 < m; j0 += N) {
    const size_t o = size_t(j0);
    I Cv, kv;
    V tv;
    HwyLanes::M go_on;
    const HwyLanes::M blend = HWY_NAMESPACE::silhouette_walk_lanes<HwyLanes>(
        r.M, r.G, hn::LoadU(di, &q.F[o]), hn::LoadU(di, &q.other[o]), hn::LoadU(d, &q.pfx[o]),
        hn::LoadU(d, &q.pfy[o]), hn::LoadU(d, &q.pox[o]), hn::LoadU(d, &q.poy[o]), hn::FirstN(d, size_t(m - j0)),
        hn::RebindMask(d, hn::Ne(hn::LoadU(di, &q.horizontal[o]), hn::Zero(di))), 0, kVectorWalkSteps, &Cv, &kv,
        &tv, &go_on);
    if (hn::AllFalse(d, blend) && hn::AllFalse(d, go_on)) continue;
    hn::Store(hn::IfThenElseZero(hn::RebindMask(di, blend), hn::Set(di, 1)), di, found);
    hn::Store(hn::IfThenElseZero(hn::RebindMask(di, go_on), hn::Set(di, 1)), di, unfinished);
    hn::Store(Cv, di, C);
    hn::Store(kv, di, k);
    hn::Store(tv, d, t);
    for (int j = 0; j < N; ++j) {
      if (!found[j] && !unfinished[j]) continue;
      const size_t e = o + size_t(j);
      const Vec2f pf{q.pfx[e], q.pfy[e]}, po{q.pox[e], q.poy[e]};
      int c = C[j], edge = k[j];
      float at = t[j];
      bool longer;
      if (unfinished[j] && !::diffdope::silhouette_walk_lanes<ScalarLanes>(
                               r.M, r.G, c, q.other[e], pf.x, pf.y, po.x, po.y, true, q.horizontal[e] != 0,
                               kVectorWalkSteps, kMaxSilhouetteWalk, &c, &edge, &at, &longer))
        continue;
      blend_at_crossing(r.M, r.G, r.K, q.f[e], pf, q.o[e], q.other[e], po, c, edge, at, &r.events[q.slot[e]]);
      r.has_event[q.slot[e]] = 1;
    }
  }
  return r.n;
}

int RasterBatchImpl(const RasterBatch& c, int* out_t, int* out_x0, int* out_x1, int* out_y0, int* out_y1,
                    int* rest) {
  const DF d;
  const DI di;
  using V = HwyLanes::V;
  using I = HwyLanes::I;
  constexpr size_t kMax = HwyLanes::kMaxLanes;
  const int N = int(hn::Lanes(d));
  const I three = hn::Set(di, 3), one = hn::Set(di, 1), two = hn::Set(di, 2);
  const I rx0 = hn::Set(di, c.rx0), rx1 = hn::Set(di, c.rx1), ry0 = hn::Set(di, c.ry0), ry1 = hn::Set(di, c.ry1);
  const I small_side = hn::Set(di, kSmallTriangleCentres - 1);
  const int w = c.rx1 - c.rx0 + 1;
  const float* pix = &c.pix[0].x;
  const float* cam = &c.cam[0].x;
  HWY_ALIGN int hit_x[kMax], hit_y[kMax], hit[kMax], span_x[kMax], span_y[kMax];
  HWY_ALIGN float hit_iz[kMax];
  int n = 0, t = c.first;
  for (; t + N <= c.end; t += N) {
    const auto drawn = hn::RebindMask(di, hn::Ne(hn::LoadU(d, c.area + t), hn::Zero(d)));
    if (hn::AllFalse(di, drawn)) continue;
    const I tri = hn::Add(hn::Set(di, t), hn::Iota(di, 0));
    I v[3];
    HWY_NAMESPACE::triangle_corners_lanes<HwyLanes>(c.triangles, tri, v);
    V sx[3], sy[3];
    for (int k = 0; k < 3; ++k) sx[k] = HwyLanes::gather(pix, two * v[k]), sy[k] = HwyLanes::gather(pix, two * v[k] + one);
    I x0, x1, y0, y1;
    HWY_NAMESPACE::raster_bounds_lanes<HwyLanes>(sx, sy, &x0, &x1, &y0, &y1);
    // As RasterStage::operator(): the bounds clipped to the region hold a pixel centre.
    const I xs = hn::Max(rx0, x0), xe = hn::Min(rx1, x1), ys = hn::Max(ry0, y0), ye = hn::Min(ry1, y1);
    const auto misses = hn::Or(hn::Gt(xs, xe), hn::Gt(ys, ye));
    const auto keep = hn::AndNot(misses, drawn);
    const auto small = hn::And(keep, hn::AndNot(hn::Gt(x1 - x0, small_side), hn::Not(hn::Gt(y1 - y0, small_side))));
    const auto big = hn::AndNot(small, keep);
    hn::CompressStore(x0, big, di, out_x0 + n);
    hn::CompressStore(x1, big, di, out_x1 + n);
    hn::CompressStore(y0, big, di, out_y0 + n);
    hn::CompressStore(y1, big, di, out_y1 + n);
    n += int(hn::CompressStore(tri, big, di, out_t + n));
    if (hn::AllFalse(di, small)) continue;
    // The small ones: every centre of their clipped bounds at once (as RasterStage::draw() one triangle at a time).
    V z[3];
    for (int k = 0; k < 3; ++k) z[k] = HwyLanes::gather(cam, three * v[k] + two);
    const SmallTriangleLanes<HwyLanes> T = HWY_NAMESPACE::raster_small_setup_lanes<HwyLanes>(sx, sy, z);
    const auto live = hn::RebindMask(d, small);
    hn::Store(hn::IfThenElseZero(small, xe - xs), di, span_x);
    hn::Store(hn::IfThenElseZero(small, ye - ys), di, span_y);
    int most_x = 0, most_y = 0;
    for (int j = 0; j < N; ++j) most_x = std::max(most_x, span_x[j]), most_y = std::max(most_y, span_y[j]);
    for (int dy = 0; dy <= most_y; ++dy)
      for (int dx = 0; dx <= most_x; ++dx) {
        const I px = xs + hn::Set(di, dx), py = ys + hn::Set(di, dy);
        const auto inside_bounds = hn::RebindMask(d, hn::Not(hn::Or(hn::Gt(px, xe), hn::Gt(py, ye))));
        V iz;
        const auto covered = HWY_NAMESPACE::raster_small_centre_lanes<HwyLanes>(T, px, py, &iz);
        // (only a NaN depth fails iz > 0: vertices are in front of the near plane)
        const auto draw = hn::And(hn::And(live, inside_bounds), hn::And(covered, hn::Gt(iz, hn::Zero(d))));
        if (hn::AllFalse(d, draw)) continue;
        hn::Store(hn::IfThenElseZero(hn::RebindMask(di, draw), one), di, hit);
        hn::Store(px, di, hit_x);
        hn::Store(py, di, hit_y);
        hn::Store(iz, d, hit_iz);
        for (int j = 0; j < N; ++j)
          if (hit[j])
            pipeline::key_min(c.key + size_t(hit_y[j] - c.ry0) * size_t(w) + size_t(hit_x[j] - c.rx0),
                              (static_cast<unsigned long long>(pipeline::depth_key(hit_iz[j])) << 32) |
                                  unsigned(t + j));
      }
  }
  *rest = t;  // the last partial vector's: the caller's
  return n;
}

const char* TargetName() { return hwy::TargetName(HWY_TARGET); }

}  // namespace HWY_NAMESPACE
}  // namespace diffdope
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace diffdope {
HWY_EXPORT(LossRowImpl);
HWY_EXPORT(ShadeRowImpl);
HWY_EXPORT(BlendRowImpl);
HWY_EXPORT(RasterBatchImpl);
HWY_EXPORT(TargetName);

int loss_row(const LossRow& row, double sum[3]) { return HWY_DYNAMIC_DISPATCH(LossRowImpl)(row, sum); }
int shade_row(const ShadeRow& row) { return HWY_DYNAMIC_DISPATCH(ShadeRowImpl)(row); }
int blend_row(const BlendRow& row) { return HWY_DYNAMIC_DISPATCH(BlendRowImpl)(row); }
int raster_batch(const RasterBatch& b, int* t, int* x0, int* x1, int* y0, int* y1, int* rest) {
  return HWY_DYNAMIC_DISPATCH(RasterBatchImpl)(b, t, x0, x1, y0, y1, rest);
}
const char* simd_row_target() { return HWY_DYNAMIC_DISPATCH(TargetName)(); }
bool simd_rows_built() { return true; }
}  // namespace diffdope
#endif
