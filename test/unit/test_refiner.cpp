// The refiner on synthetic scenes (rendered by our renderer, with colour/depth noise, holes, a textured
// background and a brightness mismatch), its options, and its input checks.
#include <gtest/gtest.h>

#include <cstring>
#include <map>

#include "diffdope/device.hpp"
#include "diffdope/metrics.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/print_alignment.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "test_scenes.hpp"

using namespace diffdope;

namespace {

struct Scene {
  Camera cam{420, 420, 159.5, 119.5, 320, 240};
  Mesh mesh = make_l_block(0.12, make_label_texture(256, 31));
  Pose truth;
  Observation obs;
};

Scene make_scene(uint32_t seed) {
  Scene s;
  Vector6d d;
  d << 0, 0, 0, 0.7, -0.4, 0.3;
  s.truth = Pose(se3_exp(d).R, Eigen::Vector3d(0.01, -0.01, 0.55));
  auto r = make_cpu_renderer();
  SyntheticNoise noise;
  noise.brightness = 0.9;
  s.obs = synthesize_observation(*r, s.cam, s.mesh, s.truth, noise, seed);
  return s;
}

RefinerOptions test_options() {
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 60;
  o.image_scale = 1.0;  // the test images are already small
  return o;
}

double add_mm(const Scene& s, const Pose& p) { return 1e3 * add_error(metric_points(s.mesh), p, s.truth); }

}  // namespace

TEST(Refiner, RecoversHardPerturbation) {
  const Scene s = make_scene(1);
  std::mt19937_64 rng(7);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 40 * M_PI / 180, 0.02, rng);
  Refiner refiner(test_options());
  const RefineResult r = refiner.refine(s.cam, s.obs, s.mesh, init);
  EXPECT_GT(add_mm(s, init), 30.0);
  EXPECT_LT(add_mm(s, r.pose), 5.0);
  EXPECT_TRUE(r.plausible);
  EXPECT_GT(r.mask_iou, 0.9);
  EXPECT_GT(r.depth_inliers, 0.8);
  EXPECT_LT(r.loss.total, r.initial_loss);
  EXPECT_EQ(r.run_losses.size(), 16u);
  EXPECT_EQ(r.history.size(), 61u);
  EXPECT_EQ(r.iterations, 60);
  // The winner's loss, or lower: the polish goes on from it.
  EXPECT_LE(r.loss.total, *std::min_element(r.run_losses.begin(), r.run_losses.end()));
  EXPECT_GT(r.polish_iterations, 0);
  EXPECT_LE(r.polish_iterations, 30);
}

// Coarse to fine (the default) recovers what a single scale recovers; the reported losses are at the fine scale
// (initial loss = the fine evaluation of the start; the winner's loss = the fine evaluation of its pose) and an
// early stop in the coarse phase moves on to the fine one instead of ending the run there.
TEST(Refiner, CoarseToFineEndsAtTheFineScale) {
  const Scene s = make_scene(4);
  std::mt19937_64 rng(9);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 20 * M_PI / 180, 0.015, rng);
  RefinerOptions one = test_options(), c2f = test_options();
  one.coarse_fraction = 0;
  c2f.coarse_fraction = 0.5;  // the halvings at 25 % and 50 % fall in the coarse phase, the one at 75 % in the fine
  ASSERT_GT(c2f.coarse_fraction, 0.0);
  const RefineResult a = Refiner(one).refine(s.cam, s.obs, s.mesh, init);
  const RefineResult b = Refiner(c2f).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_LT(add_mm(s, a.pose), 3.0);
  EXPECT_LT(add_mm(s, b.pose), 3.0);
  EXPECT_EQ(b.history.size(), 61u);
  auto r = make_cpu_renderer();
  std::vector<LossValue> v;
  r->evaluate(s.cam, s.mesh, s.obs, {init, b.pose}, c2f.loss, false, v);
  EXPECT_NEAR(b.initial_loss, v[0].total, 1e-6 * v[0].total);
  EXPECT_NEAR(b.loss.total, v[1].total, 1e-6 * v[1].total);
  EXPECT_NEAR(a.initial_loss, b.initial_loss, 1e-9 * a.initial_loss);
  // Early stop: the coarse phase may stall, the fine phase still runs and its values are reported.
  RefinerOptions stop = c2f;
  stop.iterations = 200;
  stop.early_stop_patience = 3;
  stop.early_stop_tolerance = 0.5;
  const RefineResult c = Refiner(stop).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_LT(c.iterations, 200);
  EXPECT_GE(c.iterations, 2 * stop.early_stop_patience);  // a stall in each phase
  // The stall jumped over 25 % and 50 % of the iterations: both halvings still happened (16 -> 8 -> 4 runs).
  size_t longest = 0;
  for (const auto& h : c.run_histories) longest = std::max(longest, h.size());
  EXPECT_EQ(std::count_if(c.run_histories.begin(), c.run_histories.end(), [&](auto& h) { return h.size() == longest; }), 4);
  r->evaluate(s.cam, s.mesh, s.obs, {c.pose}, c2f.loss, false, v);
  EXPECT_NEAR(c.loss.total, v[0].total, 1e-6 * v[0].total);
}

