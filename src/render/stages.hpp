#pragma once
// The stages of the render pipeline (internal header): one DD_HOST_DEVICE functor per stage, called for every
// (element i, hypothesis h) of a call; count(h) is how many elements hypothesis h has. The pipeline
// (pipeline.hpp) hands them to an executor: the CPU one (src/render/host_executor.cpp) runs all stages of
// one hypothesis back to back on one thread, the CUDA one (cuda/cuda_executor.cu) launches each stage as one
// kernel over all hypotheses of all objects. The maths inside each stage is src/render/kernels/.
//
// Layout: hypothesis h has a region of interest of w * h pixels stored row by row from `offset` in the packed
// pixel buffers, its projected vertices from `vertex_offset` and triangles from `triangle_offset`. Every write
// of a stage for hypothesis h lands in h's own ranges, which is what lets the emulation run hypotheses on
// different threads with plain memory operations.
#include <algorithm>
#include <cstring>

#include "render/kernels/edges.hpp"
#include "render/kernels/pixel_loss.hpp"
#include "render/kernels/raster.hpp"
#include "render/kernels/shade.hpp"
#include "render/kernels/silhouette.hpp"
#include "render/kernels/vertex_stage.hpp"
#if !defined(__CUDACC__)
#include "render/simd_rows.hpp"
#endif

namespace diffdope {
namespace pipeline {

/// A step of an executor's run(): stage(i, h) for every hypothesis h and i < min(n, stage.count(h)).
template <class Stage>
struct Each {
  Stage stage;
  int n;  // most elements of any hypothesis (a GPU's grid size); 0 = skip the step
};
/// A reducing step: out[stride * h + k] += sum over i of stage(i, h, v)[k], k < Stage::kValues.
template <class Stage>
struct Sum {
  Stage stage;
  int n;
  double* out;
  int stride;
};

/// Whether a stage runs over the pixels of the regions (has kPixels and pixel(lx, ly, i, h, ...)).
template <class Stage, class = void>
struct is_pixel_stage {
  static constexpr bool value = false;
};
template <class Stage>
struct is_pixel_stage<Stage, decltype(void(Stage::kPixels))> {
  static constexpr bool value = Stage::kPixels;
};

/// Whether a pixel stage also runs the start of a span of a row at once, SIMD on the host: row(ly, lo, hi, h[, v])
/// does pixels lo, lo + 1, ... of row ly as pixel() does each (writes, and sums added in order) and returns how
/// many; the CPU executor calls it before it walks the rest of the span [lo, hi].
template <class Stage, class = void>
struct has_rows {
  static constexpr bool value = false;
};
template <class Stage>
struct has_rows<Stage, decltype(void(Stage::kRows))> {
  static constexpr bool value = Stage::kRows;
};

/// Whether an element stage also runs a range of its elements at once on the host: batch(first, end, h) does
/// elements first .. end - 1 as operator() does each; the CPU executor then calls it instead of operator().
template <class Stage, class = void>
struct has_batches {
  static constexpr bool value = false;
};
template <class Stage>
struct has_batches<Stage, decltype(void(Stage::kBatches))> {
  static constexpr bool value = Stage::kBatches;
};

/// One object of a call: its mesh on the executor and, when evaluating, its loss constants and mask.
struct ObjectParams {
  MeshView M;
  int nv, nt;
  int cull;
  PixelLossParams P;
  const float* S;  // observed mask (image size), nullptr: S = 1
  float k_edges;   // the paper's edge term weight / normaliser (0: off)
  float edge_scale;
  float k_texture;  // texture term weight / normaliser (0: off)
  float texture_epsilon;
};

/// Per-hypothesis constants of one call.
struct Hypothesis {
  RigidTransform T;
  int x0, y0, w, h;     // region of interest
  int offset;           // first pixel of the region in the packed pixel buffers
  int valid;            // 0: NaN / non-rotation pose (infinite loss, no work)
  int object;           // index into the call's objects
  int vertex_offset;    // first projected vertex in cam / pix
  int triangle_offset;  // first triangle in area / level
};

/// Everything a stage reads or writes (pointers are executor memory).
struct Pipeline {
  const ObjectParams* objects;
  const Hypothesis* H;
  Intrinsics K;
  float near_z;
  int image_w, image_h;
  const float *I, *D, *E;  // observed rgb (3 floats per pixel), depth, edges; nullptr when absent
  const float* T;           // observed texture gradients (2 floats per pixel); nullptr when absent
  int with_gradient;
  Vec3f* cam;
  Vec2f* pix;
  float *area, *level;
  unsigned long long* key;  // z-buffer: (depth_key(1/z) << 32) | triangle, smallest = nearest
  int* tri;
  PixelAttr *pre, *post, *g_post;
  detail::ShadeBary* bary;
  BlendEvent* events;  // slot 2 * pixel + dir (0: right neighbour, 1: lower)
  unsigned char* has_event;
  float *grey, *g_sx, *g_sy;
  float *log_grey, *g_tx, *g_ty;  // texture term
};

/// The per-hypothesis working arrays of a Pipeline (cam .. g_sy) in grow-only buffers Buffer<T> (T* reserve(n)):
/// the pipeline's, packed for all hypotheses of a call, or one CPU worker's, for one hypothesis at a time.
template <template <class> class Buffer>
struct WorkArrays {
  Buffer<Vec3f> cam;
  Buffer<Vec2f> pix;
  Buffer<float> area, level, grey, g_sx, g_sy, log_grey, g_tx, g_ty;
  Buffer<unsigned long long> key;
  Buffer<int> tri;
  Buffer<PixelAttr> pre, post, g_post;
  Buffer<detail::ShadeBary> bary;
  Buffer<BlendEvent> events;
  Buffer<unsigned char> has_event;

