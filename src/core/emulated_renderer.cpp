// The CUDA backend's batched pipeline on CPU threads (see src/core/batched_renderer.hpp): host buffers, and
// each stage run for every (element, hypothesis) before the next stage starts, as kernels on one stream are.
// Hypotheses run in parallel; one hypothesis' elements run in order on one thread, which is what makes the
// plain-memory z-buffer minimum and the per-hypothesis sums of the stages safe here.
#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "batched_renderer.hpp"
#include "diffdope/device.hpp"
#include "diffdope/thread_pool.hpp"

namespace diffdope {
namespace {

/// Grow-only host buffer.
template <typename T>
struct HostBuffer {
  T* ptr = nullptr;
  std::vector<T> storage;
  T* reserve(size_t n) {
    if (n > storage.size()) storage.resize(n);
    ptr = storage.empty() ? nullptr : storage.data();
    return ptr;
  }
};

class EmulatedExec {
 public:
  template <class T>
  using Buffer = HostBuffer<T>;

  explicit EmulatedExec(int threads) : pool_(threads) {}  // RenderOptions::threads (0 = all)
  std::string name() const { return "cuda-emulated"; }
  template <class T>
  void upload(Buffer<T>& b, const T* host, size_t n) {
    b.reserve(n);
    if (n) std::memcpy(static_cast<void*>(b.ptr), host, sizeof(T) * n);
  }
  template <class T>
  void download(T* host, const T* src, size_t n) {
    if (n) std::memcpy(static_cast<void*>(host), src, sizeof(T) * n);
  }
  void zero(double* p, size_t n) { std::fill(p, p + n, 0.0); }
  template <class Stage>
  void for_each(int n, int B, const Stage& stage) {
    pool_.parallel_for(B, [&](int h, int) {
      for (int i = 0; i < n; ++i) stage(i, h);
    });
  }
  template <class Stage>
  void reduce(int n, int B, const Stage& stage, double* out, int stride) {
    pool_.parallel_for(B, [&](int h, int) {
      double sum[Stage::kValues] = {};
      for (int i = 0; i < n; ++i) {
        double v[Stage::kValues] = {};
        stage(i, h, v);
        for (int k = 0; k < Stage::kValues; ++k) sum[k] += v[k];
      }
      for (int k = 0; k < Stage::kValues; ++k) out[size_t(stride) * h + k] += sum[k];
    });
  }
  void synchronize(const char*) {}
  void drain() {}
  /// A copy of the image per slot, replaced only when the content differs (as the CUDA executor's staging).
  const float* image(int slot, const cv::Mat& m, bool* changed) {
    if (int(images_.size()) <= slot) images_.resize(slot + 1);
    cv::Mat& kept = images_[slot];
    const size_t bytes = m.total() * m.elemSize();
    const bool same = kept.size == m.size && kept.type() == m.type() && m.isContinuous() &&
                      std::memcmp(kept.data, m.data, bytes) == 0;
    if (!same) {
      kept = m.clone();
      *changed = true;
    }
    return kept.ptr<float>();
  }
  double* results(size_t n) {
    if (results_.size() < n) results_.resize(n);
    return results_.data();
  }

 private:
  ThreadPool pool_;
  std::vector<cv::Mat> images_;
  std::vector<double> results_;
};

}  // namespace

std::unique_ptr<Renderer> make_emulated_cuda_renderer(const RenderOptions& options) {
  return std::make_unique<batched::BatchedRenderer<EmulatedExec>>(options, options.threads);
}

}  // namespace diffdope