// Successive halving keeps the better half of the runs at 25 %, 50 % and 75 % of the iterations: 16 runs give
// 8 + 4 + 2 dropped there and 2 that go to the end, the winner among them and each dropped run's best no better
// than the winner's; without it every run goes to the end (the paper's algorithm).
TEST(Refiner, SuccessiveHalvingDropsTheWorseHalfThreeTimes) {
  const Scene s = make_scene(4);
  std::mt19937_64 rng(5);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 10 * M_PI / 180, 0.01, rng);
  RefinerOptions o = test_options();
  o.iterations = 20;
  o.coarse_fraction = 0;
  o.shape_tolerance = 0;  // (the L-block has no shape turns anyway; planned_evaluations would count them)
  o.polish_iterations = 0;  // (run_histories do not hold the polish's nor the Newton steps'; counted below)
  o.newton_rounds = 0;
  o.derive_mask = false;  // (the scene has a mask: nothing is derived; planned_evaluations would count it)
  const RefineResult r = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  std::map<size_t, int> runs_by_length;
  for (const auto& h : r.run_histories) ++runs_by_length[h.size()];
  EXPECT_EQ(runs_by_length, (std::map<size_t, int>{{5, 8}, {10, 4}, {15, 2}, {21, 2}}));
  EXPECT_EQ(r.run_histories[r.winner].size(), 21u);
  for (double loss : r.run_losses) EXPECT_GE(loss, r.loss.total);
  // planned_evaluations() (the service's time estimate) counts what the refinement evaluated, + 2 for scoring
  // and the curvature probe's.
  auto evaluated = [](const RefineResult& res) {
    long n = kCurvatureProbeEvaluations;
    for (const auto& h : res.run_histories) n += long(h.size());
    return n;
  };
  EXPECT_EQ(evaluated(r) + 2, planned_evaluations(o));
  // RefineResult::evaluations (the time estimator's unit of cost): what was made, within what was planned, the
  // same when refine_all() evaluates the runs in its joint calls.
  EXPECT_GE(r.evaluations, evaluated(r));
  EXPECT_LE(r.evaluations, planned_evaluations(o));
  test::expect_within_plan(r, o, "halved");
  EXPECT_EQ(r.stage_evaluations[size_t(RefineStage::kDescent)] + kCurvatureProbeEvaluations, evaluated(r));
  const ObjectTarget target{&s.mesh, init, s.obs.mask, {}, StartKind::kFresh};
  EXPECT_EQ(Refiner(o).refine_all(s.cam, s.obs, {target})[0].evaluations, r.evaluations);
  o.successive_halving = false;
  const RefineResult all = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  for (const auto& h : all.run_histories) EXPECT_EQ(h.size(), 21u);
  EXPECT_EQ(evaluated(all) + 2, planned_evaluations(o));
  o.successive_halving = true;
  o.coarse_fraction = 0.5;
  EXPECT_EQ(evaluated(Refiner(o).refine(s.cam, s.obs, s.mesh, init)) + 2, planned_evaluations(o));
  // With the shape scan at k = 10 of 20: the 4 runs active then, each with itself and up to kMaxShapeTurns
  // turns, and a candidate run to the end (11 iterations); the candidate's and the basin's print
  // registrations; the print alignment's, about one axis, the loss and registration at its turn and the
  // registration at the result; at the result, a registration there and per shape turn, the loss and
  // registration of the one the print prefers, and its print alignment.
  RefinerOptions scan = o;
  scan.shape_tolerance = 0.01;
  const long print = print_alignment_evaluations(scan.print_search) + 3;
  EXPECT_EQ(planned_evaluations(scan),
            planned_evaluations(o) + 4 * (1 + kMaxShapeTurns) + 11 + 2 + print + kMaxShapeTurns + 3 + print);
  // The polish: one evaluation at the result, then its runs at each further iteration (at most: it stops once
  // converged).
  RefinerOptions polished = o;
  polished.polish_iterations = 30;
  EXPECT_EQ(planned_evaluations(polished), planned_evaluations(o) + 1 + polished.polish_runs * 30);
}

// A start behind the camera or outside the image is named by start_problem(); usable_starts() leaves such
// starts out of several, and keeps them all when none is usable (refining them then says why).
TEST(Refiner, UnusableStartsAreNamedAndLeftOutOfSeveral) {
  const Scene s = make_scene(2);
  const RefinerOptions o = test_options();
  Pose behind = s.truth, aside = s.truth;
  behind.t.z() = -0.3;
  aside.t.x() += 5.0;
  EXPECT_EQ(start_problem(s.cam, s.mesh, s.truth, o), "");
  EXPECT_NE(start_problem(s.cam, s.mesh, behind, o).find("behind the camera"), std::string::npos);
  EXPECT_NE(start_problem(s.cam, s.mesh, aside, o).find("outside the image"), std::string::npos);
  EXPECT_EQ(usable_starts(s.cam, s.mesh, {s.truth, behind, aside}, o), (std::vector<size_t>{0}));
  EXPECT_EQ(usable_starts(s.cam, s.mesh, {behind, s.truth}, o), (std::vector<size_t>{1}));
  EXPECT_EQ(usable_starts(s.cam, s.mesh, {behind, aside}, o), (std::vector<size_t>{0, 1}));
  // What refine() says of the same starts.
  const RefineResult r = Refiner(o).refine_all(s.cam, s.obs, {ObjectTarget{&s.mesh, s.truth, s.obs.mask, {behind}}})[0];
  EXPECT_EQ(r.error, start_problem(s.cam, s.mesh, behind, o));
}

