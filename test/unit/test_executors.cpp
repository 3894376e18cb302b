// The render pipeline's executors. Every TEST_P runs on the CPU executor (here and in CI) and on a CUDA device
// (SKIPPED with the reason without one), against a reference: the CPU executor on the full frame (no region of
// interest) with one thread and a fresh renderer (no cached uploads or loss constants). So each comparison checks
// the regions of interest, the packing, thread independence and the caches on the CPU, and the device on a GPU.
#include <gtest/gtest.h>

#include "diffdope/device.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "test_scenes.hpp"

using namespace diffdope;
using namespace diffdope::test;

namespace {

/// Parameter: "cpu" or "cuda".
class Executor : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "cuda") {
      const CudaDeviceInfo info = cuda_device_info();
      if (!info.available) GTEST_SKIP() << "no CUDA device: " << info.reason;
    }
  }
  std::unique_ptr<Renderer> make(const RenderOptions& o = {}) const {
    return GetParam() == "cuda" ? make_cuda_renderer(o) : make_cpu_renderer(o);
  }
};

/// A CPU renderer whose pixel stages walk every pixel of the regions (DIFFDOPE_EVERY_PIXEL, read when it is
/// made), not only those near the covered ones.
std::unique_ptr<Renderer> make_cpu_every_pixel(const RenderOptions& o) {
  setenv("DIFFDOPE_EVERY_PIXEL", "1", 1);
  std::unique_ptr<Renderer> r = make_cpu_renderer(o);
  unsetenv("DIFFDOPE_EVERY_PIXEL");
  return r;
}

/// Every loss term and gradient component of a and b equal, bit for bit.
void expect_same_bits(const LossValue& a, const LossValue& b) {
  EXPECT_EQ(a.total, b.total);
  EXPECT_EQ(a.rgb, b.rgb);
  EXPECT_EQ(a.depth, b.depth);
  EXPECT_EQ(a.mask, b.mask);
  EXPECT_EQ(a.edges, b.edges);
  EXPECT_EQ(a.texture, b.texture);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(a.gradient[k], b.gradient[k]) << "component " << k;
}

/// The reference: full frame, one thread, every pixel walked.
std::unique_ptr<Renderer> make_reference() {
  RenderOptions o;
  o.use_roi = false;
  o.threads = 1;
  return make_cpu_every_pixel(o);
}

struct Case {
  const char* name;
  Mesh mesh;
  Pose truth, test;
};

std::vector<Case> cases() {
  std::vector<Case> c;
  c.push_back({"box", make_box(Eigen::Vector3d(0.10, 0.06, 0.14), make_label_texture(256, 3)),
               look_pose(0.4, -0.5, 0.2, 0.01, -0.005, 0.5), look_pose(0.43, -0.47, 0.22, 0.013, -0.002, 0.505)});
  c.push_back({"lblock", make_l_block(0.12, make_label_texture(256, 5)), look_pose(0.9, 0.3, -0.4, 0.0, 0.01, 0.55),
               look_pose(0.87, 0.34, -0.42, 0.004, 0.012, 0.545)});
  c.push_back({"sphere", make_uv_sphere(0.06, 48, 24, make_pattern_texture(256, 7)),
               look_pose(0.2, 0.1, 0.3, -0.01, 0.0, 0.45), look_pose(0.25, 0.12, 0.28, -0.006, 0.004, 0.46)});
  return c;
}

double max_abs_diff(const cv::Mat& a, const cv::Mat& b) { return cv::norm(a, b, cv::NORM_INF); }

}  // namespace