  /// Points p's arrays here, sized for that many vertices, triangles and pixels; the gradient's arrays only
  /// when p.with_gradient, the edge term's only when p.E, the texture term's only when p.T (otherwise left as
  /// they are in p).
  void bind(Pipeline& p, size_t vertices, size_t triangles, size_t pixels) {
    p.cam = cam.reserve(vertices);
    p.pix = pix.reserve(vertices);
    p.area = area.reserve(triangles);
    p.level = level.reserve(triangles);
    p.key = key.reserve(pixels);
    p.tri = tri.reserve(pixels);
    p.pre = pre.reserve(pixels);
    p.post = post.reserve(pixels);
    p.bary = bary.reserve(pixels);
    p.events = events.reserve(2 * pixels);
    p.has_event = has_event.reserve(2 * pixels);
    if (p.with_gradient) p.g_post = g_post.reserve(pixels);
    if (p.E || p.T) p.grey = grey.reserve(pixels);
    if (p.E && p.with_gradient) p.g_sx = g_sx.reserve(pixels), p.g_sy = g_sy.reserve(pixels);
    if (p.T) {
      p.log_grey = log_grey.reserve(pixels);
      if (p.with_gradient) p.g_tx = g_tx.reserve(pixels), p.g_ty = g_ty.reserve(pixels);
    }
  }
};

constexpr unsigned long long kEmptyKey = ~0ull;

/// The triangle a z-buffer key holds, -1 for an empty pixel.
DD_HOST_DEVICE int key_triangle(unsigned long long key) { return key == kEmptyKey ? -1 : int(key & 0xffffffffu); }

/// Keeps the smaller key: an atomic on the device; on the host each hypothesis runs on one thread.
DD_HOST_DEVICE void key_min(unsigned long long* slot, unsigned long long v) {
#if defined(__CUDA_ARCH__)
  atomicMin(slot, v);
#else
  if (v < *slot) *slot = v;
#endif
}

DD_HOST_DEVICE unsigned float_bits(float f) {
#if defined(__CUDA_ARCH__)
  return __float_as_uint(f);
#else
  unsigned u;
  std::memcpy(&u, &f, sizeof u);
  return u;
#endif
}

/// A positive inverse depth as 32 bits that order like the depth: positive floats' bits order like the floats,
/// so complementing them puts the nearest (largest 1/z) first. Never all ones (that is kEmptyKey's half).
DD_HOST_DEVICE unsigned depth_key(float inverse_depth) { return ~float_bits(inverse_depth); }

DD_HOST_DEVICE int imin(int a, int b) { return a < b ? a : b; }
DD_HOST_DEVICE int imax(int a, int b) { return a > b ? a : b; }

DD_HOST_DEVICE ProjectedView projected(const Pipeline& p, const Hypothesis& hy) {
  return ProjectedView{p.cam + hy.vertex_offset, p.pix + hy.vertex_offset, p.area + hy.triangle_offset,
                       p.level + hy.triangle_offset};
}

/// i: vertex.
struct VertexStage {
  static constexpr const char* kName = "vertices";
  Pipeline p;
  DD_HOST_DEVICE int count(int h) const { return p.objects[p.H[h].object].nv; }
  DD_HOST_DEVICE void operator()(int i, int h) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (i >= o.nv || !hy.valid) return;
    vertex_setup(o.M, hy.T, p.K, p.near_z, i, p.cam + hy.vertex_offset, p.pix + hy.vertex_offset);
  }
};

/// i: triangle. Screen area (0: culled / clipped) and mip level.
struct TriangleStage {
  static constexpr const char* kName = "triangles";
  Pipeline p;
  DD_HOST_DEVICE int count(int h) const { return p.objects[p.H[h].object].nt; }
  DD_HOST_DEVICE void operator()(int t, int h) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (t >= o.nt) return;
    float* a = p.area + hy.triangle_offset;
    if (!hy.valid) {
      a[t] = 0.f;
      return;
    }
    a[t] = triangle_setup(o.M, p.cam + hy.vertex_offset, p.pix + hy.vertex_offset, p.near_z, o.cull != 0, t);
    p.level[hy.triangle_offset + t] = triangle_mip_level(o.M, t, a[t]);
  }
};

