// CPU backend of the differentiable renderer: loops over hypotheses (one per worker thread at a time) and over
// the pixels of each hypothesis' region of interest, calling the shared kernels/ maths. Stages per hypothesis:
//   vertices -> triangles -> z-buffer raster -> shading -> silhouette blends -> loss -> backward.
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "diffdope/kernels/edges.hpp"
#include "diffdope/kernels/pixel_loss.hpp"
#include "diffdope/kernels/shade.hpp"
#include "diffdope/kernels/silhouette.hpp"
#include "diffdope/kernels/vertex_stage.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/thread_pool.hpp"
#include "loss_setup.hpp"
#include "pixel_rect.hpp"
#include "render_image.hpp"

namespace diffdope {
namespace {

using Rect = PixelRect;

/// Scratch memory of one worker; reused across hypotheses and calls (no per-iteration allocation).
struct Workspace {
  std::vector<Vec3f> cam;
  std::vector<Vec2f> pix;
  std::vector<float> tri_area;
  std::vector<float> tri_level;
  std::vector<float> zbuf;
  std::vector<int> tri;
  std::vector<PixelAttr> pre, post, g_pre, g_post;
  std::vector<detail::ShadeBary> bary;  // per pixel, for the backward pass
  std::vector<float> grey, g_sobel_x, g_sobel_y;  // edge term
  std::vector<BlendEvent> events;
};

ProjectedView projected_view(const Workspace& ws) {
  return ProjectedView{ws.cam.data(), ws.pix.data(), ws.tri_area.data(), ws.tri_level.data()};
}

/// What every hypothesis of one call shares.
struct CallContext {
  MeshView mesh;
  Intrinsics K;
  float near_z = 0.01f;
  bool cull = false;
  Rect mask_box;    // bounding box of S > 0 (whole image when S is implicit all-ones)
  bool use_roi = true;
  int margin = 2;
  Camera camera;
  const Mesh* source_mesh = nullptr;  // for its bounding box (region of interest)
};

class CpuRenderer final : public Renderer {
 public:
  explicit CpuRenderer(const RenderOptions& options) : Renderer(options), pool_(options.threads) {
    workspaces_.resize(pool_.size());
  }
  std::string name() const override { return "cpu"; }

  std::vector<RenderImage> render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                  const cv::Mat& observed_mask) override;
  /// All hypotheses of all objects share the threads (one parallel loop), so a frame with several objects keeps
  /// every core busy even when each object has only a few runs left.
  void evaluate_objects(const Camera& camera, const Observation& frame, const std::vector<ObjectBatch>& objects,
                        bool with_gradient, std::vector<std::vector<LossValue>>& out) override;

 private:
  /// `mask` widens the region of interest; when empty, `no_mask_means_everywhere` says whether S is then
  /// implicitly 1 on the whole image (loss evaluation) or absent (plain rendering). `views` holds the mesh's
  /// texture views while the context is in use.
  CallContext make_context(const Camera& camera, const Mesh& mesh, const cv::Mat& mask, bool no_mask_means_everywhere,
                           std::vector<TextureView>& views);
  /// Loss (and gradient) of one hypothesis.
  void evaluate_hypothesis(const CallContext& ctx, const LossSetup& setup, const Observation& obs, const Pose& pose,
                           bool with_gradient, Workspace& ws, LossValue& res) const;
  /// Vertex, triangle, raster, shading and blend stages. Returns the region that was rendered.
  Rect rasterize(const CallContext& ctx, const Pose& pose, Workspace& ws, bool keep_events) const;