TEST(Refiner, SeveralStartsTheBetterOneWins) {
  // A good start (a tracked pose) and a hopeless one (a wrong detection, 90 deg off): whichever order they
  // come in, the winner comes from the good one and RefineResult says so.
  const Scene s = make_scene(2);
  std::mt19937_64 rng(11);
  const Pose good = perturb_pose(s.truth, s.mesh.center(), 3 * M_PI / 180, 0.004, rng);
  const Pose bad = perturb_pose(s.truth, s.mesh.center(), 90 * M_PI / 180, 0.03, rng);
  RefinerOptions o = test_options();
  o.iterations = 30;
  Refiner refiner(o);
  for (int order = 0; order < 2; ++order) {
    const std::vector<Pose> starts = order == 0 ? std::vector<Pose>{good, bad} : std::vector<Pose>{bad, good};
    const RefineResult r = refiner.refine(s.cam, s.obs, s.mesh, starts);
    EXPECT_EQ(r.start, order == 0 ? 0 : 1);
    EXPECT_LT((r.initial_pose.t - good.t).norm(), 1e-12);
    EXPECT_LT(add_mm(s, r.pose), 2.0);
    EXPECT_EQ(r.run_losses.size(), 16u);
  }
  // refine_all passes ObjectTarget::alternatives as further starts.
  ObjectTarget t;
  t.mesh = &s.mesh;
  t.initial = bad;
  t.alternatives = {good};
  t.mask = s.obs.mask;
  Observation frame = s.obs;
  frame.mask = cv::Mat();
  const auto all = refiner.refine_all(s.cam, frame, {t});
  ASSERT_EQ(all.size(), 1u);
  EXPECT_EQ(all[0].start, 1);
  EXPECT_LT(add_mm(s, all[0].pose), 2.0);
}

TEST(Refiner, PreparingAMeshChangesNoResult) {
  // Refiner::prepare() only does ahead what the first refinement would (shape analysis, print axes, the
  // renderer taking in the mesh): the refinements after it are those of a refiner that never prepared.
  const Scene s = make_scene(2);
  std::mt19937_64 rng(5);
  const Pose start = perturb_pose(s.truth, s.mesh.center(), 15 * M_PI / 180, 0.01, rng);
  RefinerOptions o = test_options();
  o.iterations = 20;
  Refiner plain(o), prepared(o);
  prepared.prepare(s.mesh);
  prepared.prepare(s.mesh);  // twice: nothing more happens
  const RefineResult a = plain.refine(s.cam, s.obs, s.mesh, start);
  const RefineResult b = prepared.refine(s.cam, s.obs, s.mesh, start);
  ASSERT_TRUE(a.error.empty()) << a.error;
  EXPECT_EQ(a.loss.total, b.loss.total);
  EXPECT_EQ((a.pose.t - b.pose.t).norm(), 0.0);
  EXPECT_EQ((a.pose.R - b.pose.R).norm(), 0.0);
  EXPECT_LT(add_mm(s, b.pose), add_mm(s, start));
}

TEST(Refiner, EasyStartsDoNotGetWorse) {
  for (uint32_t seed : {2u, 3u}) {
    const Scene s = make_scene(seed);
    std::mt19937_64 rng(seed);
    const Pose init = perturb_pose(s.truth, s.mesh.center(), 1 * M_PI / 180, 0.001, rng);
    Refiner refiner(test_options());
    const RefineResult r = refiner.refine(s.cam, s.obs, s.mesh, init);
    EXPECT_LT(add_mm(s, r.pose), add_mm(s, init));
  }
}

TEST(Refiner, TheResultIsNeverWorseThanTheStartAtTheFineScale) {
  // Started at the loss's own optimum with only large learning rates, coarse to fine: every run's fine-phase
  // best is worse than the start, which is then the result (the start is a pose seen, at k = 0).
  const Scene s = make_scene(6);
  RefinerOptions o = test_options();
  o.iterations = 20;
  o.lr_low = o.lr_high = 0.05;
  o.coarse_fraction = 0.5;
  o.coarse_scale = 0.5;
  Refiner refiner(o);
  const RefineResult once = refiner.refine(s.cam, s.obs, s.mesh, s.truth);
  const RefineResult again = refiner.refine(s.cam, s.obs, s.mesh, once.pose);  // (the start is now at the optimum)
  EXPECT_LE(again.loss.total, again.initial_loss);
  for (double l : again.run_losses) EXPECT_GE(l, again.loss.total);
  if (again.loss.total == again.initial_loss) EXPECT_TRUE(again.pose.matrix().isApprox(once.pose.matrix()));
}

TEST(Refiner, SameSeedSameResultOtherSeedOtherRates) {
  const Scene s = make_scene(4);
  std::mt19937_64 rng(4);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 10 * M_PI / 180, 0.01, rng);
  RefinerOptions o = test_options();
  o.iterations = 20;
  const RefineResult a = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  const RefineResult b = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_EQ(a.pose.matrix(), b.pose.matrix());
  EXPECT_EQ(a.learning_rates, b.learning_rates);
  o.seed = 99;
  const RefineResult c = Refiner(o).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_NE(a.learning_rates, c.learning_rates);
  for (double lr : c.learning_rates) {
    EXPECT_GE(lr, o.lr_low);
    EXPECT_LE(lr, o.lr_high);
  }
}