TEST(DeviceSelection, AutoFallsBackCudaFailsClearly) {
  const CudaDeviceInfo info = cuda_device_info();
  std::string note;
  auto r = make_renderer("auto", {}, &note);
  if (info.available) {
    EXPECT_EQ(r->name(), "cuda");
  } else {
    EXPECT_EQ(r->name(), "cpu");
    EXPECT_NE(note.find("using the CPU backend"), std::string::npos) << note;
    EXPECT_NE(note.find(info.reason), std::string::npos) << note;
    try {
      make_renderer("cuda");
      ADD_FAILURE() << "device cuda without a device must throw";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("unavailable"), std::string::npos) << e.what();
    }
    RefinerOptions o;
    o.device = "cuda";
    EXPECT_THROW(Refiner{o}, std::runtime_error);
    o.device = "auto";
    EXPECT_EQ(Refiner(o).backend(), "cpu");
  }
  EXPECT_EQ(make_renderer("cpu")->name(), "cpu");
  EXPECT_THROW(make_renderer("gpu"), std::invalid_argument);
  RefinerOptions bad;
  bad.device = "gpu";
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// The CPU executor skips the pixels far from the covered ones in the stages that have nothing to do there
// (render_stages.hpp, Outside): losses and gradients are bit for bit those of walking every pixel, with every
// loss term, with and without a mask, on small triangles (the scan-like mesh: most pairs of neighbouring pixels
// lie on different triangles) and big ones.
TEST(CpuExecutor, SkippingEmptyPixelsChangesNoBit) {
  const Camera cam = test_camera();
  std::vector<Case> cs = cases();
  cs.push_back({"scan-like", make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.19), 15000, 512),
                look_pose(0.9, 0.5, 0.6, 0.0, 0.0, 0.5), look_pose(0.93, 0.47, 0.63, 0.004, -0.003, 0.505)});
  auto skipping = make_cpu_renderer();
  auto every = make_cpu_every_pixel(RenderOptions());
  for (const Case& c : cs) {
    Observation obs = observe(*every, cam, c.mesh, c.truth);
    obs.edges = observed_edges(obs.rgb);
    obs.texture = observed_texture(obs.rgb, 0.03);
    LossOptions all_terms;
    all_terms.weight_edges = all_terms.weight_texture = 1.0;
    for (bool with_mask : {true, false}) {
      Observation o = obs;
      if (!with_mask) o.mask = cv::Mat();
      const std::vector<Pose> poses = {c.test, c.truth, c.test.updated((Vector6d() << 0.01, 0, 0, 0, 0.1, 0).finished())};
      for (const LossOptions& loss : {LossOptions(), all_terms}) {
        std::vector<LossValue> a, b;
        skipping->evaluate(cam, c.mesh, o, poses, loss, true, a);
        every->evaluate(cam, c.mesh, o, poses, loss, true, b);
        for (size_t h = 0; h < poses.size(); ++h) {
          SCOPED_TRACE(std::string(c.name) + (with_mask ? " mask" : " no mask") + " pose " + std::to_string(h));
          EXPECT_GT(a[h].total, 0.0);
          EXPECT_GT(a[h].gradient.norm(), 0.0);
          expect_same_bits(a[h], b[h]);
        }
      }
    }
  }
}

TEST_P(Executor, RendersLikeTheReference) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  for (const Case& c : cases()) {
    const auto a = cpu->render(cam, c.mesh, {c.truth, c.test});
    const auto b = gpu->render(cam, c.mesh, {c.truth, c.test});
    for (size_t h = 0; h < a.size(); ++h) {
      EXPECT_EQ(cv::countNonZero(a[h].triangle != b[h].triangle), 0) << c.name << ": visible triangles differ";
      EXPECT_LT(max_abs_diff(a[h].coverage, b[h].coverage), 1e-4) << c.name;
      EXPECT_LT(max_abs_diff(a[h].color, b[h].color), 1e-4) << c.name;
      EXPECT_LT(max_abs_diff(a[h].depth, b[h].depth), 1e-5) << c.name;
    }
  }
}

TEST_P(Executor, LossesAndGradientsMatchTheReference) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  for (const Case& c : cases()) {
    const Observation obs = observe(*cpu, cam, c.mesh, c.truth);
    for (bool with_mask : {true, false}) {
      Observation o = obs;
      if (!with_mask) o.mask = cv::Mat();
      std::vector<LossValue> a, b;
      const std::vector<Pose> poses = {c.test, c.truth, c.test.updated((Vector6d() << 0.01, 0, 0, 0, 0.1, 0).finished())};
      cpu->evaluate(cam, c.mesh, o, poses, LossOptions(), true, a);
      gpu->evaluate(cam, c.mesh, o, poses, LossOptions(), true, b);
      for (size_t h = 0; h < poses.size(); ++h) {
        SCOPED_TRACE(std::string(c.name) + (with_mask ? " mask" : " no mask") + " pose " + std::to_string(h));
        EXPECT_NEAR(a[h].total, b[h].total, 1e-5 * std::max(1.0, std::abs(a[h].total)));
        EXPECT_NEAR(a[h].rgb, b[h].rgb, 1e-5);
        EXPECT_NEAR(a[h].depth, b[h].depth, 1e-5);
        EXPECT_NEAR(a[h].mask, b[h].mask, 1e-5);
        const double n = std::max(a[h].gradient.norm(), 1e-9);
        EXPECT_LT((a[h].gradient - b[h].gradient).norm() / n, 1e-3)
            << "cpu " << a[h].gradient.transpose() << "\ncuda " << b[h].gradient.transpose();
      }
    }
  }
}