  ThreadPool pool_;
  std::vector<Workspace> workspaces_;
  std::vector<TextureView> texture_views_;
};

CallContext CpuRenderer::make_context(const Camera& camera, const Mesh& mesh, const cv::Mat& mask,
                                      bool no_mask_means_everywhere, std::vector<TextureView>& views) {
  camera.validate();
  if (mesh.num_triangles() == 0 || mesh.neighbors().size() != mesh.triangles.size())
    throw std::invalid_argument("renderer: mesh '" + mesh.name + "' is empty or not finalized");
  CallContext ctx;
  ctx.mesh = mesh.view(views);
  ctx.K = camera.intrinsics();
  ctx.near_z = static_cast<float>(options_.near_plane);
  ctx.cull = options_.cull_back_faces || (options_.auto_cull_closed && mesh.closed_and_outward());
  ctx.use_roi = options_.use_roi;
  ctx.margin = std::max(1, options_.roi_margin);
  ctx.camera = camera;
  ctx.source_mesh = &mesh;
  ctx.mask_box = mask_box(mask, camera.width, camera.height, no_mask_means_everywhere);
  return ctx;
}

Rect CpuRenderer::rasterize(const CallContext& ctx, const Pose& pose, Workspace& ws, bool keep_events) const {
  const MeshView& M = ctx.mesh;
  const Intrinsics& K = ctx.K;
  const int nv = M.num_vertices, nt = M.num_triangles;
  const RigidTransform T = pose.to_kernel();

  ws.cam.resize(nv);
  ws.pix.resize(nv);
  ws.tri_area.resize(nt);
  ws.tri_level.resize(nt);
  for (int i = 0; i < nv; ++i) vertex_setup(M, T, K, ctx.near_z, i, ws.cam.data(), ws.pix.data());
  for (int t = 0; t < nt; ++t) {
    ws.tri_area[t] = triangle_setup(M, ws.cam.data(), ws.pix.data(), ctx.near_z, ctx.cull, t);
    ws.tri_level[t] = triangle_mip_level(M, t, ws.tri_area[t]);
  }
  const ProjectedView G = projected_view(ws);

  // Region of interest: projected model box U observed mask box, plus margin.
  const Rect roi = hypothesis_roi(ctx.camera, *ctx.source_mesh, pose, ctx.near_z, ctx.mask_box, ctx.margin, ctx.use_roi);
  const int W = roi.width(), H = roi.height(), N = W * H;
  ws.zbuf.assign(N, std::numeric_limits<float>::infinity());
  ws.tri.assign(N, -1);

  // Z-buffer raster with exact (fixed-point) coverage (kernels/raster.hpp). Ties keep the lower triangle index.
  for (int t = 0; t < nt; ++t) {
    if (ws.tri_area[t] == 0.f) continue;
    const int* v = M.triangles + 3 * t;
    const Vec2f s[3] = {ws.pix[v[0]], ws.pix[v[1]], ws.pix[v[2]]};
    int bx0, bx1, by0, by1;  // covers no pixel centre of the region: nothing to set up
    raster_bounds(s, &bx0, &bx1, &by0, &by1);
    if (std::max(roi.x0, bx0) > std::min(roi.x1 - 1, bx1) || std::max(roi.y0, by0) > std::min(roi.y1 - 1, by1)) continue;
    const float z[3] = {ws.cam[v[0]].z, ws.cam[v[1]].z, ws.cam[v[2]].z};
    TriangleRaster R;
    if (!triangle_raster_setup(s, z, &R)) continue;
    const int xs = std::max(roi.x0, R.x0), xe = std::min(roi.x1 - 1, R.x1);
    const int ys = std::max(roi.y0, R.y0), ye = std::min(roi.y1 - 1, R.y1);
    if (xs > xe || ys > ye) continue;
    for (int y = ys; y <= ye; ++y) {
      long long e[3];
      raster_edges_at(R, xs, y, e);
      // Wide triangles: start and stop the row at the triangle's span (exact integer division).
      int lo = xs, hi = xe;
      if (xe - xs > 8) {
        for (int k = 0; k < 3; ++k) {
          if (R.dx[k] > 0 && e[k] < 0) lo = std::max(lo, xs + static_cast<int>((-e[k] + R.dx[k] - 1) / R.dx[k]));
          else if (R.dx[k] < 0 && e[k] >= 0) hi = std::min(hi, xs + static_cast<int>(e[k] / -R.dx[k]));
          else if (R.dx[k] < 0 && e[k] < 0) hi = xs - 1;
        }
        if (lo > hi) continue;
        for (int k = 0; k < 3; ++k) e[k] += R.dx[k] * (lo - xs);
      }
      float* zrow = ws.zbuf.data() + (y - roi.y0) * W - roi.x0;
      int* trow = ws.tri.data() + (y - roi.y0) * W - roi.x0;
      for (int x = lo; x <= hi; ++x, e[0] += R.dx[0], e[1] += R.dx[1], e[2] += R.dx[2]) {
        if (!raster_inside(R, e)) continue;
        const float zp = raster_depth(R, e);
        if (zp < zrow[x]) {
          zrow[x] = zp;
          trow[x] = t;
        }
      }
    }
  }

  // Shading (deferred: only the visible triangle of each pixel).
  ws.pre.resize(N);
  ws.bary.resize(N);
  for (int y = roi.y0; y < roi.y1; ++y) {
    for (int x = roi.x0; x < roi.x1; ++x) {
      const int i = (y - roi.y0) * W + (x - roi.x0);
      const int t = ws.tri[i];
      PixelAttr& a = ws.pre[i];
      if (t < 0) {
        a = PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f};
        continue;
      }
      Vec3f c;
      float d;
      shade_pixel(M, G, K, t, static_cast<float>(x), static_cast<float>(y), &c, &d, false, &ws.bary[i]);
      a = PixelAttr{1.f, {c.x, c.y, c.z}, d};
    }
  }