TEST(Refiner, OptionsPassedPerCallActAsANewRefiner) {
  const Scene s = make_scene(4);
  std::mt19937_64 rng(4);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 10 * M_PI / 180, 0.01, rng);
  RefinerOptions o = test_options();
  o.iterations = 20;
  Refiner running(o);
  running.refine(s.cam, s.obs, s.mesh, init);  // caches the mesh's levels of detail
  RefinerOptions tuned = o;
  tuned.iterations = 7;
  tuned.batch_size = 5;
  tuned.seed = 3;
  tuned.loss.weight_rgb = 0.5;
  const RefineResult a = running.refine(s.cam, s.obs, s.mesh, init, tuned);
  const RefineResult b = Refiner(tuned).refine(s.cam, s.obs, s.mesh, init);
  EXPECT_EQ(a.iterations, 7);
  EXPECT_EQ(a.run_losses.size(), 5u);
  EXPECT_EQ(a.pose.matrix(), b.pose.matrix());
  EXPECT_EQ(a.learning_rates, b.learning_rates);
  // A call without options runs with the Refiner's own, untouched by the call before.
  EXPECT_EQ(running.refine(s.cam, s.obs, s.mesh, init).iterations, 20);
  EXPECT_EQ(running.options().iterations, 20);
  // What builds the renderer cannot change per call, nor can an invalid value pass.
  RefinerOptions other = tuned;
  other.render.lod_pixel_error = 1.0;
  EXPECT_THROW(running.refine(s.cam, s.obs, s.mesh, init, other), std::invalid_argument);
  other = tuned;
  other.device = "cuda";
  EXPECT_THROW(running.refine(s.cam, s.obs, s.mesh, init, other), std::invalid_argument);
  other = tuned;
  other.lr_low = 2 * other.lr_high;
  EXPECT_THROW(running.refine(s.cam, s.obs, s.mesh, init, other), std::invalid_argument);
  EXPECT_THROW(running.refine_all(s.cam, s.obs, {}, other), std::invalid_argument);
}

TEST(Refiner, WorksWithEachModalityMissing) {
  const Scene s = make_scene(5);
  std::mt19937_64 rng(5);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 10 * M_PI / 180, 0.01, rng);
  const double before = add_mm(s, init);
  struct Variant {
    const char* name;
    bool rgb, depth, mask;
  };
  for (const Variant v : {Variant{"rgb only + mask", true, false, true}, Variant{"depth only + mask", false, true, true},
                          Variant{"rgb-d, no mask", true, true, false}, Variant{"depth only, no mask", false, true, false}}) {
    Observation o = s.obs;
    if (!v.rgb) o.rgb.release();
    if (!v.depth) o.depth.release();
    if (!v.mask) o.mask.release();
    const RefineResult r = Refiner(test_options()).refine(s.cam, o, s.mesh, init);
    EXPECT_LT(add_mm(s, r.pose), 0.5 * before) << v.name;
    EXPECT_EQ(r.mask_iou < 0, !v.mask && !v.depth) << v.name;  // without a mask: against the derived pixels
    EXPECT_EQ(r.depth_inliers < 0, !v.depth) << v.name;
  }
}

TEST(Refiner, EarlyStopEndsWhenNothingImproves) {
  const Scene s = make_scene(6);
  RefinerOptions o = test_options();
  o.iterations = 200;
  o.early_stop_patience = 5;
  o.early_stop_tolerance = 0.5;  // demands halving every 5 iterations: stops early
  const RefineResult r = Refiner(o).refine(s.cam, s.obs, s.mesh, s.truth);
  EXPECT_LT(r.iterations, 200);
  EXPECT_EQ(r.history.size(), size_t(r.iterations + 1));
}

// Unusable input is reported in the result (the start returned, not plausible), never thrown.
TEST(Refiner, ReportsUnusableInputInTheResult) {
  const Scene s = make_scene(7);
  Refiner refiner(test_options());
  const auto expect_error = [&](const Observation& obs, const Pose& start, const std::string& says) {
    const RefineResult r = refiner.refine(s.cam, obs, s.mesh, start);
    EXPECT_NE(r.error.find(says), std::string::npos) << "error: '" << r.error << "', expected '" << says << "'";
    EXPECT_FALSE(r.plausible);
    // The result keeps the start (NaN compares unequal to itself, so compare bit patterns).
    EXPECT_EQ(0, std::memcmp(r.initial_pose.t.data(), start.t.data(), sizeof(double) * 3));
    EXPECT_EQ(0, std::memcmp(r.pose.t.data(), start.t.data(), sizeof(double) * 3));
  };
  Pose nan_pose = s.truth;
  nan_pose.t.z() = std::nan("");
  expect_error(s.obs, nan_pose, "finite");
  Pose behind = s.truth;
  behind.t.z() = -0.5;
  expect_error(s.obs, behind, "behind");
  Observation empty_mask = s.obs;
  empty_mask.mask = cv::Mat::zeros(s.cam.height, s.cam.width, CV_32F);
  expect_error(empty_mask, s.truth, "mask");
  Observation wrong_size = s.obs;
  wrong_size.depth = cv::Mat::zeros(10, 10, CV_32F);
  expect_error(wrong_size, s.truth, "depth");
  Observation nothing;
  nothing.mask = s.obs.mask;
  expect_error(nothing, s.truth, "rgb");
}