/// i: pixel of the region.
struct ClearStage {
  static constexpr const char* kName = "clear";
  Pipeline p;
  DD_HOST_DEVICE int count(int h) const { return p.H[h].w * p.H[h].h; }
  DD_HOST_DEVICE void operator()(int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i < hy.w * hy.h) p.key[hy.offset + i] = kEmptyKey;
  }
};

/// i: (triangle, band) = (i / bands, i % bands). Walks the band's rows of the triangle's pixels in the region
/// and keeps the nearest per pixel with key_min on (depth_key(1/z), triangle): ties keep the lower triangle
/// index. The minimum does not depend on the order, so splitting big triangles into bands of rows (work for
/// more threads) changes nothing in the result.
struct RasterStage {
  static constexpr const char* kName = "raster";
  Pipeline p;
  int bands;
  DD_HOST_DEVICE int count(int h) const { return p.objects[p.H[h].object].nt * bands; }
  DD_HOST_DEVICE void operator()(int i, int h) const {
    const int t = bands == 1 ? i : i / bands, band = bands == 1 ? 0 : i % bands;  // (the CPU's: no division)
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (t >= o.nt || !hy.valid || p.area[hy.triangle_offset + t] == 0.f) return;
    const Vec2f* P = p.pix + hy.vertex_offset;
    const int* v = o.M.triangles + 3 * t;
    const Vec2f s[3] = {P[v[0]], P[v[1]], P[v[2]]};
    int x0, x1, y0, y1;  // covers no pixel centre of the region: nothing to set up
    raster_bounds(s, &x0, &x1, &y0, &y1);
    if (imax(hy.x0, x0) > imin(hy.x0 + hy.w - 1, x1) || imax(hy.y0, y0) > imin(hy.y0 + hy.h - 1, y1)) return;
    draw(t, band, x0, x1, y0, y1, h);
  }

