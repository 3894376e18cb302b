// CUDA backend of the differentiable renderer. The maths is the CPU backend's: every kernel here is a thin
// launcher around the DD_HOST_DEVICE functions of include/diffdope/kernels/ (vertex and triangle set-up,
// watertight raster, shading, discontinuity blends, per-pixel loss, backward passes). All B hypotheses of a
// call run in each launch (grid.y = hypothesis); the mesh and its textures are uploaded once per mesh, the
// observed images once per frame; one small download per call brings back the loss sums and gradients.
//
// Differences from the CPU backend, by construction only in float summation order: per-pixel sums are reduced
// in parallel (double atomics), and blends reaching one pixel from several neighbours are added in a fixed
// order that differs from the CPU's scan order (compiled with --fmad=false, so single operations round as on
// the CPU). Equivalence tests: test/unit/test_cuda_backend.cpp.
#include <cuda_runtime.h>

#include <climits>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "../src/core/loss_setup.hpp"
#include "../src/core/pixel_rect.hpp"
#include "../src/core/render_image.hpp"
#include "diffdope/device.hpp"
#include "diffdope/kernels/edges.hpp"
#include "diffdope/kernels/pixel_loss.hpp"
#include "diffdope/kernels/raster.hpp"
#include "diffdope/kernels/shade.hpp"
#include "diffdope/kernels/silhouette.hpp"
#include "diffdope/kernels/vertex_stage.hpp"

namespace diffdope {
namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string("CUDA backend: ") + what + ": " + cudaGetErrorString(e));
}

/// Grow-only device buffer.
template <typename T>
struct DeviceBuffer {
  T* ptr = nullptr;
  size_t capacity = 0;
  DeviceBuffer() = default;
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  ~DeviceBuffer() {
    if (ptr) cudaFree(ptr);
  }
  T* reserve(size_t n) {
    if (n > capacity) {
      if (ptr) cudaFree(ptr);
      ptr = nullptr;
      capacity = 0;  // a failed allocation must not leave a stale capacity behind
      check(cudaMalloc(&ptr, sizeof(T) * (n ? n : 1)), "cudaMalloc");
      capacity = n;
    }
    return ptr;
  }
  void upload(const T* host, size_t n, cudaStream_t s) {
    reserve(n);
    if (n) check(cudaMemcpyAsync(ptr, host, sizeof(T) * n, cudaMemcpyHostToDevice, s), "upload");
  }
};

/// Per-hypothesis constants of one call.
struct Hypothesis {
  RigidTransform T;
  int x0, y0, w, h;  // region of interest
  int offset;        // first pixel of the region in the packed pixel buffers
  int valid;         // 0: NaN / non-rotation pose (infinite loss, no work)
};

/// Per-call scalars.
struct CallParams {
  MeshView M;
  Intrinsics K;
  float near_z;
  int cull;
  int nv, nt, B;
  int image_w, image_h;
  PixelLossParams P;
  int has_mask, has_rgb, has_depth;
  float k_edges, edge_scale;  // the paper's edge term (0: off)
};

constexpr unsigned long long kEmptyKey = ~0ull;

__device__ ProjectedView projected(const CallParams& C, const Vec3f* cam, const Vec2f* pix, const float* area,
                                   const float* level, int h) {
  return ProjectedView{cam + size_t(h) * C.nv, pix + size_t(h) * C.nv, area + size_t(h) * C.nt,
                       level + size_t(h) * C.nt};
}

__global__ void vertex_kernel(CallParams C, const Hypothesis* H, Vec3f* cam, Vec2f* pix) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  if (i >= C.nv || !H[h].valid) return;
  vertex_setup(C.M, H[h].T, C.K, C.near_z, i, cam + size_t(h) * C.nv, pix + size_t(h) * C.nv);
}

__global__ void triangle_kernel(CallParams C, const Hypothesis* H, const Vec3f* cam, const Vec2f* pix, float* area,
                                float* level) {
  const int t = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  if (t >= C.nt) return;
  float* a = area + size_t(h) * C.nt;
  if (!H[h].valid) {
    a[t] = 0.f;
    return;
  }
  a[t] = triangle_setup(C.M, cam + size_t(h) * C.nv, pix + size_t(h) * C.nv, C.near_z, C.cull != 0, t);
  level[size_t(h) * C.nt + t] = triangle_mip_level(C.M, t, a[t]);
}