/// A printed box and can side by side, 55-60 cm from a 320 x 240 camera, in one frame (rgb and depth).
struct BoxAndCan {
  Camera cam{420, 420, 159.5, 119.5, 320, 240};
  Mesh box = make_box(Eigen::Vector3d(0.08, 0.05, 0.1), make_label_texture(256, 41));
  Mesh can = make_cylinder(0.03, 0.09, 32, make_label_texture(256, 42));
  Pose box_truth, can_truth;
  SyntheticScene scene;
  Observation frame;
  BoxAndCan() {
    Vector6d d;
    d << 0, 0, 0, 0.4, 0.3, 0.2;
    box_truth = Pose(se3_exp(d).R, Eigen::Vector3d(-0.07, 0.0, 0.6));
    can_truth = Pose(se3_exp(-d).R, Eigen::Vector3d(0.07, 0.01, 0.55));
    scene = synthesize_scene(*make_cpu_renderer(), cam, {SceneObject{&box, box_truth}, SceneObject{&can, can_truth}},
                             SyntheticNoise(), 9);
    frame.rgb = scene.rgb;
    frame.depth = scene.depth;
  }
};

TEST(Refiner, RefinesEveryObjectOfAFrameAndReportsBadOnes) {
  const BoxAndCan s;
  const Camera& cam = s.cam;
  const Mesh &box = s.box, &can = s.can;
  const Pose &box_truth = s.box_truth, &can_truth = s.can_truth;
  const SyntheticScene& scene = s.scene;
  const Observation& frame = s.frame;
  std::mt19937_64 rng(9);
  Pose nan_pose = box_truth;
  nan_pose.t.x() = std::nan("");
  const std::vector<ObjectTarget> objects = {
      {&box, perturb_pose(box_truth, box.center(), 10 * M_PI / 180, 0.01, rng), scene.visible_masks[0]},
      {&can, perturb_pose(can_truth, can.center(), 10 * M_PI / 180, 0.01, rng), scene.visible_masks[1]},
      {&box, nan_pose, scene.visible_masks[0]}};
  const auto res = Refiner(test_options()).refine_all(cam, frame, objects);
  ASSERT_EQ(res.size(), 3u);
  EXPECT_TRUE(res[0].error.empty());
  EXPECT_TRUE(res[1].error.empty());
  EXPECT_LT(1e3 * add_error(metric_points(box), res[0].pose, box_truth), 3.0);
  EXPECT_LT(1e3 * adds_error(metric_points(can), res[1].pose, can_truth), 3.0);
  EXPECT_FALSE(res[2].error.empty());
  EXPECT_FALSE(res[2].plausible);

  // Lockstep (all objects' runs in one renderer call per iteration) gives what each object alone gives, with
  // regions of interest on two threads and on the full frame on one thread.
  for (const bool full_frame : {false, true}) {
    SCOPED_TRACE(full_frame ? "full frame, 1 thread" : "regions of interest");
    RenderOptions ro;
    ro.use_roi = !full_frame;
    ro.threads = full_frame ? 1 : 2;
    const auto make = [&] { return make_cpu_renderer(ro); };
    Refiner together(test_options(), make());
    // An object whose mesh the renderer refuses (not finalized) fails alone; the others are still refined.
    Mesh raw;
    raw.positions = box.positions;
    raw.triangles = box.triangles;
    std::vector<ObjectTarget> with_raw = objects;
    with_raw.push_back({&raw, box_truth, scene.visible_masks[0]});
    const auto all = together.refine_all(cam, frame, with_raw);
    ASSERT_EQ(all.size(), 4u);
    EXPECT_FALSE(all[2].error.empty());
    EXPECT_NE(all[3].error.find("not finalized"), std::string::npos) << all[3].error;
    for (size_t k = 0; k < 2; ++k) {
      Observation o = frame;
      o.mask = to_mask_float(objects[k].mask);
      const RefineResult alone = Refiner(test_options(), make()).refine(cam, o, *objects[k].mesh, objects[k].initial);
      EXPECT_TRUE(all[k].error.empty()) << all[k].error;
      EXPECT_EQ(all[k].pose.matrix(), alone.pose.matrix()) << "object " << k;
      EXPECT_EQ(all[k].loss.total, alone.loss.total) << "object " << k;
      EXPECT_EQ(all[k].winner, alone.winner);
      EXPECT_EQ(all[k].mask_iou, alone.mask_iou);
      EXPECT_LT((all[k].pose.t - res[k].pose.t).norm(), 1e-4);  // vs the default renderer
    }
  }
}

