#pragma once
// The render pipeline (internal header), written once for every executor: packing of all hypotheses of all
// objects of a call, regions of interest, the mesh cache, loss constants, results. The stages themselves are
// src/render/stages.hpp. `Exec` says where they run:
//   - HostExec (src/render/host_executor.cpp, the "cpu" backend): host memory; each hypothesis runs every stage
//     back to back on one thread (its buffers stay in cache), the hypotheses of all objects spread over the cores;
//   - CudaExec (cuda/cuda_executor.cu): device buffers, one stream, one kernel per stage, pinned staging.
// Exec provides:
//   template <class T> Buffer        grow-only storage: T* reserve(size_t n); T* ptr
//   upload(Buffer<T>&, const T*, n)  copy in (asynchronous: the host data must live until synchronize())
//   download(T* host, const T*, n)   copy out (asynchronous)
//   zero(double*, n)
//   run(B, steps...)                 the steps in order, each for every hypothesis h < B:
//                                    Each{stage, n}: stage(i, h) for i < min(n, stage.count(h));
//                                    Sum{stage, n, out, stride}: out[stride * h + k] += sum over those i of
//                                    stage(i, h, v)[k], k < Stage::kValues. A step with n = 0 is skipped.
//   kWorkerScratch                   true: evaluate() calls run_in_scratch(B, steps...) instead, which gives
//                                    every worker its own per-hypothesis arrays (Pipeline::cam .. g_sy, reused
//                                    from one hypothesis to the next, so they stay in the core's cache); the
//                                    pipeline then allocates none of them and reads none back. Every step of
//                                    one call holds the same Pipeline.
//   kSplitsTriangles                 whether big triangles are cut into bands of rows (more threads on a GPU)
//   synchronize(what)                waits for the queued work; throws naming `what` on an error
//   drain()                          waits for the queued work, ignoring errors (after a failed call)
//   image(slot, mat, &changed)       an observed CV_32F image on the executor, re-uploaded (changed = true)
//                                    only when its content differs from the slot's last one
//   results(n)                       host memory for n doubles of results (pinned on CUDA)
//   name()
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <exception>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include "diffdope/observation.hpp"
#include "diffdope/renderer.hpp"
#include "render/kernel_inputs.hpp"
#include "render/loss_setup.hpp"
#include "render/stages.hpp"
#include "render/pixel_rect.hpp"
#include "render/render_image.hpp"

namespace diffdope {
namespace pipeline {

template <class Exec>
class PipelineRenderer final : public Renderer {
 public:
  template <class... Args>
  explicit PipelineRenderer(const RenderOptions& options, Args&&... args)
      : Renderer(options), exec_(std::forward<Args>(args)...) {}
  PipelineRenderer(const PipelineRenderer&) = delete;
  PipelineRenderer& operator=(const PipelineRenderer&) = delete;
  std::string name() const override { return exec_.name(); }

  std::vector<RenderImage> render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                  const cv::Mat& observed_mask) override {
    if (!observed_mask.empty() && (observed_mask.type() != CV_32FC1 || observed_mask.cols != camera.width ||
                                   observed_mask.rows != camera.height))
      throw std::invalid_argument("render: observed mask must be CV_32FC1 of the camera's size");
    if (poses.empty()) return {};
    const Drain drain(exec_);
    const PixelRect box = mask_box(observed_mask, camera.width, camera.height, false);
    Call c = prepare(camera, {ObjectCall{&mesh, &poses, nullptr, nullptr, box}}, false);
    work_.bind(c.p, c.vertices, c.triangles, size_t(c.pixels));
    std::apply([&](const auto&... steps) { exec_.run(c.B, steps...); }, forward_steps(c));
    const size_t N = size_t(c.pixels);
    std::vector<PixelAttr> pre(N), post(N);
    std::vector<int> tri(N);
    exec_.download(pre.data(), c.p.pre, N);
    exec_.download(post.data(), c.p.post, N);
    exec_.download(tri.data(), c.p.tri, N);
    exec_.synchronize("render");
    std::vector<RenderImage> out(poses.size());
    for (size_t h = 0; h < poses.size(); ++h) {  // an invalid hypothesis has a 1-pixel region, left empty
      const Hypothesis& hy = hyp_[h];
      const PixelRect roi{hy.x0, hy.y0, hy.x0 + hy.w, hy.y0 + hy.h};
      out[h] = make_render_image(camera, roi, pre.data() + hy.offset, post.data() + hy.offset, tri.data() + hy.offset);
      out[h].lod = object_lod_[0];
    }
    return out;
  }