TEST_P(Executor, GradientMatchesFiniteDifferences) {
  const Camera cam = test_camera();
  auto gpu = make();
  for (const Case& c : cases()) {
    const Observation obs = observe(*gpu, cam, c.mesh, c.truth);
    std::vector<LossValue> v;
    gpu->evaluate(cam, c.mesh, obs, {c.test}, LossOptions(), true, v);
    const Vector6d fd = finite_difference(*gpu, cam, c.mesh, obs, c.test, LossOptions(), 1e-4, 2.5e-4);
    const double cosine = v[0].gradient.dot(fd) / (v[0].gradient.norm() * fd.norm());
    EXPECT_GT(cosine, 0.99) << c.name << "\n analytic " << v[0].gradient.transpose() << "\n finite   " << fd.transpose();
  }
}

TEST_P(Executor, RefinesLikeTheReference) {
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  const Mesh mesh = make_l_block(0.12, make_label_texture(256, 31));
  const Pose truth = look_pose(0.7, -0.4, 0.3, 0.01, -0.01, 0.55);
  auto r = make_cpu_renderer();
  const Observation obs = synthesize_observation(*r, cam, mesh, truth, SyntheticNoise(), 4);
  std::mt19937_64 rng(5);
  const Pose init = perturb_pose(truth, mesh.center(), 10 * M_PI / 180, 0.01, rng);
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 40;
  o.image_scale = 1.0;
  const RefineResult a = Refiner(o, make_reference()).refine(cam, obs, mesh, init);
  Refiner gpu_refiner(o, make(o.render));
  EXPECT_EQ(gpu_refiner.backend(), GetParam());
  const RefineResult b = gpu_refiner.refine(cam, obs, mesh, init);
  EXPECT_LT((a.pose.t - b.pose.t).norm(), 1e-4);
  EXPECT_LT(rotation_angle(a.pose.R, b.pose.R), 0.05 * M_PI / 180);
  EXPECT_NEAR(a.loss.total, b.loss.total, 1e-3 * a.loss.total);
}

TEST_P(Executor, EdgeTermMatchesTheReference) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  LossOptions loss;
  loss.weight_edges = 1.0;
  loss.edge_scale = 4.0;  // as the CPU gradient test of the edge term: a smooth edge map
  for (const Case& c : cases()) {
    Observation obs = observe(*cpu, cam, c.mesh, c.truth);
    obs.edges = observed_edges(obs.rgb);
    std::vector<LossValue> a, b;
    cpu->evaluate(cam, c.mesh, obs, {c.test}, loss, true, a);
    gpu->evaluate(cam, c.mesh, obs, {c.test}, loss, true, b);
    EXPECT_NEAR(a[0].edges, b[0].edges, 1e-5) << c.name;
    EXPECT_NEAR(a[0].total, b[0].total, 1e-5 * std::max(1.0, a[0].total)) << c.name;
    EXPECT_LT((a[0].gradient - b[0].gradient).norm() / std::max(a[0].gradient.norm(), 1e-9), 1e-3) << c.name;
  }
}