TEST(Refiner, EachObjectOfAFrameMayHaveItsOwnSmallerBudget) {
  // A box on a steady track (ObjectTarget::budget) beside a can from a detection, in one pass: the box gets its
  // budget, the can the call's options, and each result is what it gets refined alone with those options.
  const BoxAndCan s;
  std::mt19937_64 rng(9);
  std::vector<ObjectTarget> objects(2);
  objects[0].mesh = &s.box;
  objects[0].initial = perturb_pose(s.box_truth, s.box.center(), M_PI / 180, 0.001, rng);
  objects[0].mask = s.scene.visible_masks[0];
  objects[0].start_kind = StartKind::kTracked;
  RefineBudget budget;
  budget.batch_size = 2;
  budget.iterations = 6;
  objects[0].budget = budget;
  objects[1].mesh = &s.can;
  objects[1].initial = perturb_pose(s.can_truth, s.can.center(), 10 * M_PI / 180, 0.01, rng);
  objects[1].mask = s.scene.visible_masks[1];
  const RefinerOptions o = test_options();
  const auto res = Refiner(o).refine_all(s.cam, s.frame, objects);
  ASSERT_EQ(res.size(), 2u);
  EXPECT_EQ(res[0].iterations, 6);
  EXPECT_EQ(res[0].run_losses.size(), 2u);
  EXPECT_EQ(res[1].iterations, o.iterations);
  for (size_t k = 0; k < 2; ++k) {
    ObjectTarget alone = objects[k];
    alone.budget.reset();
    const RefinerOptions own = objects[k].budget ? with_budget(o, *objects[k].budget) : o;
    const RefineResult single = Refiner(o).refine_all(s.cam, s.frame, {alone}, own).front();
    EXPECT_EQ(res[k].pose.matrix(), single.pose.matrix()) << "object " << k;
    EXPECT_EQ(res[k].loss.total, single.loss.total) << "object " << k;
  }
  // A budget is a cap: larger than the call's options, it changes nothing.
  EXPECT_EQ(with_budget(o, RefineBudget()).iterations, o.iterations);
  RefineBudget none;
  none.batch_size = 0;
  EXPECT_THROW(with_budget(o, none), std::invalid_argument);
}

TEST(RefinerOptions, YamlOverridesAndRejectsTypos) {
  const RefinerOptions o = RefinerOptions::from_yaml_string(
      "batch_size: 8\niterations: 50\nlr_log_uniform: true\nloss: {weight_rgb: 0, depth_truncation: 0.02}\n"
      "render: {cull_back_faces: true}\n");
  EXPECT_EQ(o.batch_size, 8);
  EXPECT_EQ(o.iterations, 50);
  EXPECT_TRUE(o.lr_log_uniform);
  EXPECT_EQ(o.loss.weight_rgb, 0.0);
  EXPECT_EQ(o.loss.weight_depth, 1.0);  // untouched keys keep their defaults
  EXPECT_EQ(o.loss.depth_truncation, 0.02);
  EXPECT_TRUE(o.render.cull_back_faces);
  try {
    RefinerOptions::from_yaml_string("batch_sise: 8\n", "my.yaml");
    FAIL() << "a misspelt key must be rejected";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("batch_sise"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("my.yaml"), std::string::npos);
  }
  EXPECT_THROW(RefinerOptions::from_yaml_string("lr_low: -1\n"), std::runtime_error);
  EXPECT_THROW(RefinerOptions::from_yaml_string("iterations: lots\n"), std::runtime_error);
  EXPECT_THROW(RefinerOptions::from_yaml_file("/nonexistent/options.yaml"), std::runtime_error);
}

TEST(Metrics, AddAddsAndAuc) {
  const std::vector<Eigen::Vector3d> pts = {{0.1, 0, 0}, {-0.1, 0, 0}, {0, 0.1, 0}, {0, -0.1, 0}};
  const Pose truth;
  const Pose shifted(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.01, 0, 0));
  EXPECT_NEAR(add_error(pts, shifted, truth), 0.01, 1e-12);
  Vector6d d = Vector6d::Zero();
  d[5] = M_PI / 2;  // a quarter turn maps this symmetric point set onto itself
  const Pose turned(se3_exp(d).R, Eigen::Vector3d::Zero());
  EXPECT_NEAR(add_error(pts, turned, truth), 0.1 * std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(adds_error(pts, turned, truth), 0.0, 1e-12);
  EXPECT_NEAR(accuracy_auc({0.0, 0.0}, 0.05), 100.0, 1e-9);
  EXPECT_NEAR(accuracy_auc({0.025}, 0.05), 50.0, 1e-9);
  EXPECT_NEAR(accuracy_auc({0.1, 0.0}, 0.05), 50.0, 1e-9);
}