  void evaluate_objects(const Camera& camera, const Observation& frame, const std::vector<ObjectBatch>& objects,
                        bool with_gradient, std::vector<std::vector<LossValue>>& out) override {
    const Drain drain(exec_);
    const std::vector<Observation> views = object_observations(camera, frame, objects);  // checked before running
    out.assign(objects.size(), {});
    for (size_t k = 0; k < objects.size(); ++k) out[k].assign(objects[k].poses.size(), LossValue());
    const FrameImages f = upload_frame(frame);
    std::vector<ObjectCall> calls;
    std::vector<std::vector<LossValue>*> outs;
    for (size_t k = 0; k < objects.size(); ++k) {
      if (objects[k].poses.empty()) continue;
      const float* S = nullptr;
      const SetupCache& setup = object_setup(k, camera, views[k], objects[k].loss, &S);
      calls.push_back(ObjectCall{objects[k].mesh, &objects[k].poses, &setup, S, setup.box});
      outs.push_back(&out[k]);
    }
    if (!calls.empty()) run(camera, f, calls, with_gradient, outs.data());
  }

 private:
  /// When a call throws with work still queued, waits for it (ignoring its errors) before anything it uses can
  /// be freed or reused by the next call.
  struct Drain {
    Exec& exec;
    int exceptions = std::uncaught_exceptions();
    explicit Drain(Exec& e) : exec(e) {}
    ~Drain() {
      if (std::uncaught_exceptions() > exceptions) exec.drain();
    }
  };
  /// An object's loss constants and mask box, kept while its inputs stay the same: computing them reads the whole
  /// mask and depth image (~0.5 ms at 960x540), more than a GPU iteration's budget allows on every call.
  struct SetupCache {
    bool valid = false;
    LossOptions loss{};
    int width = 0, height = 0;
    bool has_rgb = false, has_depth = false, has_mask = false, has_edges = false, has_texture = false;
    uint64_t depth_generation = 0, mask_generation = 0;
    LossSetup setup;
    PixelRect box;  // observed mask's box (the whole image without a mask)
  };
  struct ObjectCall {
    const Mesh* mesh;
    const std::vector<Pose>* poses;
    const SetupCache* setup;  // nullptr: render()
    const float* S;           // observed mask on the executor (nullptr: none)
    PixelRect box;
  };
  struct FrameImages {
    const float *I, *D, *E, *T;
  };
  struct Call {
    Pipeline p;
    int B, pixels, max_vertices, max_triangles, max_pixels;
    size_t vertices, triangles;  // of all hypotheses
  };

  /// One level of detail of a mesh on the executor.
  struct ExecLevel {
    typename Exec::template Buffer<Vec3f> positions, colors;
    typename Exec::template Buffer<Vec2f> uvs;
    typename Exec::template Buffer<int> triangles, tri_texture, neighbors, opposite;
    typename Exec::template Buffer<unsigned char> seams;
    typename Exec::template Buffer<float> tri_uv_area;
  };
  /// A mesh's levels of detail (Mesh::lods()) and textures on the executor.
  struct ExecMesh {
    std::vector<std::unique_ptr<ExecLevel>> levels;  // 0: the full mesh
    std::vector<MeshView> views;                         // per level
    std::vector<std::unique_ptr<typename Exec::template Buffer<float>>> texels;  // one per texture level
    typename Exec::template Buffer<TextureView> textures;
    uint64_t used = 0;  // uses_ at the last call that used it
  };
  static constexpr size_t kMaxMeshes = kMaxCachedMeshes;