// Several objects in one call (each with its own mask, loss options and poses; invalid and empty batches too)
// give what one call per object gives.
TEST_P(Executor, SeveralObjectsInOneCallMatchOneByOne) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  const std::vector<Case> cs = cases();
  Observation frame = observe(*cpu, cam, cs[0].mesh, cs[0].truth);
  frame.edges = observed_edges(frame.rgb);
  std::vector<ObjectBatch> objects(cs.size() + 1);
  for (size_t k = 0; k < cs.size(); ++k) {
    ObjectBatch& b = objects[k];
    b.mesh = &cs[k].mesh;
    if (k != 2) b.mask = observe(*cpu, cam, cs[k].mesh, cs[k].truth).mask;  // the sphere has none
    b.poses = {cs[k].test, cs[k].truth};
    if (k == 0) b.loss.weight_edges = 1.0, b.loss.edge_scale = 4.0;
    if (k == 1) b.loss.weight_depth = 3.0, b.poses.push_back(Pose(Eigen::Matrix3d::Constant(NAN), cs[k].truth.t));
  }
  objects[3].mesh = &cs[1].mesh;  // no poses at all
  std::vector<std::vector<LossValue>> together, reference;
  gpu->evaluate_objects(cam, frame, objects, true, together);
  cpu->evaluate_objects(cam, frame, objects, true, reference);
  ASSERT_EQ(together.size(), objects.size());
  EXPECT_TRUE(together[3].empty());
  EXPECT_TRUE(std::isinf(together[1][2].total));
  for (size_t k = 0; k < cs.size(); ++k) {
    Observation o = frame;
    o.mask = objects[k].mask;
    std::vector<LossValue> alone;
    gpu->evaluate(cam, *objects[k].mesh, o, objects[k].poses, objects[k].loss, true, alone);
    ASSERT_EQ(together[k].size(), alone.size());
    for (size_t h = 0; h < alone.size(); ++h) {
      SCOPED_TRACE(std::string(cs[k].name) + " pose " + std::to_string(h));
      if (!std::isfinite(alone[h].total)) {
        EXPECT_FALSE(std::isfinite(together[k][h].total));
        continue;
      }
      // The same sums in the same order on the CPU; atomics may add them in another order on a device.
      const double tol = GetParam() == "cuda" ? 1e-9 : 0.0;
      EXPECT_NEAR(together[k][h].total, alone[h].total, tol * std::max(1.0, alone[h].total));
      EXPECT_LE((together[k][h].gradient - alone[h].gradient).norm(), 1e-6 * alone[h].gradient.norm());
      EXPECT_NEAR(together[k][h].total, reference[k][h].total, 1e-5 * std::max(1.0, reference[k][h].total));
      EXPECT_NEAR(together[k][h].edges, reference[k][h].edges, 1e-5);
      EXPECT_LT((together[k][h].gradient - reference[k][h].gradient).norm() /
                    std::max(reference[k][h].gradient.norm(), 1e-9), 1e-3);
    }
  }
}

// The CPU executor's evaluate_objects (one parallel loop over every hypothesis of every object) gives exactly what
// evaluate gives per object. On one thread every hypothesis of every object (meshes and regions of different
// sizes) reuses the same scratch arrays: nothing of the one before may leak into it.
TEST(CpuExecutor, SeveralObjectsInOneCallAreEvaluatedAsOneByOne) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  const std::vector<Case> cs = cases();
  Observation frame = observe(*cpu, cam, cs[1].mesh, cs[1].truth);
  std::vector<ObjectBatch> objects(cs.size());
  for (size_t k = 0; k < cs.size(); ++k) {
    objects[k].mesh = &cs[k].mesh;
    if (k != 0) objects[k].mask = observe(*cpu, cam, cs[k].mesh, cs[k].truth).mask;
    objects[k].poses = {cs[k].test, cs[k].truth, cs[k].test.updated((Vector6d() << 0, 0.01, 0, 0.1, 0, 0).finished())};
    objects[k].loss.weight_depth = 1.0 + k;
  }
  std::vector<std::vector<LossValue>> together;
  cpu->evaluate_objects(cam, frame, objects, true, together);
  for (size_t k = 0; k < cs.size(); ++k) {
    Observation o = frame;
    o.mask = objects[k].mask;
    std::vector<LossValue> alone;
    cpu->evaluate(cam, cs[k].mesh, o, objects[k].poses, objects[k].loss, true, alone);
    ASSERT_EQ(alone.size(), together[k].size());
    for (size_t h = 0; h < alone.size(); ++h) {
      EXPECT_EQ(alone[h].total, together[k][h].total) << cs[k].name << " " << h;
      EXPECT_EQ(alone[h].gradient, together[k][h].gradient) << cs[k].name << " " << h;
    }
  }
  objects[1].loss.depth_truncation = 0;  // one bad object: the call refuses before doing anything
  EXPECT_THROW(cpu->evaluate_objects(cam, frame, objects, true, together), std::invalid_argument);
}

// The CPU executor honours RenderOptions::threads, with the same results on 1 and 2 threads.
TEST(CpuExecutor, OneThreadGivesWhatTwoGive) {
  const Camera cam = test_camera();
  const Case c = cases()[2];
  const Observation obs = observe(*make_cpu_renderer(), cam, c.mesh, c.truth);
  RenderOptions one, two;
  one.threads = 1;
  two.threads = 2;
  std::vector<LossValue> a, b;
  const std::vector<Pose> poses = {c.test, c.truth, c.test, c.truth};
  make_cpu_renderer(one)->evaluate(cam, c.mesh, obs, poses, LossOptions(), true, a);
  make_cpu_renderer(two)->evaluate(cam, c.mesh, obs, poses, LossOptions(), true, b);
  for (size_t h = 0; h < poses.size(); ++h) {
    EXPECT_EQ(a[h].total, b[h].total);
    EXPECT_EQ(a[h].gradient, b[h].gradient);
  }
}