__global__ void clear_kernel(const Hypothesis* H, unsigned long long* key) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  if (i < H[h].w * H[h].h) key[H[h].offset + i] = kEmptyKey;
}

/// One thread per (triangle, hypothesis): walks the triangle's pixels in its region and keeps the nearest with
/// a 64-bit atomicMin on (depth bits, triangle): depths are positive, so their float bits order like the
/// floats, and ties keep the lower triangle index, as the CPU's scan does.
__global__ void raster_kernel(CallParams C, const Hypothesis* H, const Vec3f* cam, const Vec2f* pix,
                              const float* area, unsigned long long* key) {
  const int t = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  if (t >= C.nt || !H[h].valid || area[size_t(h) * C.nt + t] == 0.f) return;
  const Hypothesis hy = H[h];
  const Vec2f* P = pix + size_t(h) * C.nv;
  const Vec3f* X = cam + size_t(h) * C.nv;
  const int* v = C.M.triangles + 3 * t;
  const Vec2f s[3] = {P[v[0]], P[v[1]], P[v[2]]};
  const float z[3] = {X[v[0]].z, X[v[1]].z, X[v[2]].z};
  TriangleRaster R;
  if (!triangle_raster_setup(s, z, &R)) return;
  const int xs = max(hy.x0, R.x0), xe = min(hy.x0 + hy.w - 1, R.x1);
  const int ys = max(hy.y0, R.y0), ye = min(hy.y0 + hy.h - 1, R.y1);
  for (int y = ys; y <= ye; ++y) {
    long long e[3];
    raster_edges_at(R, xs, y, e);
    for (int x = xs; x <= xe; ++x, e[0] += R.dx[0], e[1] += R.dx[1], e[2] += R.dx[2]) {
      if (!raster_inside(R, e)) continue;
      const float zp = raster_depth(R, e);
      if (!(zp < INFINITY)) continue;  // as the CPU's zp < +inf test
      const unsigned long long k = (static_cast<unsigned long long>(__float_as_uint(zp)) << 32) | unsigned(t);
      atomicMin(key + hy.offset + (y - hy.y0) * hy.w + (x - hy.x0), k);
    }
  }
}

/// Visible triangle, shading (with the barycentrics kept for the backward pass); post starts as pre.
__global__ void shade_kernel(CallParams C, const Hypothesis* H, const Vec3f* cam, const Vec2f* pix,
                             const float* area, const float* level, const unsigned long long* key, int* tri,
                             PixelAttr* pre, PixelAttr* post, detail::ShadeBary* bary) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  if (i >= hy.w * hy.h) return;
  const int p = hy.offset + i;
  const unsigned long long k = key[p];
  const int t = k == kEmptyKey ? -1 : int(k & 0xffffffffu);
  tri[p] = t;
  PixelAttr a{0.f, {0.f, 0.f, 0.f}, 0.f};
  if (t >= 0) {
    const ProjectedView G = projected(C, cam, pix, area, level, h);
    Vec3f c;
    float d;
    shade_pixel(C.M, G, C.K, t, float(hy.x0 + i % hy.w), float(hy.y0 + i / hy.w), &c, &d, false, &bary[p]);
    a = PixelAttr{1.f, {c.x, c.y, c.z}, d};
  }
  pre[p] = a;
  post[p] = a;
}

/// Discontinuity between pixel i and its right (dir 0) / lower (dir 1) neighbour: the event goes to slot
/// 2 * pixel + dir. `to` is stored as a packed-buffer index.
__global__ void blend_detect_kernel(CallParams C, const Hypothesis* H, const Vec3f* cam, const Vec2f* pix,
                                    const float* area, const float* level, const int* tri, const PixelAttr* pre,
                                    BlendEvent* events, unsigned char* has_event) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  if (i >= hy.w * hy.h) return;
  const int lx = i % hy.w, ly = i / hy.w, p = hy.offset + i;
  const ProjectedView G = projected(C, cam, pix, area, level, h);
  const Vec2f pp{float(hy.x0 + lx), float(hy.y0 + ly)};
  for (int dir = 0; dir < 2; ++dir) {
    has_event[2 * p + dir] = 0;
    const bool horizontal = dir == 0;
    if (horizontal ? lx + 1 >= hy.w : ly + 1 >= hy.h) continue;
    const int q = horizontal ? p + 1 : p + hy.w;
    if (tri[p] == tri[q]) continue;
    const Vec2f pq = horizontal ? Vec2f{pp.x + 1.f, pp.y} : Vec2f{pp.x, pp.y + 1.f};
    BlendEvent ev;
    if (discontinuity_blend(C.M, G, C.K, p, tri[p], pre[p].d, pp, q, tri[q], pre[q].d, pq, horizontal, &ev)) {
      events[2 * p + dir] = ev;
      has_event[2 * p + dir] = 1;
    }
  }
}