  // Silhouette and seam blends between horizontal and vertical neighbours.
  ws.post = ws.pre;
  ws.events.clear();
  for (int y = roi.y0; y < roi.y1; ++y) {
    for (int x = roi.x0; x < roi.x1; ++x) {
      const int i = (y - roi.y0) * W + (x - roi.x0);
      const Vec2f p{static_cast<float>(x), static_cast<float>(y)};
      for (int dir = 0; dir < 2; ++dir) {
        const bool horizontal = dir == 0;
        if (horizontal ? x + 1 >= roi.x1 : y + 1 >= roi.y1) continue;
        const int j = horizontal ? i + 1 : i + W;
        if (ws.tri[i] == ws.tri[j]) continue;
        const Vec2f q = horizontal ? Vec2f{p.x + 1.f, p.y} : Vec2f{p.x, p.y + 1.f};
        BlendEvent ev;
        if (!discontinuity_blend(M, G, K, i, ws.tri[i], ws.pre[i].d, p, j, ws.tri[j], ws.pre[j].d, q, horizontal,
                                 &ev))
          continue;
        apply_blend(ev, ws.pre[ev.to], &ws.post[ev.to]);
        if (keep_events) ws.events.push_back(ev);
      }
    }
  }
  return roi;
}

std::vector<RenderImage> CpuRenderer::render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                             const cv::Mat& observed_mask) {
  if (!observed_mask.empty() && (observed_mask.type() != CV_32FC1 || observed_mask.cols != camera.width ||
                                 observed_mask.rows != camera.height))
    throw std::invalid_argument("render: observed mask must be CV_32FC1 of the camera's size");
  const CallContext ctx = make_context(camera, mesh, observed_mask, false, texture_views_);
  std::vector<RenderImage> out(poses.size());
  pool_.parallel_for(static_cast<int>(poses.size()), [&](int h, int worker) {
    Workspace& ws = workspaces_[worker];
    const Rect roi = rasterize(ctx, poses[h], ws, false);
    out[h] = make_render_image(camera, roi, ws.pre.data(), ws.post.data(), ws.tri.data());
  });
  return out;
}

void CpuRenderer::evaluate_objects(const Camera& camera, const Observation& frame,
                                   const std::vector<ObjectBatch>& objects, bool with_gradient,
                                   std::vector<std::vector<LossValue>>& out) {
  const size_t n = objects.size();
  const std::vector<Observation> obs = object_observations(camera, frame, objects);
  std::vector<std::vector<TextureView>> views(n);
  std::vector<CallContext> ctx(n);
  std::vector<LossSetup> setups(n);
  std::vector<std::pair<int, int>> work;  // (object, hypothesis)
  out.assign(n, {});
  for (size_t k = 0; k < n; ++k) {  // everything is checked before anything runs
    const ObjectBatch& b = objects[k];
    ctx[k] = make_context(camera, *b.mesh, b.mask, true, views[k]);
    setups[k] = make_loss_setup(camera, obs[k], b.loss);
    out[k].assign(b.poses.size(), LossValue());
    for (size_t j = 0; j < b.poses.size(); ++j) work.emplace_back(int(k), int(j));
  }
  pool_.parallel_for(static_cast<int>(work.size()), [&](int w, int worker) {
    const auto [k, j] = work[w];
    evaluate_hypothesis(ctx[k], setups[k], obs[k], objects[k].poses[j], with_gradient, workspaces_[worker], out[k][j]);
  });
}