// Fewer hypotheses than threads: each one's stages are split over the threads (rows, elements). The results
// are bit for bit those of one thread, with every loss term, with and without a mask, also when the region's
// rows do not divide evenly, and for a call with as many hypotheses as threads (not split).
TEST(CpuExecutor, SplittingAHypothesisOverThreadsChangesNoBit) {
  const Camera cam = test_camera();
  const Case c{"scan-like", make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.19), 15000, 512),
               look_pose(0.9, 0.5, 0.6, 0.0, 0.0, 0.5), look_pose(0.93, 0.47, 0.63, 0.004, -0.003, 0.505)};
  RenderOptions one;
  one.threads = 1;
  auto single = make_cpu_renderer(one);
  Observation obs = observe(*single, cam, c.mesh, c.truth);
  obs.edges = observed_edges(obs.rgb);
  obs.texture = observed_texture(obs.rgb, 0.03);
  LossOptions all_terms;
  all_terms.weight_edges = all_terms.weight_texture = 1.0;
  for (int threads : {2, 3, 4}) {
    RenderOptions o;
    o.threads = threads;
    auto split = make_cpu_renderer(o);
    for (bool with_mask : {true, false}) {
      Observation ob = obs;
      if (!with_mask) ob.mask = cv::Mat();
      for (const std::vector<Pose>& poses : {std::vector<Pose>{c.test}, std::vector<Pose>{c.test, c.truth},
                                             std::vector<Pose>(size_t(threads), c.test)}) {
        std::vector<LossValue> a, b;
        single->evaluate(cam, c.mesh, ob, poses, all_terms, true, a);
        split->evaluate(cam, c.mesh, ob, poses, all_terms, true, b);
        for (size_t h = 0; h < poses.size(); ++h) {
          SCOPED_TRACE(std::to_string(threads) + " threads, " + std::to_string(poses.size()) + " poses" +
                       (with_mask ? ", mask" : ", no mask"));
          EXPECT_GT(a[h].texture, 0.0);
          expect_same_bits(a[h], b[h]);
        }
      }
    }
  }
}

TEST_P(Executor, BadInputIsRefusedClearly) {
  const Camera cam = test_camera();
  auto gpu = make();
  const Case c = cases()[0];
  EXPECT_TRUE(gpu->render(cam, c.mesh, {}).empty());
  Observation obs = observe(*gpu, cam, c.mesh, c.truth);
  std::vector<LossValue> v;
  gpu->evaluate(cam, c.mesh, obs, {Pose(Eigen::Matrix3d::Constant(NAN), c.truth.t), c.truth}, LossOptions(), true, v);
  ASSERT_EQ(v.size(), 2u);
  EXPECT_TRUE(std::isinf(v[0].total));
  std::vector<LossValue> ref;
  make_reference()->evaluate(cam, c.mesh, obs, {c.truth}, LossOptions(), true, ref);
  EXPECT_NEAR(v[1].total, ref[0].total, 1e-5);
  Mesh empty;
  EXPECT_THROW(gpu->evaluate(cam, empty, obs, {c.truth}, LossOptions(), true, v), std::invalid_argument);
  obs.mask = cv::Mat::ones(10, 10, CV_32F);
  EXPECT_THROW(gpu->evaluate(cam, c.mesh, obs, {c.truth}, LossOptions(), true, v), std::invalid_argument);
  EXPECT_THROW(gpu->render(cam, c.mesh, {c.truth}, obs.mask), std::invalid_argument);
}