/// The (up to four) event slots that can target pixel p, in the CPU's scan order (pixels row by row, each
/// pixel's horizontal pair before its vertical one): upper neighbour's vertical, left neighbour's horizontal,
/// then p's own two. So the blended attributes add up in the same order as on the CPU.
__device__ int event_slots(const Hypothesis& hy, int i, int p, int slots[4]) {
  const int lx = i % hy.w, ly = i / hy.w;
  int n = 0;
  if (ly > 0) slots[n++] = 2 * (p - hy.w) + 1;
  if (lx > 0) slots[n++] = 2 * (p - 1);
  slots[n++] = 2 * p;
  slots[n++] = 2 * p + 1;
  return n;
}

__global__ void blend_apply_kernel(const Hypothesis* H, const BlendEvent* events, const unsigned char* has_event,
                                   const PixelAttr* pre, PixelAttr* post) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  if (i >= hy.w * hy.h) return;
  const int p = hy.offset + i;
  int slots[4];
  const int n = event_slots(hy, i, p, slots);
  PixelAttr out = post[p];
  for (int k = 0; k < n; ++k)
    if (has_event[slots[k]] && events[slots[k]].to == p) apply_blend(events[slots[k]], pre[p], &out);
  post[p] = out;
}

/// Warp-level sum, then one double atomic per warp.
__device__ void warp_add(double v, double* target) {
  for (int o = 16; o > 0; o >>= 1) v += __shfl_down_sync(0xffffffffu, v, o);
  if ((threadIdx.x & 31) == 0 && v != 0.0) atomicAdd(target, v);
}

/// Per-pixel loss (sums per hypothesis: rgb, depth, mask) and dL/d(post).
__global__ void loss_kernel(CallParams C, const Hypothesis* H, const PixelAttr* post, const float* S_img,
                            const float* I_img, const float* D_img, int with_gradient, PixelAttr* g_post,
                            double* sums) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  float v_rgb = 0.f, v_depth = 0.f, v_mask = 0.f;
  if (i < hy.w * hy.h && hy.valid) {
    const int p = hy.offset + i;
    const int x = hy.x0 + i % hy.w, y = hy.y0 + i / hy.w, pix = y * C.image_w + x;
    const float S = C.has_mask ? S_img[pix] : 1.f;
    const float zero3[3] = {0.f, 0.f, 0.f};
    const float* I = C.has_rgb ? I_img + 3 * pix : zero3;
    const float Id = C.has_depth ? D_img[pix] : 0.f;
    const PixelAttr a = post[p];
    PixelLossGrad g;
    const PixelLossValue v = pixel_loss_step(C.P, S, I, Id, a.cov, a.c, a.d, with_gradient ? &g : nullptr);
    v_rgb = v.rgb, v_depth = v.depth, v_mask = v.mask;
    if (with_gradient) g_post[p] = PixelAttr{g.cov, {g.c[0], g.c[1], g.c[2]}, g.d};
  }
  warp_add(v_rgb, sums + 4 * h + 0);
  warp_add(v_depth, sums + 4 * h + 1);
  warp_add(v_mask, sums + 4 * h + 2);
}

/// Edge term, stage 1: the render's grey image (mean of the blended colour).
__global__ void grey_kernel(const Hypothesis* H, const PixelAttr* post, float* grey) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  if (i >= hy.w * hy.h) return;
  const PixelAttr& a = post[hy.offset + i];
  grey[hy.offset + i] = (a.c[0] + a.c[1] + a.c[2]) / 3.f;
}