  const ExecMesh& upload_mesh(const Mesh& mesh) {
    if (mesh.num_triangles() == 0 || mesh.neighbors().size() != mesh.triangles.size() || mesh.content_id() == 0)
      throw std::invalid_argument("renderer: mesh '" + mesh.name + "' is empty or not finalized");
    ++uses_;
    // Keyed by the content id finalize() gives (an address can be reused by another mesh; a copy shares the
    // content and the id). The counts guard against a mesh resized after finalize() without a new one.
    const auto cached = meshes_.find(mesh.content_id());
    if (cached != meshes_.end()) {
      ExecMesh& m = *cached->second;
      if (m.views[0].num_vertices == mesh.num_vertices() && m.views[0].num_triangles == mesh.num_triangles() &&
          m.views.size() == mesh.lods().size() + 1) {
        m.used = uses_;
        return m;
      }
      meshes_.erase(cached);
    }
    // Built aside and put in the cache only once complete: a failed upload (out of device memory) must not
    // leave a half-made entry behind.
    auto made = std::make_unique<ExecMesh>();
    ExecMesh& d = *made;
    d.used = uses_;
    std::vector<TextureView> host_views;
    make_mesh_view(mesh, host_views);
    std::vector<TextureView> exec_views = host_views;
    for (size_t t = 0; t < host_views.size(); ++t)
      for (int l = 0; l < host_views[t].levels; ++l) {
        const TextureLevelView& lv = host_views[t].level[l];
        d.texels.push_back(std::make_unique<typename Exec::template Buffer<float>>());
        exec_.upload(*d.texels.back(), lv.rgb, 3 * size_t(lv.width) * lv.height);
        exec_views[t].level[l].rgb = d.texels.back()->ptr;
      }
    if (!exec_views.empty()) exec_.upload(d.textures, exec_views.data(), exec_views.size());
    std::vector<TextureView> unused;
    for (size_t level = 0; level <= mesh.lods().size(); ++level) {
      const MeshView l = make_mesh_view(mesh, unused, int(level));
      d.levels.push_back(std::make_unique<ExecLevel>());
      ExecLevel& t = *d.levels.back();
      exec_.upload(t.positions, l.positions, l.num_vertices);
      exec_.upload(t.colors, l.colors, l.num_vertices);
      if (l.uvs) exec_.upload(t.uvs, l.uvs, l.num_vertices);
      exec_.upload(t.triangles, l.triangles, 3 * size_t(l.num_triangles));
      exec_.upload(t.tri_texture, l.tri_texture, l.num_triangles);
      exec_.upload(t.neighbors, l.neighbors, 3 * size_t(l.num_triangles));
      exec_.upload(t.opposite, l.opposite, 3 * size_t(l.num_triangles));
      exec_.upload(t.seams, l.seams, 3 * size_t(l.num_triangles));
      exec_.upload(t.tri_uv_area, l.tri_uv_area, l.num_triangles);
      MeshView v = l;
      v.positions = t.positions.ptr;
      v.colors = t.colors.ptr;
      v.uvs = l.uvs ? t.uvs.ptr : nullptr;
      v.triangles = t.triangles.ptr;
      v.tri_texture = t.tri_texture.ptr;
      v.neighbors = t.neighbors.ptr;
      v.opposite = t.opposite.ptr;
      v.seams = t.seams.ptr;
      v.tri_uv_area = t.tri_uv_area.ptr;
      v.textures = exec_views.empty() ? nullptr : d.textures.ptr;
      d.views.push_back(v);
    }
    exec_.synchronize("mesh upload");  // host_views / exec_views are about to go away
    auto& entry = meshes_[mesh.content_id()];
    entry = std::move(made);
    evict_meshes();
    return *entry;
  }

  /// The level of detail to draw `mesh` at for these poses: the coarsest whose error projects to at most
  /// RenderOptions::lod_pixel_error pixels at the nearest point of the object (bounding sphere) of any pose.
  int choose_lod(const Mesh& mesh, const Camera& camera, const std::vector<Pose>& poses) const {
    if (mesh.lods().empty() || !(options_.lod_pixel_error > 0)) return 0;
    double z_near = std::numeric_limits<double>::infinity();
    const double radius = 0.5 * (mesh.bbox_max() - mesh.bbox_min()).norm();
    for (const Pose& q : poses)
      if (q.t.allFinite() && q.R.allFinite()) z_near = std::min(z_near, (q * mesh.center()).z() - radius);
    if (!(z_near > options_.near_plane)) return 0;  // the object reaches the camera: full detail
    const double px_per_m = std::max(camera.fx, camera.fy) / z_near;
    int level = 0;
    for (size_t l = 0; l < mesh.lods().size(); ++l)
      if (mesh.lods()[l].error * px_per_m <= options_.lod_pixel_error) level = int(l) + 1;
    return level;
  }

