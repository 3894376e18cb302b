// The CPU backend: the render pipeline (src/core/render_pipeline.hpp) executed on host threads. Each hypothesis
// runs every stage of a call back to back on one thread, so its region's buffers stay in the core's cache
// between stages; the hypotheses of all objects of the call are spread over the threads. One hypothesis' elements
// run in order on one thread, which is what makes the plain-memory z-buffer minimum and the sums safe here.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "diffdope/thread_pool.hpp"
#include "render_pipeline.hpp"

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

class HostExec {
 public:
  template <class T>
  using Buffer = HostBuffer<T>;
  static constexpr bool kSplitsTriangles = false;  // one thread walks a whole triangle

  /// RenderOptions::threads (0 = all). DIFFDOPE_STAGE_PROFILE=1 in the environment: time every stage and print
  /// a table to stderr when the renderer goes away (for profiling; ~20 ns per stage and hypothesis).
  explicit HostExec(int threads) : pool_(threads), profile_(std::getenv("DIFFDOPE_STAGE_PROFILE") != nullptr) {}
  ~HostExec() {
    if (!profile_) return;
    double total = 0;
    for (const StageTime& t : times_) total += 1e-6 * t.ns.load();
    std::fprintf(stderr, "diffdope stage profile (CPU time, all threads): %.1f ms in all\n", total);
    for (const StageTime& t : times_)
      if (t.name.load())
        std::fprintf(stderr, "  %-14s %10.1f ms %5.1f %%  %12lld hypothesis-runs\n", t.name.load(), 1e-6 * t.ns.load(),
                     total > 0 ? 100.0 * 1e-6 * t.ns.load() / total : 0.0, static_cast<long long>(t.runs.load()));
  }
  std::string name() const { return "cpu"; }
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

  template <class... Steps>
  void run(int B, const Steps&... steps) {
    if (!profile_) {
      pool_.parallel_for(B, [&](int h, int) { (step(steps, h), ...); });
      return;
    }
    pool_.parallel_for(B, [&](int h, int) {
      int k = 0;
      (timed(steps, h, k++), ...);
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
  /// Stages over the pixels of a region (kPixels) are walked row by row: no division per pixel.
  template <class Stage>
  static void step(const pipeline::Each<Stage>& s, int h) {
    const int n = std::min(s.n, s.stage.count(h));
    if (n <= 0) return;
    if constexpr (pipeline::is_pixel_stage<Stage>::value) {
      const int w = s.stage.p.H[h].w, rows = n / w;
      for (int ly = 0, i = 0; ly < rows; ++ly)
        for (int lx = 0; lx < w; ++lx, ++i) s.stage.pixel(lx, ly, i, h);
    } else {
      for (int i = 0; i < n; ++i) s.stage(i, h);
    }
  }
  template <class Stage>
  static void step(const pipeline::Sum<Stage>& s, int h) {
    static_assert(pipeline::is_pixel_stage<Stage>::value, "reducing stages run over the pixels of the regions");
    const int n = std::min(s.n, s.stage.count(h));
    if (n <= 0) return;
    double sum[Stage::kValues] = {};
    const int w = s.stage.p.H[h].w, rows = n / w;
    for (int ly = 0, i = 0; ly < rows; ++ly)
      for (int lx = 0; lx < w; ++lx, ++i) {
        double v[Stage::kValues] = {};
        s.stage.pixel(lx, ly, i, h, v);
        for (int k = 0; k < Stage::kValues; ++k) sum[k] += v[k];
      }
    for (int k = 0; k < Stage::kValues; ++k) s.out[size_t(s.stride) * h + k] += sum[k];
  }

  template <class Step>
  void timed(const Step& s, int h, int k) {
    const auto t0 = std::chrono::steady_clock::now();
    step(s, h);
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0);
    StageTime& t = times_[size_t(k) % kMaxSteps];
    t.name = decltype(s.stage)::kName;
    t.ns += ns.count();
    ++t.runs;
  }
  struct StageTime {
    std::atomic<const char*> name{nullptr};
    std::atomic<long long> ns{0}, runs{0};
  };

  ThreadPool pool_;
  const bool profile_;
  static constexpr size_t kMaxSteps = 16;
  StageTime times_[kMaxSteps];
  std::vector<cv::Mat> images_;
  std::vector<double> results_;
};

}  // namespace

std::unique_ptr<Renderer> make_cpu_renderer(const RenderOptions& options) {
  return std::make_unique<pipeline::PipelineRenderer<HostExec>>(options, options.threads);
}

}  // namespace diffdope