/// Edge term, stage 2: |observed edges - rendered Sobel edges| over S (sums[4h + 3]) and dL/d(Sobel responses).
__global__ void edge_kernel(CallParams C, const Hypothesis* H, const float* grey, const float* S_img,
                            const float* E_img, int with_gradient, float* g_sx, float* g_sy, double* sums) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  float v = 0.f;
  if (i < hy.w * hy.h && hy.valid) {
    const int p = hy.offset + i, lx = i % hy.w, ly = i / hy.w;
    const int pix = (hy.y0 + ly) * C.image_w + hy.x0 + lx;
    const float S = C.has_mask ? S_img[pix] : 1.f;
    v = edge_term_step(grey + hy.offset, hy.w, hy.h, lx, ly, C.edge_scale, S, E_img[pix], C.k_edges,
                       with_gradient ? g_sx + p : nullptr, with_gradient ? g_sy + p : nullptr);
  }
  warp_add(v, sums + 4 * h + 3);
}

/// Edge term, stage 3: gathers the Sobel gradients into each pixel's colour gradient.
__global__ void edge_gather_kernel(const Hypothesis* H, const float* g_sx, const float* g_sy, PixelAttr* g_post) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  if (i >= hy.w * hy.h || !hy.valid) return;
  const float g = grey_gradient(g_sx + hy.offset, g_sy + hy.offset, hy.w, hy.h, i % hy.w, i / hy.w) / 3.f;
  for (int ch = 0; ch < 3; ++ch) g_post[hy.offset + i].c[ch] += g;
}

/// Backward per pixel: blends that reached it (into its pre-blend gradient and the silhouette gradient), then
/// its shading; the 6-D pose gradient is reduced per hypothesis.
__global__ void backward_kernel(CallParams C, const Hypothesis* H, const Vec3f* cam, const Vec2f* pix,
                                const float* area, const float* level, const int* tri, const PixelAttr* pre,
                                const PixelAttr* g_post, const BlendEvent* events, const unsigned char* has_event,
                                const detail::ShadeBary* bary, double* grads) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x, h = blockIdx.y;
  const Hypothesis hy = H[h];
  double g6[6] = {0, 0, 0, 0, 0, 0};
  if (i < hy.w * hy.h && hy.valid) {
    const int p = hy.offset + i;
    const ProjectedView G = projected(C, cam, pix, area, level, h);
    PixelAttr g_pre = g_post[p];
    int slots[4];
    const int n = event_slots(hy, i, p, slots);
    for (int k = 0; k < n; ++k)
      if (has_event[slots[k]] && events[slots[k]].to == p)
        blend_backward(C.M, G, C.K, events[slots[k]], pre[p], g_post[p], &g_pre, g6);
    const int t = tri[p];
    if (t >= 0 && (g_pre.c[0] != 0.f || g_pre.c[1] != 0.f || g_pre.c[2] != 0.f || g_pre.d != 0.f))
      shade_pixel_backward(C.M, G, C.K, t, float(hy.x0 + i % hy.w), float(hy.y0 + i / hy.w),
                           Vec3f{g_pre.c[0], g_pre.c[1], g_pre.c[2]}, g_pre.d, g6, false, &bary[p]);
  }
  for (int k = 0; k < 6; ++k) warp_add(g6[k], grads + 6 * h + k);
}

/// A mesh's arrays and textures on the device.
struct DeviceMesh {
  DeviceBuffer<Vec3f> positions, colors;
  DeviceBuffer<Vec2f> uvs;
  DeviceBuffer<int> triangles, tri_texture, neighbors, opposite;
  DeviceBuffer<unsigned char> seams;
  DeviceBuffer<float> tri_uv_area;
  std::vector<std::unique_ptr<DeviceBuffer<float>>> texels;  // one per texture level
  // What the upload was made from (the cache is keyed by the Mesh's address, which a new mesh may reuse).
  const void* positions_host = nullptr;
  Vec3f first{}, last{};
  DeviceBuffer<TextureView> textures;
  MeshView view{};
};