  /// Band `band` of triangle t (drawn: area != 0), whose pixel bounds x0 .. y1 (raster_bounds()) meet the region.
  DD_HOST_DEVICE void draw(int t, int band, int x0, int x1, int y0, int y1, int h) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    const Vec2f* P = p.pix + hy.vertex_offset;
    const Vec3f* X = p.cam + hy.vertex_offset;
    const int* v = o.M.triangles + 3 * t;
    const Vec2f s[3] = {P[v[0]], P[v[1]], P[v[2]]};
    const float z[3] = {X[v[0]].z, X[v[1]].z, X[v[2]].z};
    const int xs = imax(hy.x0, x0), xe = imin(hy.x0 + hy.w - 1, x1);
    const int y_first = imax(hy.y0, y0), y_last = imin(hy.y0 + hy.h - 1, y1);
    const int rows = (y_last - y_first + bands) / bands;  // ceil(rows / bands)
    const int ys = y_first + band * rows, ye = imin(y_last, ys + rows - 1);
    if (x1 - x0 < kSmallTriangleCentres && y1 - y0 < kSmallTriangleCentres) {  // 32-bit set-up, the same bits
      const float sx[3] = {s[0].x, s[1].x, s[2].x}, sy[3] = {s[0].y, s[1].y, s[2].y};
      const SmallTriangleLanes<ScalarLanes> T = raster_small_setup_lanes<ScalarLanes>(sx, sy, z);
      if (!T.drawn) return;
      for (int y = ys; y <= ye; ++y)
        for (int x = xs; x <= xe; ++x) {
          float iz;
          if (!raster_small_centre_lanes<ScalarLanes>(T, x, y, &iz) || !(iz > 0.f)) continue;
          key_min(p.key + (hy.offset + (y - hy.y0) * hy.w + x - hy.x0),
                  (static_cast<unsigned long long>(depth_key(iz)) << 32) | unsigned(t));
        }
      return;
    }
    TriangleRaster R;
    R.x0 = x0, R.x1 = x1, R.y0 = y0, R.y1 = y1;
    if (!triangle_raster_setup(s, z, &R)) return;
    long long e_row[3];  // the edge functions at (xs, y), stepped exactly from row to row
    raster_edges_at(R, xs, ys, e_row);
    for (int y = ys; y <= ye; ++y, e_row[0] += R.dy[0], e_row[1] += R.dy[1], e_row[2] += R.dy[2]) {
      long long e[3] = {e_row[0], e_row[1], e_row[2]};
      int lo = xs, hi = xe;
      if (!raster_row_span(R, xs, e, &lo, &hi)) continue;
      // The row's edge functions in locals (registers, not the array raster_row_span wrote).
      long long e0 = e[0], e1 = e[1], e2 = e[2];
      const int row = hy.offset + (y - hy.y0) * hy.w - hy.x0;  // + x: the pixel's key
      for (int x = lo; x <= hi; ++x, e0 += R.dx[0], e1 += R.dx[1], e2 += R.dx[2]) {
        if (!raster_inside(R, e0, e1, e2)) continue;
        const float iz = raster_inverse_depth(R, e0, e1, e2);
        if (!(iz > 0.f)) continue;  // (vertices are in front of the near plane: only a NaN fails)
        key_min(p.key + (row + x), (static_cast<unsigned long long>(depth_key(iz)) << 32) | unsigned(t));
      }
    }
  }
#if !defined(__CUDACC__)
  /// Triangles first .. end - 1 (one band each): SIMD vectors find those drawn whose bounds meet the region (on a
  /// dense mesh most of the others lie between pixel centres) and draw the small ones; draw() draws the rest.
  static constexpr bool kBatches = true;
  void batch(int first, int end, int h) const {
    const Hypothesis& hy = p.H[h];
    if (!hy.valid) return;
    if (bands != 1) {
      for (int i = first; i < end; ++i) (*this)(i, h);
      return;
    }
    const ObjectParams& o = p.objects[hy.object];
    constexpr int kChunk = 256;
    int t[kChunk], x0[kChunk], x1[kChunk], y0[kChunk], y1[kChunk];
    for (int c = first; c < imin(end, o.nt); c += kChunk) {
      const RasterBatch rb{o.M.triangles, p.pix + hy.vertex_offset, p.cam + hy.vertex_offset,
                           p.area + hy.triangle_offset, c, imin(c + kChunk, imin(end, o.nt)), hy.x0,
                           hy.x0 + hy.w - 1, hy.y0, hy.y0 + hy.h - 1, p.key + hy.offset};
      int rest;
      const int n = raster_batch(rb, t, x0, x1, y0, y1, &rest);
      for (int k = 0; k < n; ++k) draw(t[k], 0, x0[k], x1[k], y0[k], y1[k], h);
      for (int i = rest; i < rb.end; ++i) (*this)(i, h);
    }
  }