// Images and loss constants are kept between calls while the inputs stay the same: a change written into the
// same buffers (mask, depth, rgb), other loss options or a dropped mask must all be seen.
TEST_P(Executor, SeesEveryChangeOfItsInputs) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  const Case c = cases()[1];
  Observation obs = observe(*cpu, cam, c.mesh, c.truth);
  const auto check = [&](const Observation& o, const LossOptions& loss, const char* what) {
    std::vector<LossValue> a, b;
    cpu->evaluate(cam, c.mesh, o, {c.test}, loss, true, a);
    gpu->evaluate(cam, c.mesh, o, {c.test}, loss, true, b);
    EXPECT_NEAR(a[0].total, b[0].total, 1e-5 * std::max(1.0, a[0].total)) << what;
    EXPECT_LT((a[0].gradient - b[0].gradient).norm() / std::max(a[0].gradient.norm(), 1e-9), 1e-3) << what;
  };
  LossOptions loss;
  check(obs, loss, "first");
  obs.mask(cv::Rect(0, 0, cam.width / 2, cam.height)).setTo(0.0);  // in place: same buffer, other content
  check(obs, loss, "mask changed in place");
  obs.depth(cv::Rect(0, 0, cam.width, cam.height / 2)).setTo(0.0);
  check(obs, loss, "depth changed in place");
  obs.rgb *= 0.5;
  check(obs, loss, "rgb changed in place");
  loss.weight_depth = 4.0;
  check(obs, loss, "other weights");
  Observation no_mask = obs;
  no_mask.mask = cv::Mat();
  check(no_mask, loss, "mask dropped");
  check(obs, loss, "mask back");
}

// A mesh whose texture changed in place (same address, same vertices) is uploaded again once re-finalized.
TEST_P(Executor, ReFinalizedMeshIsUploadedAgain) {
  const Camera cam = test_camera();
  auto cpu = make_reference();
  auto gpu = make();
  Case c = cases()[0];
  const Observation obs = observe(*cpu, cam, c.mesh, c.truth);
  std::vector<LossValue> before, after, ref;
  gpu->evaluate(cam, c.mesh, obs, {c.truth}, LossOptions(), true, before);
  for (float& v : c.mesh.textures[0].rgb) v = 1.f - v;  // the same mesh object, another texture
  c.mesh.finalize();
  gpu->evaluate(cam, c.mesh, obs, {c.truth}, LossOptions(), true, after);
  cpu->evaluate(cam, c.mesh, obs, {c.truth}, LossOptions(), true, ref);
  EXPECT_GT(after[0].rgb, before[0].rgb + 0.05);
  EXPECT_NEAR(after[0].total, ref[0].total, 1e-5);
}

// More meshes than the upload cache keeps (64): the least recently used are dropped and uploaded again when
// they come back, with the same results; a call with many objects keeps all of its own.
TEST_P(Executor, ManyMeshesComeAndGo) {
  const Camera cam(200, 200, 39.5, 29.5, 80, 60);
  auto gpu = make();
  auto cpu = make_reference();
  std::vector<Mesh> meshes;
  for (int k = 0; k < 70; ++k) meshes.push_back(make_box(Eigen::Vector3d(0.05 + 0.001 * k, 0.04, 0.06), make_pattern_texture(16, k)));
  const Pose pose = look_pose(0.3, 0.2, 0.1, 0.0, 0.0, 0.5);
  const Observation obs = observe(*cpu, cam, meshes[0], pose);
  std::vector<ObjectBatch> all(meshes.size());
  for (size_t k = 0; k < meshes.size(); ++k) all[k].mesh = &meshes[k], all[k].mask = obs.mask, all[k].poses = {pose};
  std::vector<LossValue> one;
  std::vector<double> alone(meshes.size());
  for (size_t k = 0; k < meshes.size(); ++k) {  // one call each: the first ones are dropped after 64
    gpu->evaluate(cam, meshes[k], obs, {pose}, LossOptions(), true, one);
    alone[k] = one[0].total;
  }
  std::vector<std::vector<LossValue>> together;
  gpu->evaluate_objects(cam, obs, all, true, together);  // re-uploads the dropped ones, keeps all 70
  for (size_t k = 0; k < meshes.size(); k += 3) {
    std::vector<LossValue> ref;
    cpu->evaluate(cam, meshes[k], obs, {pose}, LossOptions(), true, ref);
    gpu->evaluate(cam, meshes[k], obs, {pose}, LossOptions(), true, one);
    EXPECT_NEAR(alone[k], ref[0].total, 1e-5) << k;
    // Bit for bit on the CPU; device atomics add in no fixed order.
    const double tol = GetParam() == "cuda" ? 1e-9 * std::max(1.0, alone[k]) : 0.0;
    EXPECT_NEAR(together[k][0].total, alone[k], tol) << k;
    EXPECT_NEAR(one[0].total, alone[k], tol) << k;
  }
}

INSTANTIATE_TEST_SUITE_P(Executors, Executor, ::testing::Values("cpu", "cuda"),
                         [](const ::testing::TestParamInfo<std::string>& i) {
                           return i.param == "cuda" ? std::string("Cuda") : std::string("Cpu");
                         });