// A deprecated key is read as its current one; a config that gives both is refused, naming both.
TEST(RefinerOptions, DeprecatedNamesAreReadAsTheCurrentOnes) {
  const RefinerOptions o = RefinerOptions::from_yaml_string("explore_tolerance: 0.05\nexplore_texture_weight: 2\n");
  EXPECT_EQ(o.shape_tolerance, 0.05);
  EXPECT_EQ(o.scan_texture_weight, 2.0);
  try {
    RefinerOptions::from_yaml_string("explore_tolerance: 0.05\nshape_tolerance: 0.02\n", "old.yaml");
    ADD_FAILURE() << "both names were accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("old.yaml: explore_tolerance is the deprecated name of shape_tolerance"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(RefinerOptions::from_yaml_string("explore_tolerance: 0.5\n"), std::runtime_error);  // its range
}

TEST(RefinerOptions, ShippedPresetsLoadAndDefaultYamlHoldsTheDefaults) {
  const std::string dir = std::string(DIFFDOPE_SOURCE_DIR) + "/config/";
  // default.yaml spells out the struct's defaults (read onto a base that differs in every field checked).
  RefinerOptions other;
  other.batch_size = 3, other.iterations = 7, other.coarse_fraction = 0.1, other.successive_halving = false;
  other.shape_tolerance = 0.05, other.print_search = 0.1, other.render.lod_pixel_error = 2, other.retry_turn = 1;
  const RefinerOptions d = RefinerOptions::from_yaml_file(dir + "default.yaml", other), want;
  EXPECT_EQ(d.batch_size, want.batch_size);
  EXPECT_EQ(d.iterations, want.iterations);
  EXPECT_EQ(d.coarse_fraction, want.coarse_fraction);
  EXPECT_EQ(d.successive_halving, want.successive_halving);
  EXPECT_EQ(d.shape_tolerance, want.shape_tolerance);
  EXPECT_EQ(d.print_search, want.print_search);
  EXPECT_EQ(d.retry_turn, want.retry_turn);
  EXPECT_EQ(d.render.lod_pixel_error, want.render.lod_pixel_error);
  // paper.yaml is Algorithm 1 exactly: B = 32 runs of 100 steps at one scale, all to the end, nothing added.
  const RefinerOptions p = RefinerOptions::from_yaml_file(dir + "paper.yaml");
  p.validate();
  EXPECT_EQ(p.batch_size, 32);
  EXPECT_EQ(p.iterations, 100);
  EXPECT_EQ(p.image_scale, 0.5);
  EXPECT_EQ(p.coarse_fraction, 0.0);
  EXPECT_FALSE(p.successive_halving);
  EXPECT_EQ(p.early_stop_patience, 0);
  EXPECT_EQ(p.shape_tolerance, 0.0);
  EXPECT_EQ(p.print_search, 0.0);
  EXPECT_EQ(p.retry_turn, 0.0);
  EXPECT_EQ(p.render.lod_pixel_error, 0.0);
  RefinerOptions::from_yaml_file(dir + "fast.yaml").validate();
}

TEST(Refiner, ARejectedResultIsRefinedAgainFromTurnedStarts) {
  // The L-block 70 degrees off: the descent ends in a wrong basin that the verdict rejects; among the starts
  // turned by +-retry_turn about the principal axes one lies in the right basin, and its result wins on loss.
  const Scene s = make_scene(1);
  RefinerOptions plain = test_options();
  plain.retry_turn = 0;
  Refiner once(plain), retrying(test_options());
  for (const uint64_t seed : {1, 3}) {
    SCOPED_TRACE(seed);
    std::mt19937_64 rng(seed);
    const Pose init = perturb_pose(s.truth, s.mesh.center(), 70 * M_PI / 180, 0.02, rng);
    const RefineResult a = once.refine(s.cam, s.obs, s.mesh, init);
    const RefineResult b = retrying.refine(s.cam, s.obs, s.mesh, init);
    EXPECT_GT(add_mm(s, a.pose), 20.0);
    EXPECT_FALSE(a.plausible);
    EXPECT_FALSE(a.retried);
    EXPECT_TRUE(b.retried);
    EXPECT_TRUE(b.plausible);
    EXPECT_LT(add_mm(s, b.pose), 5.0);
    EXPECT_LT(b.loss.total, a.loss.total);
    EXPECT_EQ(b.initial_loss, a.initial_loss);  // the caller's start, not a turned one
    EXPECT_GT(b.start, 0);                      // the winner came from a turned start
    // refine_all retries the same way, unless the start is a tracked one.
    ObjectTarget t{&s.mesh, init, s.obs.mask, {}, StartKind::kFresh};
    const RefineResult c = retrying.refine_all(s.cam, s.obs, {t})[0];
    EXPECT_TRUE(c.retried);
    EXPECT_LT(add_mm(s, c.pose), 5.0);
    t.start_kind = StartKind::kTracked;
    EXPECT_FALSE(retrying.refine_all(s.cam, s.obs, {t})[0].retried);
  }
  // An accepted result is not refined again: the same as without retries.
  std::mt19937_64 rng(2);
  const Pose init = perturb_pose(s.truth, s.mesh.center(), 70 * M_PI / 180, 0.02, rng);
  const RefineResult a = once.refine(s.cam, s.obs, s.mesh, init);
  const RefineResult b = retrying.refine(s.cam, s.obs, s.mesh, init);
  ASSERT_TRUE(a.plausible);
  EXPECT_FALSE(b.retried);
  EXPECT_TRUE(b.pose.matrix().isApprox(a.pose.matrix(), 1e-12));
}


TEST(Refiner, ARetryReplacesTheFirstResultOnlyWhenAcceptedAndLowerOrClearlyBetterPrinted) {
  const auto printed = [](double z) {  // a registration z standard deviations above its chance level
    PrintRegistration p;
    p.ncc = 0.1 * z;
    p.far_mean = 0.0;
    p.far_std = 0.1;
    return p;
  };
  RefineResult first;
  first.plausible = false;
  first.loss.total = 0.40;
  RefineResult retry;
  retry.plausible = true;
  retry.loss.total = 0.30;
  EXPECT_TRUE(retry_replaces(first, retry, true));
  retry.loss.total = 0.45;  // accepted but worse fit, the print measured at neither
  EXPECT_FALSE(retry_replaces(first, retry, true));
  // A worse fit whose print registers clearly where the first's did not: the colour term favoured a wrong turn.
  first.print = printed(0.2);
  retry.print = printed(0.2 + kClearPrint + 0.5);
  EXPECT_TRUE(retry_replaces(first, retry, true));
  EXPECT_FALSE(retry_replaces(first, retry, false));  // the print not weighed
  retry.print = printed(0.2 + kClearPrint - 0.5);     // better, but not clearly
  EXPECT_FALSE(retry_replaces(first, retry, true));
  first.print = PrintRegistration();  // not measured at the first: nothing to weigh
  retry.print = printed(8.0);
  EXPECT_FALSE(retry_replaces(first, retry, true));
  first.print = printed(-1.0);  // below chance: counts as 0
  retry.print = printed(kClearPrint - 0.5);
  EXPECT_FALSE(retry_replaces(first, retry, true));
  retry.print = printed(kClearPrint + 0.5);
  EXPECT_TRUE(retry_replaces(first, retry, true));
  first.print = printed(2.0);  // both register: the loss decides
  retry.print = printed(4.5);
  EXPECT_FALSE(retry_replaces(first, retry, true));
  retry.loss.total = 0.30;
  retry.plausible = false;  // rejected too: lower loss alone does not win (RGB-only turned starts)
  EXPECT_FALSE(retry_replaces(first, retry, true));
  retry.plausible = true;
  retry.error = "lost";
  EXPECT_FALSE(retry_replaces(first, retry, true));
}

TEST(Refiner, APlainModelGetsNoColourTermUnlessAskedAndTheResultSaysWhichTermsWereUsedAndWhetherItWasJudged) {
  // A grey box against a lit, colourful image of it: the flat colour can only mislead.
  const Mesh plain = make_box(Eigen::Vector3d(0.08, 0.05, 0.12), make_flat_texture(Eigen::Vector3f(0.6f, 0.6f, 0.6f)));
  const Mesh printed = make_box(Eigen::Vector3d(0.08, 0.05, 0.12), make_label_texture(64, 2));
  EXPECT_TRUE(plain.plain());
  EXPECT_FALSE(printed.plain());
  const Camera cam(400, 400, 159.5, 119.5, 320, 240);
  const Pose truth(Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix(),
                   Eigen::Vector3d(0.01, 0, 0.5));
  const Observation obs = synthesize_observation(*make_cpu_renderer(), cam, printed, truth, SyntheticNoise(), 2);
  RefinerOptions o;
  o.batch_size = 2;
  o.iterations = 2;
  o.image_scale = 1.0;
  const auto terms = [&](const Mesh& mesh, const Observation& in) {
    return used_terms(Refiner(o).refine(cam, in, mesh, truth).loss_used);
  };
  using T = std::vector<std::string>;
  EXPECT_EQ(terms(printed, obs), (T{"rgb", "depth", "mask"}));
  EXPECT_EQ(terms(plain, obs), (T{"depth", "mask"}));
  Observation no_mask = obs;
  no_mask.mask = cv::Mat();
  EXPECT_EQ(terms(plain, no_mask), (T{"depth", "mask"}));  // the pixels derived from depth
  RefinerOptions window = o;
  window.derive_mask = false;
  EXPECT_EQ(used_terms(Refiner(window).refine(cam, no_mask, plain, truth).loss_used), (T{"depth"}));
  Observation rgb_alone = no_mask;
  rgb_alone.depth = cv::Mat();
  EXPECT_EQ(terms(plain, rgb_alone), (T{"rgb", "mask"}));  // the only evidence left, and the pixels it gives
  EXPECT_EQ(used_terms(Refiner(window).refine(cam, rgb_alone, plain, truth).loss_used), (T{"rgb"}));
  // Nothing can judge that result (no mask, no depth, no print): its verdict is undetermined, and says why.
  const RefineResult unjudged = Refiner(o).refine(cam, rgb_alone, plain, truth);
  EXPECT_FALSE(unjudged.plausible);
  EXPECT_EQ(verdict_state(unjudged), VerdictState::kUndetermined);
  EXPECT_NE(undetermined_reason(unjudged).find("nothing could judge"), std::string::npos);
  const RefineResult judged = Refiner(o).refine(cam, obs, printed, truth);
  EXPECT_EQ(verdict_state(judged), judged.plausible ? VerdictState::kPlausible : VerdictState::kImplausible);
  EXPECT_EQ(undetermined_reason(judged), "");
  RefinerOptions none = o;  // no iteration run: the start is not a refined result, whatever its scores
  none.iterations = 0;
  const RefineResult unrefined = Refiner(none).refine(cam, obs, printed, truth);
  EXPECT_EQ(verdict_state(unrefined), VerdictState::kUndetermined);
  EXPECT_NE(undetermined_reason(unrefined).find("iterations 0"), std::string::npos);
  Observation wrong_size = obs;
  wrong_size.depth = cv::Mat(7, 7, CV_32F, cv::Scalar(0.5));
  const RefineResult refused = Refiner(o).refine(cam, wrong_size, printed, truth);
  ASSERT_FALSE(refused.error.empty());
  EXPECT_EQ(verdict_state(refused), VerdictState::kUndetermined);
  EXPECT_EQ(undetermined_reason(refused), "not refined: " + refused.error);
  EXPECT_STREQ(to_string(VerdictState::kUndetermined), "undetermined");
  o.plain_model_rgb = true;
  EXPECT_EQ(terms(plain, obs), (T{"rgb", "depth", "mask"}));
  // Loaded meshes: vertex colours of one value are plain, two are not.
  Mesh painted = plain;
  painted.textures.clear();
  painted.tri_texture.clear();
  painted.uvs.clear();
  painted.colors.assign(painted.positions.size(), Vec3f{0.2f, 0.3f, 0.4f});
  painted.finalize();
  EXPECT_TRUE(painted.plain());
  painted.colors[0] = Vec3f{0.9f, 0.3f, 0.4f};
  painted.finalize();
  EXPECT_FALSE(painted.plain());
}
