// Renderer benchmark, B = 32 hypotheses per call near a true pose, loss only (Forward) or loss + gradient:
//   BM_ScanLike*  a scan-like bottle (make_scan_like: ~15k triangles, UV atlas, 2048^2 texture) covering ~10k
//                 pixels: what users' meshes look like, drawn at the level of detail the renderer chooses;
//   BM_Forward*   a 14.4k-triangle UV sphere covering ~10k pixels (kept for comparison with earlier figures);
//   BM_Cuda*      the same on a CUDA device (skipped with the reason when there is none), at 320, 640, 960x540.
// Prints time per call and per hypothesis.   build-core/bin/bench_renderer [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <random>

#include "diffdope/device.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/renderer.hpp"

using namespace diffdope;

namespace {

struct Scene {
  Camera cam;
  Mesh mesh;
  Observation obs;
  std::vector<Pose> poses;
};

enum MeshKind { kSphere = 0, kBox = 1, kScanLike = 2 };

/// kSphere: the 14.4k-triangle sphere; kBox: a 12-triangle box (few big triangles: the raster's worst case);
/// kScanLike: a scan-like bottle of 15k triangles.
Scene make_scene(int width, int batch, int mesh = kSphere) {
  Scene s;
  const double f = 300.0 * width / 320.0;
  const int height = width == 960 ? 540 : width * 3 / 4;
  s.cam = Camera(f, f, width / 2.0 - 0.5, height / 2.0 - 0.5, width, height);
  s.mesh = mesh == kSphere ? make_uv_sphere(0.05, 60, 120, make_label_texture(512, 7))  // 14,400 triangles
           : mesh == kBox  ? make_box(Eigen::Vector3d(0.08, 0.08, 0.08), make_label_texture(512, 7))
                           : make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.19));
  Vector6d d0;
  d0 << 0.0, 0.0, 0.0, 0.3, 0.2, 0.1;
  auto r = make_cpu_renderer();
  // Distance chosen so the object covers ~10,000 pixels: for the sphere pi * (f r / z)^2 = 1e4; otherwise from
  // the area seen at 0.5 m (area ~ 1 / z^2).
  double z = f * 0.05 / std::sqrt(1e4 / M_PI);
  if (mesh == kScanLike) {
    const double area = cv::sum(r->render(s.cam, s.mesh, {Pose(se3_exp(d0).R, Eigen::Vector3d(0, 0, 0.5))})[0].coverage)[0];
    z = 0.5 * std::sqrt(area / 1e4);
  }
  const Pose truth = Pose(se3_exp(d0).R, Eigen::Vector3d(0.0, 0.0, z));
  const RenderImage img = r->render(s.cam, s.mesh, {truth})[0];
  s.obs.rgb = img.color;
  s.obs.depth = img.depth;
  s.obs.mask = cv::Mat(img.coverage >= 0.5f) / 255;
  s.obs.mask.convertTo(s.obs.mask, CV_32F);
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < batch; ++i) {
    Vector6d d;
    d << 0.003 * n(rng), 0.003 * n(rng), 0.003 * n(rng), 0.03 * n(rng), 0.03 * n(rng), 0.03 * n(rng);
    s.poses.push_back(truth.updated(d));
  }
  return s;
}

void run(benchmark::State& state, bool gradient, bool cull, bool cuda = false, int mesh = 0) {
  if (cuda && !cuda_device_info().available) {
    state.SkipWithError(("no CUDA device: " + cuda_device_info().reason).c_str());
    return;
  }
  const int width = static_cast<int>(state.range(0));
  const Scene s = make_scene(width, 32, mesh);
  RenderOptions ro;
  ro.cull_back_faces = cull;
  auto r = cuda ? make_cuda_renderer(ro) : make_cpu_renderer(ro);
  std::vector<LossValue> out;
  for (auto _ : state) {
    r->evaluate(s.cam, s.mesh, s.obs, s.poses, LossOptions(), gradient, out);
    benchmark::DoNotOptimize(out.data());
  }
  const double covered = cv::sum(s.obs.mask)[0];
  state.counters["pixels"] = covered;
  state.counters["triangles"] = s.mesh.num_triangles();
  state.counters["lod"] = r->render(s.cam, s.mesh, {s.poses[0]})[0].lod;  // level of detail drawn
  // Seconds per hypothesis (printed with an SI prefix: "2.1m" = 2.1 ms).
  state.counters["s_per_hyp"] =
      benchmark::Counter(32.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_ScanLikeLoss(benchmark::State& st) { run(st, false, false, false, kScanLike); }
void BM_ScanLikeLossGradient(benchmark::State& st) { run(st, true, false, false, kScanLike); }
void BM_Forward(benchmark::State& st) { run(st, false, false); }
void BM_ForwardGradient(benchmark::State& st) { run(st, true, false); }
void BM_ForwardGradientCulled(benchmark::State& st) { run(st, true, true); }
void BM_CudaForward(benchmark::State& st) { run(st, false, false, true); }
void BM_CudaForwardGradient(benchmark::State& st) { run(st, true, false, true); }
void BM_CudaForwardGradientBox(benchmark::State& st) { run(st, true, false, true, kBox); }
void BM_CudaScanLikeLossGradient(benchmark::State& st) { run(st, true, false, true, kScanLike); }

/// Three objects of a frame, B = 32 each, in one evaluate_objects() call (the refiner's lockstep refine_all).
void BM_CudaThreeObjects(benchmark::State& state) {
  if (!cuda_device_info().available) {
    state.SkipWithError(("no CUDA device: " + cuda_device_info().reason).c_str());
    return;
  }
  const Scene s = make_scene(static_cast<int>(state.range(0)), 32);
  auto r = make_cuda_renderer();
  std::vector<ObjectBatch> objects(3);
  for (ObjectBatch& b : objects) b.mesh = &s.mesh, b.mask = s.obs.mask, b.poses = s.poses;
  std::vector<std::vector<LossValue>> out;
  for (auto _ : state) {
    r->evaluate_objects(s.cam, s.obs, objects, true, out);
    benchmark::DoNotOptimize(out.data());
  }
}

}  // namespace

BENCHMARK(BM_ScanLikeLoss)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ScanLikeLossGradient)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Forward)->Arg(320)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ForwardGradient)->Arg(320)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ForwardGradientCulled)->Arg(320)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CudaForward)->Arg(320)->Arg(640)->Arg(960)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CudaForwardGradient)->Arg(320)->Arg(640)->Arg(960)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CudaScanLikeLossGradient)->Arg(640)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CudaForwardGradientBox)->Arg(960)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_CudaThreeObjects)->Arg(960)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