  /// Keeps at most kMaxMeshes uploaded meshes, dropping the least recently used ones that the current call
  /// does not use (a long-running node that sees many objects must not grow without bound).
  void evict_meshes() {
    while (meshes_.size() > kMaxMeshes) {
      auto oldest = meshes_.end();
      for (auto it = meshes_.begin(); it != meshes_.end(); ++it)
        if (it->second->used < call_start_ && (oldest == meshes_.end() || it->second->used < oldest->second->used))
          oldest = it;
      if (oldest == meshes_.end()) return;  // all in use by this call
      meshes_.erase(oldest);
    }
  }

  /// Packs every hypothesis of every object (hyp_, regions, offsets); the caller binds the working arrays.
  /// Evaluating (a loss setup per object): S = 1 without a mask and a non-rotation pose gets no work and an
  /// infinite loss; rendering: only non-finite poses are skipped.
  Call prepare(const Camera& camera, const std::vector<ObjectCall>& objects, bool evaluating) {
    camera.validate();
    call_start_ = uses_ + 1;  // meshes used from here on belong to this call
    Call c{};
    Pipeline& p = c.p;
    p.K = to_intrinsics(camera);
    p.near_z = static_cast<float>(options_.near_plane);
    p.image_w = camera.width;
    p.image_h = camera.height;

    object_params_.resize(objects.size());
    object_lod_.resize(objects.size());
    size_t B = 0;
    for (const ObjectCall& o : objects) B += o.poses->size();
    if (B > 65535) throw std::invalid_argument("renderer: too many hypotheses in one call");
    hyp_.resize(B);
    int64_t pixels = 0, vertices = 0, triangles = 0;
    c.max_pixels = 1;
    size_t h = 0;
    for (size_t k = 0; k < objects.size(); ++k) {
      const Mesh& mesh = *objects[k].mesh;
      ObjectParams& op = object_params_[k];
      op = ObjectParams{};
      const int lod = object_lod_[k] = choose_lod(mesh, camera, *objects[k].poses);
      op.M = upload_mesh(mesh).views[size_t(lod)];
      op.nv = op.M.num_vertices;
      op.nt = op.M.num_triangles;
      op.cull = options_.cull_back_faces || (options_.auto_cull_closed && mesh.closed_and_outward(lod));
      c.max_vertices = std::max(c.max_vertices, op.nv);
      c.max_triangles = std::max(c.max_triangles, op.nt);
      const PixelRect& box = objects[k].box;
      for (const Pose& q : *objects[k].poses) {
        Hypothesis& hy = hyp_[h++];
        hy.valid = (evaluating ? q.is_valid(1e-3) : (q.R.allFinite() && q.t.allFinite())) ? 1 : 0;
        const PixelRect roi = hy.valid ? hypothesis_roi(camera, mesh, q, p.near_z, box,
                                                        std::max(1, options_.roi_margin), options_.use_roi)
                                       : PixelRect{0, 0, 1, 1};
        hy.T = to_rigid_transform(q);
        hy.x0 = roi.x0, hy.y0 = roi.y0, hy.w = roi.width(), hy.h = roi.height();
        hy.object = int(k);
        hy.offset = static_cast<int>(pixels);
        hy.vertex_offset = static_cast<int>(vertices);
        hy.triangle_offset = static_cast<int>(triangles);
        pixels += int64_t(hy.w) * hy.h;
        vertices += op.nv;
        triangles += op.nt;
        // Indices (and the 2 * pixel event slots) are ints on the device.
        if (pixels > INT_MAX / 2 || vertices > INT_MAX || triangles > INT_MAX)
          throw std::invalid_argument("renderer: too many pixels or vertices in one call (" +
                                      std::to_string(B) + " hypotheses); use smaller batches, images or a mask");
        c.max_pixels = std::max(c.max_pixels, hy.w * hy.h);
      }
    }
    c.B = int(B);
    c.pixels = int(pixels);
    c.vertices = size_t(vertices);
    c.triangles = size_t(triangles);
    exec_.upload(d_hyp_, hyp_.data(), B);
    p.H = d_hyp_.ptr;

    for (size_t k = 0; k < objects.size(); ++k) {  // loss constants and masks: evaluation only
      if (!objects[k].setup) continue;
      const LossSetup& s = objects[k].setup->setup;
      ObjectParams& op = object_params_[k];
      op.P = s.P;
      op.S = objects[k].S;
      op.k_edges = s.k_edges;
      op.edge_scale = s.edge_scale;
      op.k_texture = s.k_texture;
      op.texture_epsilon = s.texture_epsilon;
    }
    exec_.upload(d_objects_, object_params_.data(), object_params_.size());
    p.objects = d_objects_.ptr;

    return c;
  }