/// An observed image on the device, uploaded once per frame: the refiner evaluates the same images on every
/// iteration. The pinned staging buffer keeps exactly what was uploaded, so a new frame is recognised by an
/// exact comparison (~0.1 ms per MB; an address or a sampled hash could be reused by a different image).
struct DeviceImage {
  DeviceBuffer<float> data;
  float* pinned = nullptr;  // page-locked copy of the uploaded image (the copy runs at full bus speed)
  size_t pinned_size = 0, size = 0;
  DeviceImage() = default;
  DeviceImage(const DeviceImage&) = delete;
  DeviceImage& operator=(const DeviceImage&) = delete;
  ~DeviceImage() {
    if (pinned) cudaFreeHost(pinned);
  }
  const float* get(const cv::Mat& m, cudaStream_t s) {
    if (m.empty()) return nullptr;
    const cv::Mat c = m.isContinuous() ? m : m.clone();
    const size_t n = c.total() * c.channels();
    if (n == size && std::memcmp(pinned, c.ptr<float>(), sizeof(float) * n) == 0) return data.ptr;
    if (n > pinned_size) {
      if (pinned) cudaFreeHost(pinned);
      pinned = nullptr;
      pinned_size = size = 0;
      check(cudaMallocHost(&pinned, sizeof(float) * n), "cudaMallocHost");
      pinned_size = n;
    }
    size = 0;  // until the upload is queued
    std::memcpy(pinned, c.ptr<float>(), sizeof(float) * n);
    data.upload(pinned, n, s);
    size = n;
    return data.ptr;
  }
};

class CudaRenderer final : public Renderer {
 public:
  explicit CudaRenderer(const RenderOptions& options) : Renderer(options) {
    check(cudaStreamCreate(&stream_), "cudaStreamCreate");
    if (cudaMallocHost(&host_out_, sizeof(double) * kMaxOut) != cudaSuccess) {
      cudaStreamDestroy(stream_);
      throw std::runtime_error("CUDA backend: cannot allocate pinned host memory");
    }
  }
  ~CudaRenderer() override {
    if (host_out_) cudaFreeHost(host_out_);
    if (stream_) cudaStreamDestroy(stream_);
  }
  std::string name() const override { return "cuda"; }

  std::vector<RenderImage> render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                  const cv::Mat& observed_mask) override;
  void evaluate(const Camera& camera, const Mesh& mesh, const Observation& observed, const std::vector<Pose>& poses,
                const LossOptions& loss, bool with_gradient, std::vector<LossValue>& out) override;

 private:
  static constexpr size_t kMaxOut = 10 * 4096;  // sums (4) and gradients (6) per hypothesis

  const MeshView& upload_mesh(const Mesh& mesh);
  /// Forward stages for every hypothesis: vertices .. blends. Fills hyp_ and the pixel buffers.
  /// `evaluating`: evaluate() semantics (S = 1 without a mask; a non-rotation pose gets no work and an infinite
  /// loss); else render() semantics (only non-finite poses are skipped), as the CPU backend.
  CallParams forward(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses, const cv::Mat& mask,
                     bool evaluating);

  cudaStream_t stream_ = nullptr;
  double* host_out_ = nullptr;
  std::map<const Mesh*, std::unique_ptr<DeviceMesh>> meshes_;
  std::vector<Hypothesis> hyp_;
  int total_pixels_ = 0, max_pixels_ = 0;
  DeviceBuffer<Hypothesis> d_hyp_;
  DeviceBuffer<Vec3f> cam_;
  DeviceBuffer<Vec2f> pix_;
  DeviceBuffer<float> area_, level_;
  DeviceBuffer<unsigned long long> key_;
  DeviceBuffer<int> tri_;
  DeviceBuffer<PixelAttr> pre_, post_, g_post_;
  DeviceBuffer<detail::ShadeBary> bary_;
  DeviceBuffer<BlendEvent> events_;
  DeviceBuffer<unsigned char> has_event_;
  DeviceBuffer<double> out_;
  DeviceBuffer<float> grey_, g_sx_, g_sy_;
  DeviceImage mask_img_, rgb_img_, depth_img_, edges_img_;
};