#endif
};

/// What a pixel stage does at a pixel with no covered pixel within one pixel of it (in its row or the rows above
/// and below) after the raster: an executor that knows where those are (the CPU one, from the z-buffer) may then
/// skip the per-pixel call. Such a pixel is in no discontinuity pair with a covered pixel, so no blend reaches
/// it and its shading is empty. kSkip: pixel() changes nothing there (writes, sums); kFill: pixel() only writes
/// what Stage::fill_outside(i, n, h) writes for pixels i .. i + n - 1. Stages without kOutside run everywhere.
enum class Outside { kSkip, kFill };
template <class Stage, class = void>
struct outside_of {
  static constexpr bool known = false;
};
template <class Stage>
struct outside_of<Stage, decltype(void(Stage::kOutside))> {
  static constexpr bool known = true;
};

/// What every stage over the pixels of the regions shares: element i of hypothesis h is pixel (i % w, i / w) of
/// its region. The CUDA kernels call operator(), which splits i; the CPU executor walks the rows and calls
/// Stage::pixel(lx, ly, i, h[, v]) directly (no division per pixel).
template <class Stage>
struct PixelStage {
  Pipeline p;
  static constexpr bool kPixels = true;
  DD_HOST_DEVICE int count(int h) const { return p.H[h].w * p.H[h].h; }
  DD_HOST_DEVICE void operator()(int i, int h) const {
    const int w = p.H[h].w;
    static_cast<const Stage&>(*this).pixel(i % w, i / w, i, h);
  }
  DD_HOST_DEVICE void operator()(int i, int h, double* v) const {
    const int w = p.H[h].w;
    static_cast<const Stage&>(*this).pixel(i % w, i / w, i, h, v);
  }
};

/// i: pixel. Visible triangle and shading (barycentrics and texture derivatives kept for the backward pass);
/// post starts as pre.
struct ShadeStage : PixelStage<ShadeStage> {
  static constexpr const char* kName = "shade";
  static constexpr Outside kOutside = Outside::kFill;  // no triangle, empty attributes
  void fill_outside(int i, int n, int h) const {
    const int q = p.H[h].offset + i;
    std::fill(p.tri + q, p.tri + q + n, -1);
    std::fill(p.pre + q, p.pre + q + n, PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f});
    std::fill(p.post + q, p.post + q + n, PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f});
  }
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h) return;
    const int q = hy.offset + i;
    const int t = key_triangle(p.key[q]);
    p.tri[q] = t;
    PixelAttr a{0.f, {0.f, 0.f, 0.f}, 0.f};
    if (t >= 0) {
      Vec3f c;
      float d;
      shade_pixel(p.objects[hy.object].M, projected(p, hy), p.K, t, float(hy.x0 + lx),
                  float(hy.y0 + ly), &c, &d, false, &p.bary[q]);
      a = PixelAttr{1.f, {c.x, c.y, c.z}, d};
    }
    p.pre[q] = a;
    p.post[q] = a;
  }
#if !defined(__CUDACC__)
  static constexpr bool kRows = true;
  int row(int ly, int lo, int hi, int h) const {
    const Hypothesis& hy = p.H[h];
    const int q = hy.offset + ly * hy.w + lo;
    const ShadeRow r{p.objects[hy.object].M, projected(p, hy), p.K, p.key + q, p.tri + q, p.pre + q, p.post + q,
                     p.bary + q, hy.x0 + lo, float(hy.y0 + ly), hi - lo + 1};
    return shade_row(r);
  }
#endif
};