  /// The forward stages (vertices .. blends) of a prepared call.
  auto forward_steps(const Call& c) const {
    const Pipeline& p = c.p;
    // On a GPU, bands of rows per triangle, so a few big triangles (a box seen close up) still spread over many
    // threads: about 4 rows per thread for a triangle of average size (projected area ~ 2 * region / triangles).
    int bands = 1;
    if (Exec::kSplitsTriangles) {
      const double mean_rows = std::sqrt(2.0 * c.max_pixels / std::max(1, c.max_triangles));
      bands = std::max(1, std::min({64, int(std::ceil(mean_rows / 4.0)), (INT_MAX - 1024) / std::max(1, c.max_triangles)}));
    }
    return std::make_tuple(Each<VertexStage>{{p}, c.max_vertices}, Each<TriangleStage>{{p}, c.max_triangles},
                           Each<ClearStage>{{p}, c.max_pixels}, Each<RasterStage>{{p, bands}, c.max_triangles * bands},
                           Each<ShadeStage>{{p}, c.max_pixels}, Each<BlendDetectStage>{{p}, c.max_pixels},
                           Each<BlendApplyStage>{{p}, c.max_pixels});
  }

  /// The frame's images on the executor (uploaded when they changed); a new depth image invalidates the loss
  /// constants of every object.
  FrameImages upload_frame(const Observation& frame) {
    FrameImages f{nullptr, nullptr, nullptr, nullptr};
    bool changed = false;
    f.I = frame.has_rgb() ? exec_.image(0, frame.rgb, &changed) : nullptr;
    changed = false;
    f.D = frame.has_depth() ? exec_.image(1, frame.depth, &changed) : nullptr;
    if (changed) ++depth_generation_;
    f.E = frame.has_edges() ? exec_.image(2, frame.edges, &changed) : nullptr;
    f.T = frame.has_texture() ? exec_.image(3, frame.texture, &changed) : nullptr;
    return f;
  }

  /// Object k's mask on the executor (*S) and its loss constants, recomputed only when its inputs changed.
  const SetupCache& object_setup(size_t k, const Camera& camera, const Observation& o, const LossOptions& loss,
                                 const float** S) {
    static_assert(std::is_trivially_copyable<LossOptions>::value, "LossOptions is compared bytewise");
    if (setups_.size() <= k) setups_.resize(k + 1), mask_generation_.resize(k + 1, 0);
    *S = nullptr;
    if (o.has_mask()) {
      bool changed = false;
      *S = exec_.image(4 + int(k), o.mask, &changed);
      if (changed) ++mask_generation_[k];
    }
    SetupCache& c = setups_[k];
    const bool same = c.valid && c.loss == loss && c.width == camera.width &&
                      c.height == camera.height && c.has_rgb == o.has_rgb() && c.has_depth == o.has_depth() &&
                      c.has_mask == o.has_mask() && c.has_edges == o.has_edges() &&
                      c.has_texture == o.has_texture() &&
                      c.depth_generation == depth_generation_ && c.mask_generation == mask_generation_[k];
    if (!same) {
      c.valid = false;
      c.setup = make_loss_setup(camera, o, loss);
      c.box = mask_box(o.mask, camera.width, camera.height, true);
      c.loss = loss;
      c.width = camera.width, c.height = camera.height;
      c.has_rgb = o.has_rgb(), c.has_depth = o.has_depth(), c.has_mask = o.has_mask(), c.has_edges = o.has_edges();
      c.has_texture = o.has_texture();
      c.depth_generation = depth_generation_, c.mask_generation = mask_generation_[k];
      c.valid = true;
    }
    return c;
  }