void CpuRenderer::evaluate_hypothesis(const CallContext& ctx, const LossSetup& setup, const Observation& obs,
                                      const Pose& pose, bool with_gradient, Workspace& ws, LossValue& res) const {
  const PixelLossParams& P = setup.P;
  const float k_edges = setup.k_edges, edge_scale = setup.edge_scale;
  if (!pose.is_valid(1e-3)) {
    res.rgb = res.depth = res.mask = res.total = std::numeric_limits<double>::infinity();
    return;  // a NaN or non-rotation pose gets an infinite loss, never a gradient
  }
  const Rect roi = rasterize(ctx, pose, ws, with_gradient);
  const ProjectedView G = projected_view(ws);
  const int W = roi.width(), N = W * roi.height();
  if (with_gradient) ws.g_post.resize(N);
  double sum_rgb = 0, sum_depth = 0, sum_mask = 0;
  static const float kZero3[3] = {0.f, 0.f, 0.f};
  for (int y = roi.y0; y < roi.y1; ++y) {
    const float* mrow = obs.has_mask() ? obs.mask.ptr<float>(y) : nullptr;
    const float* crow = obs.has_rgb() ? obs.rgb.ptr<float>(y) : nullptr;
    const float* drow = obs.has_depth() ? obs.depth.ptr<float>(y) : nullptr;
    for (int x = roi.x0; x < roi.x1; ++x) {
      const int i = (y - roi.y0) * W + (x - roi.x0);
      const float S = mrow ? mrow[x] : 1.f;
      const float* I = crow ? crow + 3 * x : kZero3;
      const float Id = drow ? drow[x] : 0.f;  // to_depth_metres maps NaN / negative to 0: no reading
      const PixelAttr& a = ws.post[i];
      PixelLossGrad g;
      const PixelLossValue v = pixel_loss_step(P, S, I, Id, a.cov, a.c, a.d, with_gradient ? &g : nullptr);
      sum_rgb += v.rgb;
      sum_depth += v.depth;
      sum_mask += v.mask;
      if (with_gradient) ws.g_post[i] = PixelAttr{g.cov, {g.c[0], g.c[1], g.c[2]}, g.d};
    }
  }
  double sum_edges = 0;
  if (k_edges != 0.f) {
    // Edge term: compare the observed edge map with the render's differentiable edge map over S.
    const int H = roi.height();
    ws.grey.resize(N);
    for (int i = 0; i < N; ++i) ws.grey[i] = (ws.post[i].c[0] + ws.post[i].c[1] + ws.post[i].c[2]) / 3.f;
    if (with_gradient) {
      ws.g_sobel_x.resize(N);  // edge_term_step writes every pixel
      ws.g_sobel_y.resize(N);
    }
    for (int y = roi.y0; y < roi.y1; ++y) {
      const float* mrow = obs.has_mask() ? obs.mask.ptr<float>(y) : nullptr;
      const float* erow = obs.edges.ptr<float>(y);
      for (int x = roi.x0; x < roi.x1; ++x) {
        const int lx = x - roi.x0, ly = y - roi.y0;
        const float S = mrow ? mrow[x] : 1.f;
        sum_edges += edge_term_step(ws.grey.data(), W, H, lx, ly, edge_scale, S, erow[x], k_edges,
                                    with_gradient ? &ws.g_sobel_x[ly * W + lx] : nullptr,
                                    with_gradient ? &ws.g_sobel_y[ly * W + lx] : nullptr);
      }
    }
    if (with_gradient)
      for (int ly = 0; ly < H; ++ly)
        for (int lx = 0; lx < W; ++lx) {
          const float g = grey_gradient(ws.g_sobel_x.data(), ws.g_sobel_y.data(), W, H, lx, ly) / 3.f;
          for (int ch = 0; ch < 3; ++ch) ws.g_post[ly * W + lx].c[ch] += g;
        }
  }
  finish_loss(setup, sum_rgb, sum_depth, sum_mask, sum_edges, &res);
  if (!with_gradient) return;

  double grad[6] = {0, 0, 0, 0, 0, 0};
  ws.g_pre = ws.g_post;
  for (const BlendEvent& e : ws.events)
    blend_backward(ctx.mesh, G, ctx.K, e, ws.pre[e.to], ws.g_post[e.to], &ws.g_pre[e.to], grad);
  for (int y = roi.y0; y < roi.y1; ++y) {
    for (int x = roi.x0; x < roi.x1; ++x) {
      const int i = (y - roi.y0) * W + (x - roi.x0);
      const int t = ws.tri[i];
      if (t < 0) continue;
      const PixelAttr& g = ws.g_pre[i];
      if (g.c[0] == 0.f && g.c[1] == 0.f && g.c[2] == 0.f && g.d == 0.f) continue;
      shade_pixel_backward(ctx.mesh, G, ctx.K, t, static_cast<float>(x), static_cast<float>(y),
                           Vec3f{g.c[0], g.c[1], g.c[2]}, g.d, grad, false, &ws.bary[i]);
    }
  }
  for (int k = 0; k < 6; ++k) res.gradient[k] = grad[k];
}

}  // namespace

std::unique_ptr<Renderer> make_cpu_renderer(const RenderOptions& options) {
  return std::make_unique<CpuRenderer>(options);
}

}  // namespace diffdope