/// i: pixel. The discontinuity between the pixel and its right (dir 0) / lower (dir 1) neighbour, if any, into
/// slot 2 * pixel + dir; `to` is a packed-buffer index.
struct BlendDetectStage : PixelStage<BlendDetectStage> {
  static constexpr const char* kName = "blend detect";
  static constexpr Outside kOutside = Outside::kFill;  // both pairs empty: no event
  void fill_outside(int i, int n, int h) const {
    const int q = p.H[h].offset + i;
    std::fill(p.has_event + 2 * q, p.has_event + 2 * (q + n), static_cast<unsigned char>(0));
  }
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h) return;
    const int a = hy.offset + i;
    const ProjectedView G = projected(p, hy);
    const MeshView& M = p.objects[hy.object].M;
    const Vec2f pa{float(hy.x0 + lx), float(hy.y0 + ly)};
    for (int dir = 0; dir < 2; ++dir) {
      p.has_event[2 * a + dir] = 0;
      const bool horizontal = dir == 0;
      if (horizontal ? lx + 1 >= hy.w : ly + 1 >= hy.h) continue;
      const int b = horizontal ? a + 1 : a + hy.w;
      if (p.tri[a] == p.tri[b]) continue;
      const Vec2f pb = horizontal ? Vec2f{pa.x + 1.f, pa.y} : Vec2f{pa.x, pa.y + 1.f};
      if (discontinuity_blend(M, G, p.K, a, p.tri[a], p.pre[a].d, pa, b, p.tri[b], p.pre[b].d, pb, horizontal,
                              &p.events[2 * a + dir]))
        p.has_event[2 * a + dir] = 1;
    }
  }
#if !defined(__CUDACC__)
  static constexpr bool kRows = true;
  int row(int ly, int lo, int hi, int h) const {
    const Hypothesis& hy = p.H[h];
    const BlendRow r{p.objects[hy.object].M, projected(p, hy), p.K, p.tri, p.pre, p.events, p.has_event,
                     hy.offset + ly * hy.w + lo, hy.w, hy.w - 1 - lo, ly + 1 < hy.h, hy.x0 + lo, float(hy.y0 + ly),
                     hi - lo + 1};
    return blend_row(r);
  }
#endif
};

/// The (up to four) event slots that can target pixel q, in the CPU's scan order (pixels row by row, each
/// pixel's horizontal pair before its vertical one): upper neighbour's vertical, left neighbour's horizontal,
/// then q's own two. So blended attributes add up in the same order as on the CPU.
DD_HOST_DEVICE int event_slots(const Hypothesis& hy, int lx, int ly, int q, int slots[4]) {
  int n = 0;
  if (ly > 0) slots[n++] = 2 * (q - hy.w) + 1;
  if (lx > 0) slots[n++] = 2 * (q - 1);
  slots[n++] = 2 * q;
  slots[n++] = 2 * q + 1;
  return n;
}

/// i: pixel. Applies the blends that reach it.
struct BlendApplyStage : PixelStage<BlendApplyStage> {
  static constexpr const char* kName = "blend apply";
  static constexpr Outside kOutside = Outside::kSkip;  // no blend reaches it
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h) return;
    const int q = hy.offset + i;
    int slots[4];
    const int n = event_slots(hy, lx, ly, q, slots);
    PixelAttr out = p.post[q];
    for (int k = 0; k < n; ++k)
      if (p.has_event[slots[k]] && p.events[slots[k]].to == q) apply_blend(p.events[slots[k]], p.pre[q], &out);
    p.post[q] = out;
  }
};

/// i: pixel; reduced per hypothesis into (rgb, depth, mask). Also dL/d(post) when with_gradient.
struct LossStage : PixelStage<LossStage> {
  static constexpr const char* kName = "loss";
  static constexpr int kValues = 3;
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h, double* v) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h || !hy.valid) return;
    const ObjectParams& o = p.objects[hy.object];
    const int q = hy.offset + i;
    const int pix = (hy.y0 + ly) * p.image_w + hy.x0 + lx;
    const float S = o.S ? o.S[pix] : 1.f;
    const float zero3[3] = {0.f, 0.f, 0.f};
    const float* I = p.I ? p.I + 3 * pix : zero3;
    const float Id = p.D ? p.D[pix] : 0.f;
    const PixelAttr a = p.post[q];
    PixelLossGrad g;
    const PixelLossValue r = pixel_loss_step(o.P, S, I, Id, a.cov, a.c, a.d, p.with_gradient ? &g : nullptr);
    v[0] = r.rgb, v[1] = r.depth, v[2] = r.mask;
    if (p.with_gradient) p.g_post[q] = PixelAttr{g.cov, {g.c[0], g.c[1], g.c[2]}, g.d};
  }
