// The CPU backend: the render pipeline (src/render/pipeline.hpp) executed on host threads. Each hypothesis
// runs every stage of a call back to back on one thread; the hypotheses of all objects of the call are spread
// over the threads. When evaluating, each thread works in its own per-hypothesis arrays, reused from one
// hypothesis to the next, so they stay in the core's cache between stages and hypotheses (the packed arrays of
// all hypotheses, tens of MB for B = 32, would stream through memory). A call with fewer hypotheses than
// threads (a refinement's last runs, its print search and scoring) runs them one at a time instead, each stage
// split over the threads by elements or rows, the raster excepted: its z-buffer minimum is plain memory, safe
// only on one thread. Sums are added row by row in row order either way, so results never depend on the split.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "base/thread_pool.hpp"
#include "render/pipeline.hpp"

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
  static constexpr bool kWorkerScratch = true;     // evaluate() runs in per-thread arrays (run_in_scratch)

  /// RenderOptions::threads (0 = all). DIFFDOPE_STAGE_PROFILE=1 in the environment: time every stage and print
  /// a table to stderr when the renderer goes away (for profiling; ~20 ns per stage and hypothesis).
  /// DIFFDOPE_EVERY_PIXEL=1: pixel stages walk every pixel of the regions, also far from the covered ones (the
  /// same results, slower: a reference for tests).
  explicit HostExec(int threads)
      : pool_(threads),
        profile_(std::getenv("DIFFDOPE_STAGE_PROFILE") != nullptr),
        every_pixel_(std::getenv("DIFFDOPE_EVERY_PIXEL") != nullptr) {}
  ~HostExec() {
    if (!profile_) return;
    double total = 0;
    for (const StageTime& t : times_) total += 1e-6 * t.ns.load();
    std::fprintf(stderr, "diffdope stage profile (CPU time, all threads; SIMD rows on %s): %.1f ms in all\n",
                 simd_row_target(), total);
    for (const StageTime& t : times_)
      if (t.name.load())
        std::fprintf(stderr, "  %-14s %10.1f ms %5.1f %%  %12lld hypothesis-runs\n", t.name.load(), 1e-6 * t.ns.load(),
                     total > 0 ? 100.0 * 1e-6 * t.ns.load() / total : 0.0, static_cast<long long>(t.runs.load()));
    if (hypotheses_ > 0)
      std::fprintf(stderr, "  per evaluated hypothesis: %.0f region pixels, %.0f triangles (level of detail)\n",
                   double(region_pixels_) / double(hypotheses_), double(triangles_) / double(hypotheses_));
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
    pool_.parallel_for(B, [&](int h, int) {
      int k = 0;
      (timed(steps, h, h, k++), ...);
    });
  }
  /// As run(), each hypothesis in its thread's own arrays: the steps see it as hypothesis 0 of a pipeline whose
  /// per-hypothesis arrays are the thread's scratch; sums still land in the real hypothesis' outputs. The steps
  /// of one call share one Pipeline (pipeline.hpp builds them all from it).
  template <class First, class... Steps>
  void run_in_scratch(int B, const First& first, const Steps&... steps) {
    while (scratch_.size() < size_t(pool_.size())) scratch_.push_back(std::make_unique<Scratch>());
    if (B < pool_.size()) {  // fewer hypotheses than threads: one at a time, each stage over all threads
      for (int h = 0; h < B; ++h) {
        Scratch& scratch = *scratch_[0];
        const pipeline::Pipeline local = start(scratch, first.stage.p, h);
        NearCoverage* near = every_pixel_ ? nullptr : &scratch.rows;
        int k = 0;
        split(with_pipeline(first, local), h, k++, near, scratch);
        (split(with_pipeline(steps, local), h, k++, near, scratch), ...);
      }
      return;
    }
    pool_.parallel_for(B, [&](int h, int worker) {
      Scratch& scratch = *scratch_[size_t(worker)];
      const pipeline::Pipeline local = start(scratch, first.stage.p, h);
      NearCoverage* near = every_pixel_ ? nullptr : &scratch.rows;
      int k = 0;
      timed(with_pipeline(first, local), 0, h, k++, near);
      (timed(with_pipeline(steps, local), 0, h, k++, near), ...);
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
  /// Per row of a region, the pixels with a covered pixel within one pixel of them: [lo[y], hi[y]] (none when
  /// lo > hi), a superset of where pixel stages with an Outside policy have work. From the z-buffer after the
  /// raster (valid); one pass over the region's keys.
  struct NearCoverage {
    std::vector<int> lo, hi, row_lo, row_hi;
    bool valid = false;

    void compute(const pipeline::Pipeline& p, int h) {
      const pipeline::Hypothesis& hy = p.H[h];
      const int w = hy.w, rows = hy.h;
      row_lo.assign(size_t(rows), w);
      row_hi.assign(size_t(rows), -1);
      for (int y = 0; y < rows; ++y) {
        const unsigned long long* key = p.key + hy.offset + size_t(y) * size_t(w);
        int x = 0;
        while (x < w && key[x] == pipeline::kEmptyKey) ++x;
        if (x == w) continue;
        int last = w - 1;
        while (key[last] == pipeline::kEmptyKey) --last;
        row_lo[size_t(y)] = x, row_hi[size_t(y)] = last;
      }
      lo.assign(size_t(rows), w);
      hi.assign(size_t(rows), -1);
      for (int y = 0; y < rows; ++y) {
        int l = w, r = -1;
        for (int dy = -1; dy <= 1; ++dy)
          if (y + dy >= 0 && y + dy < rows) l = std::min(l, row_lo[size_t(y + dy)]), r = std::max(r, row_hi[size_t(y + dy)]);
        if (l > r) continue;
        lo[size_t(y)] = std::max(0, l - 1), hi[size_t(y)] = std::min(w - 1, r + 1);
      }
      valid = true;
    }
  };

  /// One worker's per-hypothesis arrays, grown to the largest hypothesis it has run.
  struct Scratch {
    pipeline::Hypothesis hy;  // the hypothesis being run, its offsets zero
    pipeline::WorkArrays<HostBuffer> arrays;
    NearCoverage rows;
    std::vector<double> row_sums;  // a reducing stage's per-row sums, when its rows are split over the threads

    /// `p` for hypothesis h of it, as hypothesis 0 of a pipeline whose per-hypothesis arrays are these.
    pipeline::Pipeline bind(const pipeline::Pipeline& p, int h) {
      hy = p.H[h];
      hy.offset = hy.vertex_offset = hy.triangle_offset = 0;
      const pipeline::ObjectParams& o = p.objects[hy.object];
      pipeline::Pipeline out = p;
      out.H = &hy;
      arrays.bind(out, size_t(o.nv), size_t(o.nt), size_t(hy.w) * size_t(hy.h));
      return out;
    }
  };
  template <class Step>
  static Step with_pipeline(const Step& step, const pipeline::Pipeline& p) {
    Step out = step;
    out.stage.p = p;
    return out;
  }

  /// A kFill stage's writes for the pixels of a region's row (from `row`, w of them) outside [lo, hi].
  template <class Stage>
  static void fill_outside(const Stage& stage, int row, int w, int lo, int hi, int h) {
    if constexpr (pipeline::outside_of<Stage>::known) {
      if constexpr (Stage::kOutside == pipeline::Outside::kFill) {
        if (lo > hi) return stage.fill_outside(row, w, h);
        stage.fill_outside(row, lo, h);
        stage.fill_outside(row + hi + 1, w - 1 - hi, h);
      }
    }
  }

  /// Where part `part` of `parts` equal slices of [0, n) begins (part `parts` begins at n).
  static int slice_begin(int n, int part, int parts) { return int(int64_t(n) * part / parts); }

  /// How many pixels of span [lo, hi] of row ly a stage by rows did at once (0 for the others); `sums`: a
  /// reducing stage's row sums.
  template <class Stage, class... Sums>
  static int first_by_rows(const Stage& stage, int ly, int lo, int hi, int h, Sums... sums) {
    if constexpr (pipeline::has_rows<Stage>::value) return lo <= hi ? stage.row(ly, lo, hi, h, sums...) : 0;
    return 0;
  }

  /// Whether a step may be split over threads (all but the raster, whose z-buffer minimum needs one thread).
  template <class Stage>
  static constexpr bool splits(const pipeline::Each<Stage>&) {
    return !std::is_same<Stage, pipeline::RasterStage>::value;
  }
  template <class Stage>
  static constexpr bool splits(const pipeline::Sum<Stage>&) {
    return true;
  }

  /// Runs part `part` of `parts` of step s for hypothesis h of its pipeline (its elements, or for pixel stages
  /// its rows); sums go to hypothesis h_out's outputs. Stages over the pixels of a region (kPixels) are walked
  /// row by row: no division per pixel; where `near` is valid, those with an Outside policy only near the
  /// covered pixels. The raster's step computes `near` (when given).
  /// flatten: the stage and every kernel it calls are inlined into the loop, so what is invariant over the
  /// elements (the pipeline's pointers, the hypothesis, the mesh view) is loaded once, not once per triangle or
  /// pixel (measured: 7-11 % less time on the scan-like benchmark and dev set).
  template <class Stage>
  __attribute__((flatten)) static void step(const pipeline::Each<Stage>& s, int h, int, NearCoverage* near,
                                            int part = 0, int parts = 1, double* = nullptr) {
    const int n = std::min(s.n, s.stage.count(h));
    if (n <= 0) return;
    if constexpr (pipeline::is_pixel_stage<Stage>::value) {
      const int w = s.stage.p.H[h].w, rows = n / w;
      const int y0 = slice_begin(rows, part, parts), y1 = slice_begin(rows, part + 1, parts);
      if constexpr (pipeline::outside_of<Stage>::known) {
        if (near && near->valid) {
          for (int ly = y0; ly < y1; ++ly) {
            const int row = ly * w, lo = near->lo[size_t(ly)], hi = near->hi[size_t(ly)];
            fill_outside(s.stage, row, w, lo, hi, h);
            for (int lx = lo + first_by_rows(s.stage, ly, lo, hi, h); lx <= hi; ++lx) s.stage.pixel(lx, ly, row + lx, h);
          }
          return;
        }
      }
      for (int ly = y0; ly < y1; ++ly)
        for (int lx = first_by_rows(s.stage, ly, 0, w - 1, h); lx < w; ++lx) s.stage.pixel(lx, ly, ly * w + lx, h);
    } else {
      const int first = slice_begin(n, part, parts), end = slice_begin(n, part + 1, parts);
      if constexpr (pipeline::has_batches<Stage>::value) s.stage.batch(first, end, h);
      else for (int i = first; i < end; ++i) s.stage(i, h);
      if constexpr (std::is_same<Stage, pipeline::RasterStage>::value)
        if (near) near->compute(s.stage.p, h);
    }
  }
  /// A reducing step: each row's sum, then the rows' in row order (into `row_sums` when given: the caller adds
  /// them up in that order once every part is done; else here).
  template <class Stage>
  __attribute__((flatten)) static void step(const pipeline::Sum<Stage>& s, int h, int h_out, NearCoverage* near,
                                            int part = 0, int parts = 1, double* row_sums = nullptr) {
    static_assert(pipeline::is_pixel_stage<Stage>::value, "reducing stages run over the pixels of the regions");
    constexpr int K = Stage::kValues;
    const int n = std::min(s.n, s.stage.count(h));
    if (n <= 0) return;
    double sum[K] = {};
    const int w = s.stage.p.H[h].w, rows = n / w;
    // Skipped pixels add exact zeros: the sums are the same.
    bool skip = false;
    if constexpr (pipeline::outside_of<Stage>::known) skip = near && near->valid;
    for (int ly = slice_begin(rows, part, parts), y1 = slice_begin(rows, part + 1, parts); ly < y1; ++ly) {
      const int lo = skip ? near->lo[size_t(ly)] : 0, hi = skip ? near->hi[size_t(ly)] : w - 1;
      if (skip) fill_outside(s.stage, ly * w, w, lo, hi, h);
      double row[K] = {};
      for (int lx = lo + first_by_rows(s.stage, ly, lo, hi, h, row); lx <= hi; ++lx) {
        double v[K] = {};
        s.stage.pixel(lx, ly, ly * w + lx, h, v);
        for (int k = 0; k < K; ++k) row[k] += v[k];
      }
      for (int k = 0; k < K; ++k) {
        if (row_sums) row_sums[size_t(ly) * K + k] = row[k];
        else sum[k] += row[k];
      }
    }
    if (!row_sums)
      for (int k = 0; k < K; ++k) s.out[size_t(s.stride) * h_out + k] += sum[k];
  }

  /// Step s of hypothesis h (bound to `scratch` as its hypothesis 0) split over all threads, sums added in row
  /// order as step() adds them on one thread.
  template <class Step>
  void split(const Step& s, int h, int k, NearCoverage* near, Scratch& scratch) {
    const int parts = splits(s) ? pool_.size() : 1;
    std::atomic<long long> cpu_ns{0};
    const auto run_part = [&](int part, double* row_sums) {
      const auto t0 = profile_ ? std::chrono::steady_clock::now() : std::chrono::steady_clock::time_point();
      step(s, 0, h, near, part, parts, row_sums);
      if (profile_)
        cpu_ns += std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count();
    };
    using Stage = std::decay_t<decltype(s.stage)>;
    if constexpr (std::is_same<Step, pipeline::Sum<Stage>>::value) {
      constexpr int K = Stage::kValues;
      const int n = std::min(s.n, s.stage.count(0));
      const int rows = n > 0 ? n / s.stage.p.H[0].w : 0;
      scratch.row_sums.assign(size_t(rows) * K, 0.0);
      pool_.parallel_for(parts, [&](int part, int) { run_part(part, scratch.row_sums.data()); });
      double sum[K] = {};
      for (int ly = 0; ly < rows; ++ly)
        for (int j = 0; j < K; ++j) sum[j] += scratch.row_sums[size_t(ly) * K + j];
      if (rows > 0)
        for (int j = 0; j < K; ++j) s.out[size_t(s.stride) * h + j] += sum[j];
    } else {
      pool_.parallel_for(parts, [&](int part, int) { run_part(part, nullptr); });
    }
    if (profile_) add_time(s, k, std::chrono::nanoseconds(cpu_ns.load()));
  }

  template <class Step>
  void timed(const Step& s, int h, int h_out, int k, NearCoverage* near = nullptr) {
    if (!profile_) return step(s, h, h_out, near);
    const auto t0 = std::chrono::steady_clock::now();
    step(s, h, h_out, near);
    add_time(s, k, std::chrono::steady_clock::now() - t0);
  }
  template <class Step>
  void add_time(const Step& s, int k, std::chrono::steady_clock::duration took) {
    StageTime& t = times_[size_t(k) % kMaxSteps];
    t.name = decltype(s.stage)::kName;
    t.ns += std::chrono::duration_cast<std::chrono::nanoseconds>(took).count();
    ++t.runs;
  }
  /// Hypothesis h of p bound to `scratch` (its coverage spans not yet known), counted for the profile.
  pipeline::Pipeline start(Scratch& scratch, const pipeline::Pipeline& p, int h) {
    const pipeline::Pipeline local = scratch.bind(p, h);
    scratch.rows.valid = false;
    if (profile_) {
      region_pixels_ += int64_t(local.H->w) * local.H->h;
      triangles_ += local.objects[local.H->object].nt;
      ++hypotheses_;
    }
    return local;
  }
  struct StageTime {
    std::atomic<const char*> name{nullptr};
    std::atomic<long long> ns{0}, runs{0};
  };

  ThreadPool pool_;
  const bool profile_, every_pixel_;
  static constexpr size_t kMaxSteps = 16;
  StageTime times_[kMaxSteps];
  std::atomic<long long> region_pixels_{0}, triangles_{0}, hypotheses_{0};
  std::vector<std::unique_ptr<Scratch>> scratch_;  // per worker of pool_
  std::vector<cv::Mat> images_;
  std::vector<double> results_;
};

}  // namespace

std::unique_ptr<Renderer> make_cpu_renderer(const RenderOptions& options) {
  return std::make_unique<pipeline::PipelineRenderer<HostExec>>(options, options.threads);
}

}  // namespace diffdope