  /// Forward, loss and (with_gradient) backward for the objects; outs[k] receives object k's values.
  void run(const Camera& camera, const FrameImages& frame, const std::vector<ObjectCall>& objects,
           bool with_gradient, std::vector<LossValue>* const* outs) {
    Call c = prepare(camera, objects, true);
    Pipeline& p = c.p;
    p.I = frame.I;
    p.D = frame.D;
    bool edges = false, texture = false;
    for (const ObjectCall& o : objects) {
      edges = edges || o.setup->setup.k_edges != 0.f;
      texture = texture || o.setup->setup.k_texture != 0.f;
    }
    edges = edges && frame.E;  // (k_edges != 0 only with an edge image, k_texture only with texture gradients)
    texture = texture && frame.T;
    p.E = edges ? frame.E : nullptr;
    p.T = texture ? frame.T : nullptr;
    p.with_gradient = with_gradient ? 1 : 0;
    const size_t B = size_t(c.B), N = size_t(c.pixels);
    // Per hypothesis: kSums loss sums (rgb, depth, mask, edges, texture), then 6 gradient components.
    constexpr int kSums = 5;
    out_.reserve((kSums + 6) * B);
    exec_.zero(out_.ptr, (kSums + 6) * B);
    if (!Exec::kWorkerScratch) work_.bind(p, c.vertices, c.triangles, N);
    const int n = c.max_pixels, n_edges = edges ? n : 0, n_texture = texture ? n : 0, n_grad = with_gradient ? n : 0;
    // Every stage of the call in one run: on the CPU each hypothesis goes through all of them on one thread.
    std::apply(
        [&](const auto&... forward) {
          const auto steps = std::make_tuple(
              forward..., Sum<LossStage>{{p}, n, out_.ptr, kSums}, Each<GreyStage>{{p}, edges || texture ? n : 0},
              Sum<EdgeStage>{{p}, n_edges, out_.ptr + 3, kSums}, Each<EdgeGatherStage>{{p}, n_edges && n_grad ? n : 0},
              Sum<TextureStage>{{p}, n_texture, out_.ptr + 4, kSums},
              Each<TextureGatherStage>{{p}, n_texture && n_grad ? n : 0},
              Sum<BackwardStage>{{p}, n_grad, out_.ptr + kSums * B, 6});
          std::apply(
              [&](const auto&... all) {
                if constexpr (!Exec::kWorkerScratch) exec_.run(c.B, all...);
                else exec_.run_in_scratch(c.B, all...);
              },
              steps);
        },
        forward_steps(c));
    double* host = exec_.results((kSums + 6) * B);
    exec_.download(host, out_.ptr, (kSums + 6) * B);
    exec_.synchronize("evaluate");
    size_t h = 0;
    for (size_t k = 0; k < objects.size(); ++k) {
      std::vector<LossValue>& out = *outs[k];
      for (size_t j = 0; j < out.size(); ++j, ++h) {
        LossValue& res = out[j];
        if (!hyp_[h].valid) {
          res.rgb = res.depth = res.mask = res.total = std::numeric_limits<double>::infinity();
          continue;
        }
        const double* s = host + kSums * h;
        finish_loss(objects[k].setup->setup, s[0], s[1], s[2], s[3], s[4], &res);
        if (with_gradient)
          for (int g = 0; g < 6; ++g) res.gradient[g] = host[kSums * B + 6 * h + g];
      }
    }
  }

  Exec exec_;
  std::map<uint64_t, std::unique_ptr<ExecMesh>> meshes_;  // by Mesh::content_id()
  uint64_t uses_ = 0, call_start_ = 0;
  std::vector<Hypothesis> hyp_;
  std::vector<ObjectParams> object_params_;
  std::vector<int> object_lod_;  // level of detail of each object of the call
  std::deque<SetupCache> setups_;  // per object slot of evaluate_objects; a deque, so
                                   // growing it keeps the references of the call in progress valid
  std::vector<uint64_t> mask_generation_;
  uint64_t depth_generation_ = 0;
  typename Exec::template Buffer<Hypothesis> d_hyp_;
  typename Exec::template Buffer<ObjectParams> d_objects_;
  WorkArrays<Exec::template Buffer> work_;  // packed for all hypotheses (unused when Exec::kWorkerScratch)
  typename Exec::template Buffer<double> out_;
};

}  // namespace pipeline
}  // namespace diffdope