#if !defined(__CUDACC__)
  static constexpr bool kRows = true;
  int row(int ly, int lo, int hi, int h, double* v) const {
    const Hypothesis& hy = p.H[h];
    if (!hy.valid) return hi - lo + 1;  // (pixel() adds nothing there)
    const ObjectParams& o = p.objects[hy.object];
    const int q = hy.offset + ly * hy.w + lo, pix = (hy.y0 + ly) * p.image_w + hy.x0 + lo;
    const LossRow r{o.P, p.post + q, o.S ? o.S + pix : nullptr, p.I ? p.I + 3 * pix : nullptr,
                    p.D ? p.D + pix : nullptr, p.with_gradient ? p.g_post + q : nullptr, hi - lo + 1};
    return loss_row(r, v);
  }
#endif
};

/// Edge and texture terms, stage 1, i: pixel. The render's grey image (mean of the blended colour) and, for the
/// texture term, its log.
struct GreyStage : PixelStage<GreyStage> {
  static constexpr const char* kName = "edges grey";
  static constexpr Outside kOutside = Outside::kFill;  // the grey (and log grey) of an empty pixel
  void fill_outside(int i, int n, int h) const {
    const int q = p.H[h].offset + i;
    std::fill(p.grey + q, p.grey + q + n, 0.f);
    if (p.T) std::fill(p.log_grey + q, p.log_grey + q + n, logf(0.f + p.objects[p.H[h].object].texture_epsilon));
  }
  DD_HOST_DEVICE void pixel(int, int, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h) return;
    const PixelAttr& a = p.post[hy.offset + i];
    const float grey = (a.c[0] + a.c[1] + a.c[2]) / 3.f;
    p.grey[hy.offset + i] = grey;
    if (p.T) p.log_grey[hy.offset + i] = logf(grey + p.objects[hy.object].texture_epsilon);
  }
};

/// Edge term, stage 2, i: pixel; reduced per hypothesis. |observed edges - rendered Sobel edges| over S, and
/// dL/d(Sobel responses) when with_gradient.
struct EdgeStage : PixelStage<EdgeStage> {
  static constexpr const char* kName = "edges sobel";
  static constexpr int kValues = 1;
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h, double* v) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (i >= hy.w * hy.h || !hy.valid || o.k_edges == 0.f) return;
    const int q = hy.offset + i;
    const int pix = (hy.y0 + ly) * p.image_w + hy.x0 + lx;
    const float S = o.S ? o.S[pix] : 1.f;
    v[0] = edge_term_step(p.grey + hy.offset, hy.w, hy.h, lx, ly, o.edge_scale, S, p.E[pix], o.k_edges,
                          p.with_gradient ? p.g_sx + q : nullptr, p.with_gradient ? p.g_sy + q : nullptr);
  }
};

/// Edge term, stage 3, i: pixel. Gathers the Sobel gradients into the pixel's colour gradient.
struct EdgeGatherStage : PixelStage<EdgeGatherStage> {
  static constexpr const char* kName = "edges gather";
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h || !hy.valid || p.objects[hy.object].k_edges == 0.f) return;
    const float g = grey_gradient(p.g_sx + hy.offset, p.g_sy + hy.offset, hy.w, hy.h, lx, ly) / 3.f;
    for (int ch = 0; ch < 3; ++ch) p.g_post[hy.offset + i].c[ch] += g;
  }
};