const MeshView& CudaRenderer::upload_mesh(const Mesh& mesh) {
  auto& slot = meshes_[&mesh];
  // Keyed by the Mesh's address; counts, the positions' storage and two vertices confirm it is the same mesh
  // (a new mesh at a reused address is uploaded again).
  const auto same = [](Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  if (slot && slot->view.num_vertices == mesh.num_vertices() && slot->view.num_triangles == mesh.num_triangles() &&
      slot->positions_host == mesh.positions.data() && same(slot->first, mesh.positions.front()) &&
      same(slot->last, mesh.positions.back()))
    return slot->view;
  slot = std::make_unique<DeviceMesh>();
  DeviceMesh& d = *slot;
  std::vector<TextureView> host_views;
  const MeshView h = mesh.view(host_views);
  d.positions.upload(h.positions, h.num_vertices, stream_);
  d.colors.upload(h.colors, h.num_vertices, stream_);
  if (h.uvs) d.uvs.upload(h.uvs, h.num_vertices, stream_);
  d.triangles.upload(h.triangles, 3 * size_t(h.num_triangles), stream_);
  d.tri_texture.upload(h.tri_texture, h.num_triangles, stream_);
  d.neighbors.upload(h.neighbors, 3 * size_t(h.num_triangles), stream_);
  d.opposite.upload(h.opposite, 3 * size_t(h.num_triangles), stream_);
  d.seams.upload(h.seams, 3 * size_t(h.num_triangles), stream_);
  d.tri_uv_area.upload(h.tri_uv_area, h.num_triangles, stream_);
  std::vector<TextureView> device_views = host_views;
  for (size_t t = 0; t < host_views.size(); ++t)
    for (int l = 0; l < host_views[t].levels; ++l) {
      const TextureLevelView& lv = host_views[t].level[l];
      d.texels.push_back(std::make_unique<DeviceBuffer<float>>());
      d.texels.back()->upload(lv.rgb, 3 * size_t(lv.width) * lv.height, stream_);
      device_views[t].level[l].rgb = d.texels.back()->ptr;
    }
  if (!device_views.empty()) d.textures.upload(device_views.data(), device_views.size(), stream_);
  check(cudaStreamSynchronize(stream_), "mesh upload");  // host_views / device_views are about to go away
  d.positions_host = mesh.positions.data();
  d.first = mesh.positions.front();
  d.last = mesh.positions.back();
  d.view = h;
  d.view.positions = d.positions.ptr;
  d.view.colors = d.colors.ptr;
  d.view.uvs = h.uvs ? d.uvs.ptr : nullptr;
  d.view.triangles = d.triangles.ptr;
  d.view.tri_texture = d.tri_texture.ptr;
  d.view.neighbors = d.neighbors.ptr;
  d.view.opposite = d.opposite.ptr;
  d.view.seams = d.seams.ptr;
  d.view.tri_uv_area = d.tri_uv_area.ptr;
  d.view.textures = device_views.empty() ? nullptr : d.textures.ptr;
  return d.view;
}

CallParams CudaRenderer::forward(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                 const cv::Mat& mask, bool evaluating) {
  camera.validate();
  if (mesh.num_triangles() == 0 || mesh.neighbors().size() != mesh.triangles.size())
    throw std::invalid_argument("renderer: mesh '" + mesh.name + "' is empty or not finalized");
  if (poses.size() > kMaxOut / 10) throw std::invalid_argument("CUDA backend: too many hypotheses in one call");
  CallParams C{};
  C.M = upload_mesh(mesh);
  C.K = camera.intrinsics();
  C.near_z = static_cast<float>(options_.near_plane);
  C.cull = options_.cull_back_faces || (options_.auto_cull_closed && mesh.closed_and_outward());
  C.nv = mesh.num_vertices();
  C.nt = mesh.num_triangles();
  C.B = static_cast<int>(poses.size());
  C.image_w = camera.width;
  C.image_h = camera.height;

  const PixelRect box = mask_box(mask, camera.width, camera.height, evaluating);
  hyp_.resize(poses.size());
  int64_t total = 0;
  max_pixels_ = 1;
  for (size_t h = 0; h < poses.size(); ++h) {
    Hypothesis& hy = hyp_[h];
    const Pose& q = poses[h];
    hy.valid = (evaluating ? q.is_valid(1e-3) : (q.R.allFinite() && q.t.allFinite())) ? 1 : 0;
    const PixelRect roi = hy.valid ? hypothesis_roi(camera, mesh, poses[h], C.near_z, box,
                                                    std::max(1, options_.roi_margin), options_.use_roi)
                                   : PixelRect{0, 0, 1, 1};
    hy.T = poses[h].to_kernel();
    hy.x0 = roi.x0, hy.y0 = roi.y0, hy.w = roi.width(), hy.h = roi.height();
    hy.offset = static_cast<int>(total);
    total += int64_t(hy.w) * hy.h;
    // Pixel indices (and the 2 * pixel event slots) are ints on the device.
    if (total > INT_MAX / 2)
      throw std::invalid_argument("CUDA backend: too many pixels in one call (" + std::to_string(poses.size()) +
                                  " hypotheses); use smaller batches, images or a mask");
    max_pixels_ = std::max(max_pixels_, hy.w * hy.h);
  }
  total_pixels_ = static_cast<int>(total);
  const size_t B = poses.size(), N = size_t(total_pixels_);
  d_hyp_.upload(hyp_.data(), B, stream_);
  cam_.reserve(B * C.nv);
  pix_.reserve(B * C.nv);
  area_.reserve(B * C.nt);
  level_.reserve(B * C.nt);
  key_.reserve(N);
  tri_.reserve(N);
  pre_.reserve(N);
  post_.reserve(N);
  bary_.reserve(N);
  events_.reserve(2 * N);
  has_event_.reserve(2 * N);

  const int T = 128;
  const dim3 gv((C.nv + T - 1) / T, C.B), gt((C.nt + T - 1) / T, C.B), gp((max_pixels_ + T - 1) / T, C.B);
  vertex_kernel<<<gv, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr);
  triangle_kernel<<<gt, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr, area_.ptr, level_.ptr);
  clear_kernel<<<gp, T, 0, stream_>>>(d_hyp_.ptr, key_.ptr);
  raster_kernel<<<gt, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr, area_.ptr, key_.ptr);
  shade_kernel<<<gp, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr, area_.ptr, level_.ptr, key_.ptr, tri_.ptr,
                                      pre_.ptr, post_.ptr, bary_.ptr);
  blend_detect_kernel<<<gp, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr, area_.ptr, level_.ptr, tri_.ptr,
                                             pre_.ptr, events_.ptr, has_event_.ptr);
  blend_apply_kernel<<<gp, T, 0, stream_>>>(d_hyp_.ptr, events_.ptr, has_event_.ptr, pre_.ptr, post_.ptr);
  check(cudaGetLastError(), "forward kernels");
  return C;
}

