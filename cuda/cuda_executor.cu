// The CUDA executor of the render pipeline (src/render/pipeline.hpp): each stage of
// src/render/stages.hpp (thin functors around the DD_HOST_DEVICE maths of src/render/kernels/) is one
// kernel launch over every hypothesis of every object of a call (grid.y = hypothesis); meshes and textures are
// uploaded once per mesh, observed images once per frame (pinned staging), all on one stream; one small download
// per call brings back the loss sums and gradients.
//
// Differences from the CPU executor (src/render/host_executor.cpp, the same stages on host threads): float
// summation order (per-pixel sums are reduced in parallel, a warp sum then a double atomic per warp, in no fixed
// order) and the device's libm (log2f of the mip level may differ by an ulp). Compiled with --fmad=false, so
// single arithmetic operations round as on the CPU. Equivalence tests: test/unit/test_executors.cpp.
#include <cuda_runtime.h>

#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "render/pipeline.hpp"
#include "diffdope/device.hpp"

namespace diffdope {
namespace {

void check(cudaError_t e, const char* what) {
  if (e == cudaSuccess) return;
  cudaGetLastError();  // a failed allocation stays the "last error": a later launch check must not see it again
  throw std::runtime_error(std::string("CUDA backend: ") + what + ": " + cudaGetErrorString(e));
}

template <class Stage>
__global__ void for_each_kernel(Stage stage, int n) {
  const long long i = static_cast<long long>(blockIdx.x) * blockDim.x + threadIdx.x;  // no int overflow near n
  if (i < n) stage(int(i), int(blockIdx.y));
}

/// Every thread of a warp takes part in the warp sum, so the bound check is inside the stage.
template <class Stage>
__global__ void reduce_kernel(Stage stage, int n, double* out, int stride) {
  const long long i = static_cast<long long>(blockIdx.x) * blockDim.x + threadIdx.x;
  const int h = int(blockIdx.y);
  double v[Stage::kValues];
  for (int k = 0; k < Stage::kValues; ++k) v[k] = 0.0;
  if (i < n) stage(int(i), h, v);
  for (int k = 0; k < Stage::kValues; ++k) {
    double s = v[k];
    for (int o = 16; o > 0; o >>= 1) s += __shfl_down_sync(0xffffffffu, s, o);
    if ((threadIdx.x & 31) == 0 && s != 0.0) atomicAdd(out + size_t(stride) * h + k, s);
  }
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
  const float* get(const cv::Mat& m, cudaStream_t s, bool* changed) {
    const cv::Mat c = m.isContinuous() ? m : m.clone();
    const size_t n = c.total() * c.channels();
    if (n == size && std::memcmp(pinned, c.ptr<float>(), sizeof(float) * n) == 0) return data.ptr;
    *changed = true;
    if (n > pinned_size) {
      if (pinned) cudaFreeHost(pinned);
      pinned = nullptr;
      pinned_size = size = 0;
      check(cudaMallocHost(&pinned, sizeof(float) * n), "cudaMallocHost");
      pinned_size = n;
    }
    size = 0;  // until the upload is queued
    std::memcpy(pinned, c.ptr<float>(), sizeof(float) * n);
    data.reserve(n);
    check(cudaMemcpyAsync(data.ptr, pinned, sizeof(float) * n, cudaMemcpyHostToDevice, s), "image upload");
    size = n;
    return data.ptr;
  }
};

class CudaExec {
 public:
  template <class T>
  using Buffer = DeviceBuffer<T>;
  static constexpr int kThreads = 128;
  static unsigned blocks(int n) { return static_cast<unsigned>((static_cast<long long>(n) + kThreads - 1) / kThreads); }

  CudaExec() { check(cudaStreamCreate(&stream_), "cudaStreamCreate"); }
  ~CudaExec() {
    if (results_) cudaFreeHost(results_);
    if (stream_) cudaStreamDestroy(stream_);
  }
  CudaExec(const CudaExec&) = delete;
  CudaExec& operator=(const CudaExec&) = delete;
  std::string name() const { return "cuda"; }

  template <class T>
  void upload(Buffer<T>& b, const T* host, size_t n) {
    b.reserve(n);
    if (n) check(cudaMemcpyAsync(b.ptr, host, sizeof(T) * n, cudaMemcpyHostToDevice, stream_), "upload");
  }
  template <class T>
  void download(T* host, const T* src, size_t n) {
    if (n) check(cudaMemcpyAsync(host, src, sizeof(T) * n, cudaMemcpyDeviceToHost, stream_), "download");
  }
  void zero(double* p, size_t n) { check(cudaMemsetAsync(p, 0, sizeof(double) * n, stream_), "memset"); }
  static constexpr bool kSplitsTriangles = true;  // big triangles in bands of rows: more threads
  static constexpr bool kWorkerScratch = false;  // the packed arrays are the device's working memory
  template <class... Steps>
  void run(int B, const Steps&... steps) {
    if (B > 0) (launch(steps, B), ...);
  }
  void synchronize(const char* what) { check(cudaStreamSynchronize(stream_), what); }
  void drain() {
    cudaStreamSynchronize(stream_);
    cudaGetLastError();
  }
  const float* image(int slot, const cv::Mat& m, bool* changed) {
    while (int(images_.size()) <= slot) images_.push_back(std::make_unique<DeviceImage>());
    return images_[slot]->get(m, stream_, changed);
  }
  double* results(size_t n) {
    if (n > results_size_) {
      if (results_) cudaFreeHost(results_);
      results_ = nullptr;
      results_size_ = 0;
      check(cudaMallocHost(&results_, sizeof(double) * n), "cudaMallocHost");
      results_size_ = n;
    }
    return results_;
  }

 private:
  cudaStream_t stream_ = nullptr;
  std::vector<std::unique_ptr<DeviceImage>> images_;
  double* results_ = nullptr;
  size_t results_size_ = 0;

  template <class Stage>
  void launch(const pipeline::Each<Stage>& s, int B) {
    if (s.n <= 0) return;
    for_each_kernel<<<dim3(blocks(s.n), B), kThreads, 0, stream_>>>(s.stage, s.n);
    check(cudaGetLastError(), "kernel launch");
  }
  template <class Stage>
  void launch(const pipeline::Sum<Stage>& s, int B) {
    if (s.n <= 0) return;
    reduce_kernel<<<dim3(blocks(s.n), B), kThreads, 0, stream_>>>(s.stage, s.n, s.out, s.stride);
    check(cudaGetLastError(), "kernel launch");
  }
};

}  // namespace

CudaDeviceInfo cuda_probe_device() {
  CudaDeviceInfo info;
  info.built = true;
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    info.reason = std::string("no usable CUDA device: ") + cudaGetErrorString(e);
    cudaGetLastError();  // clear the error so later calls start clean
    return info;
  }
  if (count == 0) {
    info.reason = "no CUDA device present";
    return info;
  }
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) {
    cudaGetLastError();
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
  const cudaError_t k = cudaFuncGetAttributes(&attr, for_each_kernel<pipeline::VertexStage>);
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
  return std::make_unique<pipeline::PipelineRenderer<CudaExec>>(options);
}

}  // namespace diffdope
