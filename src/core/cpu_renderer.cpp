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

namespace diffdope {
namespace {

/// Pixel rectangle [x0, x1) x [y0, y1).
struct Rect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int width() const { return x1 - x0; }
  int height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
};

Rect unite(const Rect& a, const Rect& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)};
}

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
  void evaluate(const Camera& camera, const Mesh& mesh, const Observation& observed, const std::vector<Pose>& poses,
                const LossOptions& loss, bool with_gradient, std::vector<LossValue>& out) override;

 private:
  /// `mask` widens the region of interest; when empty, `no_mask_means_everywhere` says whether S is then
  /// implicitly 1 on the whole image (loss evaluation) or absent (plain rendering).
  CallContext make_context(const Camera& camera, const Mesh& mesh, const cv::Mat& mask, bool no_mask_means_everywhere);
  /// Vertex, triangle, raster, shading and blend stages. Returns the region that was rendered.
  Rect rasterize(const CallContext& ctx, const Pose& pose, Workspace& ws, bool keep_events) const;

  ThreadPool pool_;
  std::vector<Workspace> workspaces_;
  std::vector<TextureView> texture_views_;
};

CallContext CpuRenderer::make_context(const Camera& camera, const Mesh& mesh, const cv::Mat& mask,
                                      bool no_mask_means_everywhere) {
  camera.validate();
  if (mesh.num_triangles() == 0 || mesh.neighbors().size() != mesh.triangles.size())
    throw std::invalid_argument("renderer: mesh '" + mesh.name + "' is empty or not finalized");
  CallContext ctx;
  ctx.mesh = mesh.view(texture_views_);
  ctx.K = camera.intrinsics();
  ctx.near_z = static_cast<float>(options_.near_plane);
  ctx.cull = options_.cull_back_faces || (options_.auto_cull_closed && mesh.closed_and_outward());
  ctx.use_roi = options_.use_roi;
  ctx.margin = std::max(1, options_.roi_margin);
  ctx.camera = camera;
  ctx.source_mesh = &mesh;
  if (mask.empty()) {
    if (no_mask_means_everywhere) ctx.mask_box = {0, 0, camera.width, camera.height};  // S = 1 everywhere
  } else {
    cv::Mat nz;
    cv::compare(mask, 0.0, nz, cv::CMP_GT);
    const cv::Rect r = cv::boundingRect(nz);
    ctx.mask_box = {r.x, r.y, r.x + r.width, r.y + r.height};
  }
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
  Rect roi{0, 0, K.width, K.height};
  if (ctx.use_roi) {
    Rect model{0, 0, K.width, K.height};  // unbounded projection (box reaches the near plane): whole image
    const Eigen::AlignedBox2d b = ctx.camera.project_bounds(ctx.source_mesh->bbox_corners(pose), ctx.near_z);
    if (!b.isEmpty()) {
      const Eigen::Vector2d lo = b.min().cwiseMax(-1e6), hi = b.max().cwiseMin(1e6);
      model = {static_cast<int>(std::floor(lo.x())), static_cast<int>(std::floor(lo.y())),
               static_cast<int>(std::ceil(hi.x())) + 1, static_cast<int>(std::ceil(hi.y())) + 1};
    }
    roi = unite(model, ctx.mask_box);
    roi = {std::max(0, roi.x0 - ctx.margin), std::max(0, roi.y0 - ctx.margin),
           std::min(K.width, roi.x1 + ctx.margin), std::min(K.height, roi.y1 + ctx.margin)};
    if (roi.empty()) roi = {0, 0, 1, 1};
  }
  const int W = roi.width(), H = roi.height(), N = W * H;
  ws.zbuf.assign(N, std::numeric_limits<float>::infinity());
  ws.tri.assign(N, -1);

  // Z-buffer raster with exact (fixed-point) coverage. Depth is interpolated as 1/z (linear in the image);
  // ties keep the lower triangle index.
  constexpr long long kOne = 1LL << kSubpixelBits;
  for (int t = 0; t < nt; ++t) {
    if (ws.tri_area[t] == 0.f) continue;
    const int* v = M.triangles + 3 * t;
    const Vec2f s[3] = {ws.pix[v[0]], ws.pix[v[1]], ws.pix[v[2]]};
    const FixedPoint2 f[3] = {to_fixed(s[0]), to_fixed(s[1]), to_fixed(s[2])};
    const long long area2 = edge_function_fixed(f[0], f[1], f[2].x, f[2].y);
    if (area2 == 0) continue;
    const long long orient = area2 > 0 ? 1 : -1;
    const int xs = std::max(roi.x0, static_cast<int>(std::ceil(std::min({s[0].x, s[1].x, s[2].x}))));
    const int xe = std::min(roi.x1 - 1, static_cast<int>(std::floor(std::max({s[0].x, s[1].x, s[2].x}))));
    const int ys = std::max(roi.y0, static_cast<int>(std::ceil(std::min({s[0].y, s[1].y, s[2].y}))));
    const int ye = std::min(roi.y1 - 1, static_cast<int>(std::floor(std::max({s[0].y, s[1].y, s[2].y}))));
    if (xs > xe || ys > ye) continue;
    const float inv2a = 1.f / static_cast<float>(orient * area2);
    // Edge k (s_k -> s_k+1) weighs the opposite vertex k+2.
    const float iz[3] = {1.f / ws.cam[v[2]].z, 1.f / ws.cam[v[0]].z, 1.f / ws.cam[v[1]].z};
    bool top_left[3];
    long long dx[3];
    for (int k = 0; k < 3; ++k) {
      top_left[k] = edge_is_top_left_fixed(f[k], f[(k + 1) % 3], orient);
      dx[k] = -orient * (f[(k + 1) % 3].y - f[k].y) * kOne;  // edge change per pixel step in x
    }
    for (int y = ys; y <= ye; ++y) {
      long long e[3];
      for (int k = 0; k < 3; ++k) e[k] = orient * edge_function_fixed(f[k], f[(k + 1) % 3], xs * kOne, y * kOne);
      // Wide triangles: start and stop the row at the triangle's span (exact integer division).
      int lo = xs, hi = xe;
      if (xe - xs > 8) {
        for (int k = 0; k < 3; ++k) {
          if (dx[k] > 0 && e[k] < 0) lo = std::max(lo, xs + static_cast<int>((-e[k] + dx[k] - 1) / dx[k]));
          else if (dx[k] < 0 && e[k] >= 0) hi = std::min(hi, xs + static_cast<int>(e[k] / -dx[k]));
          else if (dx[k] < 0 && e[k] < 0) hi = xs - 1;
        }
        if (lo > hi) continue;
        for (int k = 0; k < 3; ++k) e[k] += dx[k] * (lo - xs);
      }
      float* zrow = ws.zbuf.data() + (y - roi.y0) * W - roi.x0;
      int* trow = ws.tri.data() + (y - roi.y0) * W - roi.x0;
      for (int x = lo; x <= hi; ++x, e[0] += dx[0], e[1] += dx[1], e[2] += dx[2]) {
        bool inside = true;
        for (int k = 0; k < 3; ++k) inside &= e[k] > 0 || (e[k] == 0 && top_left[k]);
        if (!inside) continue;
        const float z = 1.f / ((float(e[0]) * iz[0] + float(e[1]) * iz[1] + float(e[2]) * iz[2]) * inv2a);
        if (z < zrow[x]) {
          zrow[x] = z;
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
  const CallContext ctx = make_context(camera, mesh, observed_mask, false);
  std::vector<RenderImage> out(poses.size());
  pool_.parallel_for(static_cast<int>(poses.size()), [&](int h, int worker) {
    Workspace& ws = workspaces_[worker];
    const Rect roi = rasterize(ctx, poses[h], ws, false);
    RenderImage& img = out[h];
    img.roi = cv::Rect(roi.x0, roi.y0, roi.width(), roi.height());
    img.color = cv::Mat::zeros(camera.height, camera.width, CV_32FC3);
    img.depth = cv::Mat::zeros(camera.height, camera.width, CV_32FC1);
    img.coverage = cv::Mat::zeros(camera.height, camera.width, CV_32FC1);
    img.triangle = cv::Mat(camera.height, camera.width, CV_32SC1, cv::Scalar(-1));
    for (int y = roi.y0; y < roi.y1; ++y) {
      for (int x = roi.x0; x < roi.x1; ++x) {
        const int i = (y - roi.y0) * roi.width() + (x - roi.x0);
        const PixelAttr& a = ws.post[i];
        img.color.at<cv::Vec3f>(y, x) = cv::Vec3f(a.c[0], a.c[1], a.c[2]);
        img.coverage.at<float>(y, x) = a.cov;
        img.depth.at<float>(y, x) = ws.tri[i] >= 0 ? ws.pre[i].d : 0.f;
        img.triangle.at<int>(y, x) = ws.tri[i];
      }
    }
  });
  return out;
}

void CpuRenderer::evaluate(const Camera& camera, const Mesh& mesh, const Observation& obs,
                           const std::vector<Pose>& poses, const LossOptions& loss, bool with_gradient,
                           std::vector<LossValue>& out) {
  obs.validate(camera);
  if (!(loss.depth_truncation > 0)) throw std::invalid_argument("loss: depth_truncation must be > 0");
  const CallContext ctx = make_context(camera, mesh, obs.mask, true);

  // Normalisers: each term is a mean over the pixels it is defined on (whole image, not the ROI, so that the
  // value does not depend on the region of interest).
  double n_rgb = 0, n_depth = 0;
  if (obs.has_mask()) {
    n_rgb = cv::sum(obs.mask)[0];
    if (obs.has_depth()) {
      cv::Mat valid;
      cv::compare(obs.depth, 0.0, valid, cv::CMP_GT);
      valid.convertTo(valid, CV_32F, 1.0 / 255.0);
      n_depth = cv::sum(valid.mul(obs.mask))[0];
    }
  } else {
    n_rgb = static_cast<double>(camera.width) * camera.height;
    if (obs.has_depth()) n_depth = cv::countNonZero(obs.depth > 0);
  }
  PixelLossParams P;
  P.k_rgb = (obs.has_rgb() && n_rgb > 0) ? static_cast<float>(loss.weight_rgb / n_rgb) : 0.f;
  P.k_depth = (obs.has_depth() && n_depth > 0) ? static_cast<float>(loss.weight_depth / n_depth) : 0.f;
  P.k_mask = (obs.has_mask() && n_rgb > 0) ? static_cast<float>(loss.weight_mask / n_rgb) : 0.f;
  P.rgb_miss = static_cast<float>(loss.rgb_miss);
  P.depth_trunc = static_cast<float>(loss.depth_truncation);
  P.occlusion_margin = static_cast<float>(loss.occlusion_margin);
  const float k_edges = (obs.has_edges() && n_rgb > 0) ? static_cast<float>(loss.weight_edges / n_rgb) : 0.f;
  const float edge_scale = static_cast<float>(loss.edge_scale);

  out.assign(poses.size(), LossValue());
  pool_.parallel_for(static_cast<int>(poses.size()), [&](int h, int worker) {
    Workspace& ws = workspaces_[worker];
    LossValue& res = out[h];
    if (!poses[h].is_valid(1e-3)) {
      res.rgb = res.depth = res.mask = res.total = std::numeric_limits<double>::infinity();
      return;  // a NaN or non-rotation pose gets an infinite loss, never a gradient
    }
    const Rect roi = rasterize(ctx, poses[h], ws, with_gradient);
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
        const float Id = drow ? drow[x] : 0.f;
        const bool valid = Id > 0.f;  // to_depth_metres maps NaN / negative to 0
        const PixelAttr& a = ws.post[i];
        if (S == 0.f && a.cov == 0.f) {  // background the render does not touch: no loss, no gradient
          if (with_gradient) ws.g_post[i] = PixelAttr{0.f, {0.f, 0.f, 0.f}, 0.f};
          continue;
        }
        PixelLossGrad g;
        const PixelLossValue v = pixel_loss(P, S, I, Id, valid, a.cov, a.c, a.d, with_gradient ? &g : nullptr);
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
        ws.g_sobel_x.assign(N, 0.f);
        ws.g_sobel_y.assign(N, 0.f);
      }
      for (int y = roi.y0; y < roi.y1; ++y) {
        const float* mrow = obs.has_mask() ? obs.mask.ptr<float>(y) : nullptr;
        const float* erow = obs.edges.ptr<float>(y);
        for (int x = roi.x0; x < roi.x1; ++x) {
          const float S = mrow ? mrow[x] : 1.f;
          if (!(S > 0.f)) continue;
          const int lx = x - roi.x0, ly = y - roi.y0;
          float gx, gy;
          const float e = edge_value(ws.grey.data(), W, H, lx, ly, edge_scale, &gx, &gy);
          sum_edges += S * std::fabs(erow[x] - e);
          if (with_gradient)
            edge_value_backward(gx, gy, edge_scale, k_edges * S * signf(e - erow[x]), &ws.g_sobel_x[ly * W + lx],
                                &ws.g_sobel_y[ly * W + lx]);
        }
      }
      if (with_gradient)
        for (int ly = 0; ly < H; ++ly)
          for (int lx = 0; lx < W; ++lx) {
            const float g = grey_gradient(ws.g_sobel_x.data(), ws.g_sobel_y.data(), W, H, lx, ly) / 3.f;
            for (int ch = 0; ch < 3; ++ch) ws.g_post[ly * W + lx].c[ch] += g;
          }
    }
    res.edges = n_rgb > 0 && k_edges != 0.f ? sum_edges / n_rgb : 0.0;
    res.rgb = n_rgb > 0 && obs.has_rgb() ? sum_rgb / n_rgb : 0.0;
    res.depth = n_depth > 0 ? sum_depth / n_depth : 0.0;
    res.mask = n_rgb > 0 && obs.has_mask() ? sum_mask / n_rgb : 0.0;
    res.total = P.k_rgb * sum_rgb + P.k_depth * sum_depth + P.k_mask * sum_mask + k_edges * sum_edges;
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
  });
}

}  // namespace

std::unique_ptr<Renderer> make_cpu_renderer(const RenderOptions& options) {
  return std::make_unique<CpuRenderer>(options);
}

}  // namespace diffdope