std::vector<RenderImage> CudaRenderer::render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                              const cv::Mat& observed_mask) {
  if (!observed_mask.empty() && (observed_mask.type() != CV_32FC1 || observed_mask.cols != camera.width ||
                                 observed_mask.rows != camera.height))
    throw std::invalid_argument("render: observed mask must be CV_32FC1 of the camera's size");
  if (poses.empty()) return {};
  forward(camera, mesh, poses, observed_mask, false);
  std::vector<PixelAttr> pre(total_pixels_), post(total_pixels_);
  std::vector<int> tri(total_pixels_);
  check(cudaMemcpyAsync(pre.data(), pre_.ptr, sizeof(PixelAttr) * pre.size(), cudaMemcpyDeviceToHost, stream_), "download");
  check(cudaMemcpyAsync(post.data(), post_.ptr, sizeof(PixelAttr) * post.size(), cudaMemcpyDeviceToHost, stream_), "download");
  check(cudaMemcpyAsync(tri.data(), tri_.ptr, sizeof(int) * tri.size(), cudaMemcpyDeviceToHost, stream_), "download");
  check(cudaStreamSynchronize(stream_), "render");
  std::vector<RenderImage> out(poses.size());
  for (size_t h = 0; h < poses.size(); ++h) {  // an invalid hypothesis has a 1-pixel region, left empty
    const Hypothesis& hy = hyp_[h];
    const PixelRect roi{hy.x0, hy.y0, hy.x0 + hy.w, hy.y0 + hy.h};
    out[h] = make_render_image(camera, roi, pre.data() + hy.offset, post.data() + hy.offset, tri.data() + hy.offset);
  }
  return out;
}