/// Texture term, stage 2, i: pixel; reduced per hypothesis. texture_term_step() inside the object, and
/// k * dL/d(Sobel of the log grey) when with_gradient.
struct TextureStage : PixelStage<TextureStage> {
  static constexpr const char* kName = "texture";
  static constexpr int kValues = 1;
  // Empty in its window: weight 0, no value and no gradient.
  static constexpr Outside kOutside = Outside::kFill;
  void fill_outside(int i, int n, int h) const {
    const Hypothesis& hy = p.H[h];
    if (!hy.valid || p.objects[hy.object].k_texture == 0.f || !p.with_gradient) return;
    std::fill(p.g_tx + hy.offset + i, p.g_tx + hy.offset + i + n, 0.f);
    std::fill(p.g_ty + hy.offset + i, p.g_ty + hy.offset + i + n, 0.f);
  }
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h, double* v) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (i >= hy.w * hy.h || !hy.valid || o.k_texture == 0.f) return;
    const int q = hy.offset + i;
    // The weight: the smallest observed mask and coverage over the 3x3 window (0 where it leaves the region or
    // the image, so the Sobel below never reads outside them).
    float w = 1.f;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int x = lx + dx, y = ly + dy, gx = hy.x0 + x, gy = hy.y0 + y;
        if (x < 0 || y < 0 || x >= hy.w || y >= hy.h || gx < 0 || gy < 0 || gx >= p.image_w || gy >= p.image_h) {
          w = 0.f;
        } else {
          // (Comparisons, not fminf: a library call on the host. A NaN is skipped either way.)
          const float cov = p.post[hy.offset + y * hy.w + x].cov;
          w = cov < w ? cov : w;
          if (o.S) {
            const float S = o.S[gy * p.image_w + gx];
            w = S < w ? S : w;
          }
        }
      }
    const int pix = (hy.y0 + ly) * p.image_w + hy.x0 + lx;
    v[0] = texture_term_step(p.log_grey + hy.offset, w, hy.w, hy.h, lx, ly, p.T + 2 * pix, o.k_texture,
                             p.with_gradient ? p.g_tx + q : nullptr, p.with_gradient ? p.g_ty + q : nullptr);
  }
};

/// Texture term, stage 3, i: pixel. Gathers the Sobel gradients into dL/d(log grey), then through the log and
/// the grey into the pixel's colour gradient.
struct TextureGatherStage : PixelStage<TextureGatherStage> {
  static constexpr const char* kName = "texture gather";
  static constexpr Outside kOutside = Outside::kSkip;  // its neighbours' texture gradients are all zero
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h) const {
    const Hypothesis& hy = p.H[h];
    const ObjectParams& o = p.objects[hy.object];
    if (i >= hy.w * hy.h || !hy.valid || o.k_texture == 0.f) return;
    const float g_log = grey_gradient(p.g_tx + hy.offset, p.g_ty + hy.offset, hy.w, hy.h, lx, ly);
    if (g_log == 0.f) return;
    const float g = g_log / (p.grey[hy.offset + i] + o.texture_epsilon) / 3.f;
    for (int ch = 0; ch < 3; ++ch) p.g_post[hy.offset + i].c[ch] += g;
  }
};

/// Backward, i: pixel; reduced per hypothesis into the 6-D pose gradient. The blends that reached the pixel
/// (into its pre-blend gradient and the silhouette gradient), then its shading.
struct BackwardStage : PixelStage<BackwardStage> {
  static constexpr const char* kName = "backward";
  static constexpr int kValues = 6;
  static constexpr Outside kOutside = Outside::kSkip;  // no triangle, no blend: nothing to add
  DD_HOST_DEVICE void pixel(int lx, int ly, int i, int h, double* g6) const {
    const Hypothesis& hy = p.H[h];
    if (i >= hy.w * hy.h || !hy.valid) return;
    const MeshView& M = p.objects[hy.object].M;
    const int q = hy.offset + i;
    const ProjectedView G = projected(p, hy);
    PixelAttr g_pre = p.g_post[q];
    int slots[4];
    const int n = event_slots(hy, lx, ly, q, slots);
    for (int k = 0; k < n; ++k)
      if (p.has_event[slots[k]] && p.events[slots[k]].to == q)
        blend_backward(M, G, p.K, p.events[slots[k]], p.pre[q], p.g_post[q], &g_pre, g6);
    const int t = p.tri[q];
    if (t >= 0 && (g_pre.c[0] != 0.f || g_pre.c[1] != 0.f || g_pre.c[2] != 0.f || g_pre.d != 0.f))
      shade_pixel_backward(M, G, p.K, t, float(hy.x0 + lx), float(hy.y0 + ly),
                           Vec3f{g_pre.c[0], g_pre.c[1], g_pre.c[2]}, g_pre.d, g6, false, &p.bary[q]);
  }
};

}  // namespace pipeline
}  // namespace diffdope