void CudaRenderer::evaluate(const Camera& camera, const Mesh& mesh, const Observation& obs,
                            const std::vector<Pose>& poses, const LossOptions& loss, bool with_gradient,
                            std::vector<LossValue>& out) {
  obs.validate(camera);
  if (!(loss.depth_truncation > 0)) throw std::invalid_argument("loss: depth_truncation must be > 0");
  const LossSetup setup = make_loss_setup(camera, obs, loss);
  out.assign(poses.size(), LossValue());
  if (poses.empty()) return;
  CallParams C = forward(camera, mesh, poses, obs.mask, true);
  C.P = setup.P;
  C.has_mask = obs.has_mask(), C.has_rgb = obs.has_rgb(), C.has_depth = obs.has_depth();
  C.k_edges = setup.k_edges, C.edge_scale = setup.edge_scale;
  const float* S = mask_img_.get(obs.mask, stream_);
  const float* I = rgb_img_.get(obs.rgb, stream_);
  const float* D = depth_img_.get(obs.depth, stream_);
  const float* E = C.k_edges != 0.f ? edges_img_.get(obs.edges, stream_) : nullptr;
  const size_t B = poses.size();
  out_.reserve(10 * B);
  check(cudaMemsetAsync(out_.ptr, 0, sizeof(double) * 10 * B, stream_), "memset");
  if (with_gradient) g_post_.reserve(size_t(total_pixels_));
  const int T = 128;
  const dim3 gp((max_pixels_ + T - 1) / T, C.B);
  loss_kernel<<<gp, T, 0, stream_>>>(C, d_hyp_.ptr, post_.ptr, S, I, D, with_gradient ? 1 : 0, g_post_.ptr, out_.ptr);
  if (E) {  // the edge term, as the CPU backend computes it, after the per-pixel terms
    grey_.reserve(size_t(total_pixels_));
    if (with_gradient) g_sx_.reserve(size_t(total_pixels_)), g_sy_.reserve(size_t(total_pixels_));
    grey_kernel<<<gp, T, 0, stream_>>>(d_hyp_.ptr, post_.ptr, grey_.ptr);
    edge_kernel<<<gp, T, 0, stream_>>>(C, d_hyp_.ptr, grey_.ptr, S, E, with_gradient ? 1 : 0, g_sx_.ptr, g_sy_.ptr,
                                       out_.ptr);
    if (with_gradient) edge_gather_kernel<<<gp, T, 0, stream_>>>(d_hyp_.ptr, g_sx_.ptr, g_sy_.ptr, g_post_.ptr);
  }
  if (with_gradient)
    backward_kernel<<<gp, T, 0, stream_>>>(C, d_hyp_.ptr, cam_.ptr, pix_.ptr, area_.ptr, level_.ptr, tri_.ptr,
                                           pre_.ptr, g_post_.ptr, events_.ptr, has_event_.ptr, bary_.ptr,
                                           out_.ptr + 4 * B);
  check(cudaGetLastError(), "loss kernels");
  check(cudaMemcpyAsync(host_out_, out_.ptr, sizeof(double) * 10 * B, cudaMemcpyDeviceToHost, stream_), "download");
  check(cudaStreamSynchronize(stream_), "evaluate");
  for (size_t h = 0; h < B; ++h) {
    LossValue& res = out[h];
    if (!hyp_[h].valid) {
      res.rgb = res.depth = res.mask = res.total = std::numeric_limits<double>::infinity();
      continue;
    }
    const double* s = host_out_ + 4 * h;
    finish_loss(setup, s[0], s[1], s[2], s[3], &res);
    if (with_gradient)
      for (int k = 0; k < 6; ++k) res.gradient[k] = host_out_[4 * B + 6 * h + k];
  }
}

}  // namespace

CudaDeviceInfo cuda_probe_device() {
  CudaDeviceInfo info;
  info.built = true;
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    info.reason = std::string("no usable CUDA device: ") + cudaGetErrorString(e);
    cudaGetLastError();  // clear the sticky error so later calls start clean
    return info;
  }
  if (count == 0) {
    info.reason = "no CUDA device present";
    return info;
  }
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) {
    info.reason = "cannot read CUDA device 0's properties";
    return info;
  }
  info.name = std::string(prop.name) + " (sm_" + std::to_string(prop.major) + std::to_string(prop.minor) + ")";
  int compute_mode = 0;
  if (cudaDeviceGetAttribute(&compute_mode, cudaDevAttrComputeMode, 0) == cudaSuccess &&
      compute_mode == cudaComputeModeProhibited) {
    info.reason = info.name + " is in compute-prohibited mode";
    return info;
  }
  // A device older than the compiled architectures has no kernel image for them: not usable.
  cudaFuncAttributes attr{};
  const cudaError_t k = cudaFuncGetAttributes(&attr, vertex_kernel);
  if (k != cudaSuccess) {
    info.reason = info.name + " cannot run this build's kernels (" + cudaGetErrorString(k) +
                  "; rebuild with diffdope_ros_CUDA_ARCHITECTURES including it)";
    cudaGetLastError();
    return info;
  }
  info.available = true;
  return info;
}

std::unique_ptr<Renderer> cuda_make_renderer(const RenderOptions& options) {
  return std::make_unique<CudaRenderer>(options);
}

}  // namespace diffdope
