// The object's pixels without a mask (derive_object_pixels) and the refiner that derives them, on a generated
// scene as users have them: the object on a table, a box touching it, a post in front of it, depth noise and holes.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "diffdope/device.hpp"
#include "diffdope/metrics.hpp"
#include "diffdope/object_pixels.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/primitives.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"
#include "test_scenes.hpp"

using namespace diffdope;

namespace {

/// Camera-from-world of a camera at `eye` looking at `target`, world z up (OpenCV optical frame).
Pose look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_camera;
  world_from_camera << x, y, z;
  const Eigen::Matrix3d R = world_from_camera.transpose();
  return Pose(R, -R * eye);
}

struct ClutteredScene {
  Camera cam{420, 420, 159.5, 119.5, 320, 240};
  Mesh object = make_scan_like(ScanShape::Bottle, Eigen::Vector3d(0.07, 0.045, 0.16), 3000, 256, 3);
  Mesh table = make_box(Eigen::Vector3d(0.6, 0.6, 0.02), make_pattern_texture(256, 5));
  Mesh neighbour = make_box(Eigen::Vector3d(0.06, 0.06, 0.1), make_label_texture(256, 77));
  Mesh post = make_box(Eigen::Vector3d(0.025, 0.025, 0.3), make_pattern_texture(64, 9));
  Pose truth;
  SyntheticScene scene;
  Observation obs;  // rgb and depth, no mask
};

/// The object standing on a table seen from 45 degrees above, a box touching its side and a post between it and
/// the camera hiding part of it.
/// `colour_dx`: the colour image this many pixels right of the depth image and the masks (a camera's registration).
ClutteredScene make_cluttered_scene(uint32_t seed, double colour_dx = 0) {
  ClutteredScene s;
  const Pose camera_from_world = look_at(Eigen::Vector3d(0.05, -0.38, 0.38), Eigen::Vector3d(0, 0, 0.04));
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
  const Pose turned(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()).toRotationMatrix(), Eigen::Vector3d::Zero());
  for (const Eigen::Vector3d& c : s.object.bbox_corners(turned)) lo = lo.cwiseMin(c), hi = hi.cwiseMax(c);
  const Pose world_from_object(turned.R, Eigen::Vector3d(-0.5 * (lo.x() + hi.x()), -0.5 * (lo.y() + hi.y()), -lo.z()));
  s.truth = camera_from_world * world_from_object;
  const Pose table = camera_from_world * Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, -0.01));
  const double half_width = 0.5 * (hi.x() - lo.x());
  const Pose neighbour = camera_from_world * Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(half_width + 0.03, 0, 0.05));
  const Pose post = camera_from_world * Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.0, -0.12, 0.15));
  auto renderer = make_cpu_renderer();
  SyntheticNoise noise;
  noise.brightness = 0.9;
  noise.colour_offset_x_px = colour_dx;
  s.scene = synthesize_scene(*renderer, s.cam,
                             {{&s.object, s.truth}, {&s.table, table}, {&s.neighbour, neighbour}, {&s.post, post}},
                             noise, seed);
  s.obs.rgb = s.scene.rgb;
  s.obs.depth = s.scene.depth;
  return s;
}

RefinerOptions test_options() {
  RefinerOptions o;
  o.batch_size = 16;
  o.iterations = 48;
  o.image_scale = 1.0;  // the test images are already small
  return o;
}

double overlap(const cv::Mat& a, const cv::Mat& b) { return cv::countNonZero((a >= 0.5f) & (b >= 0.5f)); }

}  // namespace

// At the true pose, the derived pixels are the object's visible ones: the table under it, the box touching it and
// the post in front of it are left out.
TEST(ObjectPixels, LeaveOutTheTableANeighbourAndAnOccluder) {
  const ClutteredScene s = make_cluttered_scene(3);
  const cv::Mat& visible = s.scene.visible_masks[0];
  ASSERT_LT(s.scene.visible_fraction[0], 0.97);  // the post hides part of it
  auto renderer = make_cpu_renderer();
  ObjectPixelsOptions po;
  po.margin = 0.01;
  po.surface_search = 0.5 * s.object.diameter();
  po.touching_render = true;
  po.holes_from_colour = true;
  const cv::Mat pixels = derive_object_pixels(s.cam, s.obs.depth, renderer->render(s.cam, s.object, {s.truth}), po, s.obs.rgb);
  const double object = cv::countNonZero(visible >= 0.5f);
  const double iou = overlap(pixels, visible) / cv::countNonZero((pixels >= 0.5f) | (visible >= 0.5f));
  EXPECT_GT(iou, 0.9);
  for (size_t k = 1; k < 4; ++k)
    EXPECT_LT(overlap(pixels, s.scene.visible_masks[k]), 0.02 * object) << "scene object " << k;
  // A box bounds the pixels.
  po.bounds = cv::Rect(0, 0, s.cam.width / 2, s.cam.height);
  const cv::Mat bounded = derive_object_pixels(s.cam, s.obs.depth, renderer->render(s.cam, s.object, {s.truth}), po, s.obs.rgb);
  EXPECT_EQ(cv::countNonZero(bounded(cv::Rect(s.cam.width / 2, 0, s.cam.width / 2, s.cam.height)) > 0), 0);
  EXPECT_GT(cv::countNonZero(bounded > 0), 0);
}

// An estimate slid along a plain cylinder's axis: the end it does not cover yet is within reach and must stay
// the object's, or nothing pulls the estimate back. A rod lies on the table behind that end; the table is a
// plane, the rod and the slabs RANSAC cuts through it and the table beside it are not.
TEST(ObjectPixels, AnUncoveredEndBesideARodStaysTheObjects) {
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  const Mesh object = make_cylinder(0.035, 0.11, 48, make_flat_texture(Eigen::Vector3f(0.4f, 0.3f, 0.9f)));
  const Mesh rod = make_cylinder(0.02, 0.24, 32, make_pattern_texture(128, 5));
  const Mesh table = make_box(Eigen::Vector3d(0.8, 0.8, 0.02), make_pattern_texture(256, 7));
  const Pose camera_from_world = look_at(Eigen::Vector3d(0.0, -0.42, 0.3), Eigen::Vector3d(0, 0, 0.03));
  const Pose lying(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix(), Eigen::Vector3d(0, 0, 0.035));
  auto renderer = make_cpu_renderer();
  SyntheticNoise noise;
  noise.hole_fraction = 0;
  const SyntheticScene scene = synthesize_scene(
      *renderer, cam,
      {{&object, camera_from_world * lying},
       {&rod, camera_from_world * Pose(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix(), Eigen::Vector3d(0.045, 0.18, 0.02))},
       {&table, camera_from_world * Pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, -0.01))}},
      noise, 5);
  // Slid 2 cm along its axis, away from the end by the rod; derived at a coarse start's margin.
  const Pose slid = camera_from_world * Pose(lying.R, lying.t + Eigen::Vector3d(-0.02, 0, 0));
  ObjectPixelsOptions po;
  po.margin = 0.04;
  po.surface_search = 0.5 * object.diameter();
  po.touching_render = true;
  const cv::Mat pixels = derive_object_pixels(cam, scene.depth, renderer->render(cam, object, {slid}), po);
  const cv::Mat& visible = scene.visible_masks[0];
  EXPECT_GT(overlap(pixels, visible), 0.95 * cv::countNonZero(visible >= 0.5f));
  for (size_t k = 1; k < 3; ++k)  // the rod and the table
    EXPECT_LT(overlap(pixels, scene.visible_masks[k]), 0.05 * cv::countNonZero(visible >= 0.5f)) << "scene object " << k;
}

TEST(ObjectPixels, RefusesWhatItCannotUse) {
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  ObjectPixelsOptions po;
  EXPECT_THROW(derive_object_pixels(cam, cv::Mat(), {}, po), std::invalid_argument);
  EXPECT_THROW(derive_object_pixels(cam, cv::Mat::zeros(10, 10, CV_32F), {}, po), std::invalid_argument);
  po.margin = 0;
  EXPECT_THROW(derive_object_pixels(cam, cv::Mat::zeros(240, 320, CV_32F), {}, po), std::invalid_argument);
  po.margin = 0.01;
  EXPECT_THROW(derive_object_pixels(cam, cv::Mat::zeros(240, 320, CV_32F), {}, po, cv::Mat::zeros(240, 320, CV_8UC3)),
               std::invalid_argument);
  // Nothing rendered: nothing is the object's.
  EXPECT_EQ(cv::countNonZero(derive_object_pixels(cam, cv::Mat::ones(240, 320, CV_32F), {}, po)), 0);
}

// Good starts stay good without a mask, with a detector's box too: the table, the box touching the object and
// the post in front do not pull the render onto themselves.
TEST(ObjectPixels, WithoutAMaskGoodStartsStayWithinTwoMillimetres) {
  const ClutteredScene s = make_cluttered_scene(4);
  const auto points = metric_points(s.object);
  cv::Rect box = cv::boundingRect(cv::Mat(s.scene.visible_masks[0] >= 0.5f));
  std::mt19937_64 rng(11);
  for (int k = 0; k < 4; ++k) {
    const Pose start = perturb_pose(s.truth, s.object.center(), M_PI / 180, 0.001, rng);
    const RefineResult r = Refiner(test_options()).refine(s.cam, s.obs, s.object, start);
    EXPECT_LT(1e3 * add_error(points, r.pose, s.truth), 2.0) << "start " << k;
    test::expect_within_plan(r, test_options(), "start " + std::to_string(k));
    EXPECT_GT(r.stage_evaluations[size_t(RefineStage::kDerivePixels)], 0) << "start " << k;
    EXPECT_TRUE(r.plausible) << "start " << k;
    EXPECT_GT(r.mask_iou, 0.8) << "start " << k;  // against the derived pixels
    Observation boxed = s.obs;
    boxed.box = box;
    const RefineResult b = Refiner(test_options()).refine(s.cam, boxed, s.object, start);
    EXPECT_LT(1e3 * add_error(points, b.pose, s.truth), 2.0) << "start " << k << ", with a box";
  }
}

// A segmenter's mask a few pixels off is checked against depth and replaced by the derived pixels; an exact one
// is taken as given. Either way good starts end within two millimetres and are judged plausible; the grown mask
// taken as given (derive_mask false) pulls them 3-4 mm off.
TEST(ObjectPixels, ASegmentersMaskIsCheckedAgainstDepth) {
  const ClutteredScene s = make_cluttered_scene(5);
  const auto points = metric_points(s.object);
  const cv::Mat exact = s.scene.visible_masks[0];
  cv::Mat grown;
  cv::dilate(exact, grown, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(7, 7)));
  std::mt19937_64 rng(12);
  for (int k = 0; k < 3; ++k) {
    const Pose start = perturb_pose(s.truth, s.object.center(), M_PI / 180, 0.001, rng);
    Observation given = s.obs;
    given.mask = exact;
    const RefineResult e = Refiner(test_options()).refine(s.cam, given, s.object, start);
    EXPECT_FALSE(e.given_mask_replaced) << "start " << k << ", offset " << e.given_mask_offset;
    EXPECT_GE(e.given_mask_offset, 0.0);
    EXPECT_LT(1e3 * add_error(points, e.pose, s.truth), 2.0) << "start " << k << ", exact mask";
    EXPECT_TRUE(e.plausible) << "start " << k << ", exact mask";
    given.mask = grown;
    const RefineResult c = Refiner(test_options()).refine(s.cam, given, s.object, start);
    EXPECT_TRUE(c.given_mask_replaced) << "start " << k << ", offset " << c.given_mask_offset;
    EXPECT_GT(c.given_mask_offset, 1.0);  // 3 pixels out, less the one depth's mixed edge readings lose
    EXPECT_LT(1e3 * add_error(points, c.pose, s.truth), 2.0) << "start " << k << ", grown mask";
    EXPECT_TRUE(c.plausible) << "start " << k << ", grown mask";
    RefinerOptions as_given = test_options();
    as_given.derive_mask = false;
    const RefineResult t = Refiner(as_given).refine(s.cam, given, s.object, start);
    EXPECT_EQ(t.given_mask_offset, -1.0);
    EXPECT_FALSE(t.given_mask_replaced);
    EXPECT_GT(1e3 * add_error(points, t.pose, s.truth), 2.0) << "start " << k << ", the grown mask taken as given";
  }
}

// Without depth, colour says which pixels are the object's: about a start a centimetre and five degrees off, the
// object's visible pixels are likely, the table is not, and the box beside it and the post in front (prints like
// the object's) are clearly less likely than it.
TEST(ObjectPixels, FromColourTheObjectIsLikelyAndItsSurroundingsNot) {
  const ClutteredScene s = make_cluttered_scene(3);
  auto renderer = make_cpu_renderer();
  std::mt19937_64 rng(13);
  const Pose start = perturb_pose(s.truth, s.object.center(), 5 * M_PI / 180, 0.01, rng);
  ObjectPixelsOptions po;
  po.margin = 0.3 * s.object.diameter();
  const cv::Mat p = derive_object_pixels_from_colour(s.cam, s.obs.rgb, renderer->render(s.cam, s.object, {start}), po);
  ASSERT_FALSE(p.empty());
  // Over each scene object's visible pixels within the reach (beyond it the probability is 0).
  const auto mean_over = [&](const cv::Mat& where) { return cv::mean(p, (where >= 0.5f) & (p > 0.f))[0]; };
  const double object = mean_over(s.scene.visible_masks[0]);
  EXPECT_GT(object, 0.8);
  EXPECT_LT(mean_over(s.scene.visible_masks[1]), 0.5) << "the table";
  for (size_t k = 2; k < 4; ++k) EXPECT_LT(mean_over(s.scene.visible_masks[k]), object - 0.15) << "scene object " << k;
  // Nothing beyond the reach, nor outside a detector's box.
  EXPECT_EQ(cv::countNonZero(p(cv::Rect(0, 0, 20, 20))), 0);
  po.bounds = cv::Rect(0, 0, s.cam.width / 2, s.cam.height);
  const cv::Mat bounded =
      derive_object_pixels_from_colour(s.cam, s.obs.rgb, renderer->render(s.cam, s.object, {start}), po);
  EXPECT_EQ(cv::countNonZero(bounded(cv::Rect(s.cam.width / 2, 0, s.cam.width / 2, s.cam.height)) > 0), 0);
  EXPECT_GT(cv::countNonZero(bounded > 0), 0);
}

TEST(ObjectPixels, FromColourRefusesWhatItCannotUse) {
  const ClutteredScene s = make_cluttered_scene(3);
  auto renderer = make_cpu_renderer();
  const std::vector<RenderImage> renders = renderer->render(s.cam, s.object, {s.truth});
  ObjectPixelsOptions po;
  EXPECT_THROW(derive_object_pixels_from_colour(s.cam, cv::Mat(), renders, po), std::invalid_argument);
  EXPECT_THROW(derive_object_pixels_from_colour(s.cam, cv::Mat::zeros(240, 320, CV_8UC3), renders, po),
               std::invalid_argument);
  EXPECT_THROW(derive_object_pixels_from_colour(s.cam, cv::Mat::zeros(10, 10, CV_32FC3), renders, po),
               std::invalid_argument);
  po.margin = 0;
  EXPECT_THROW(derive_object_pixels_from_colour(s.cam, s.obs.rgb, renders, po), std::invalid_argument);
  po.margin = 0.01;
  const Camera other(100, 100, 49.5, 49.5, 100, 100);
  EXPECT_THROW(derive_object_pixels_from_colour(other, cv::Mat::zeros(100, 100, CV_32FC3), renders, po),
               std::invalid_argument);
  // Nothing rendered, or nothing left around the render to learn the surroundings from: no pixels.
  EXPECT_TRUE(derive_object_pixels_from_colour(s.cam, s.obs.rgb, {}, po).empty());
  po.margin = 1.0;
  EXPECT_TRUE(derive_object_pixels_from_colour(s.cam, s.obs.rgb, renders, po).empty());
}

// From colour alone, good starts stay good: the pixels colour gives the object hold its silhouette, where the
// window about the start (derive_mask false) lets the colour term's misses pull the render off. The window's
// errors here are 0.7-2.1 mm.
TEST(ObjectPixels, FromColourAloneGoodStartsStayGood) {
  const ClutteredScene s = make_cluttered_scene(4);
  const auto points = metric_points(s.object);
  Observation colour = s.obs;
  colour.depth = cv::Mat();
  std::mt19937_64 rng(14);
  double colour_sum = 0, window_sum = 0;
  for (int k = 0; k < 3; ++k) {
    const Pose start = perturb_pose(s.truth, s.object.center(), M_PI / 180, 0.001, rng);
    const RefineResult r = Refiner(test_options()).refine(s.cam, colour, s.object, start);
    EXPECT_LT(1e3 * add_error(points, r.pose, s.truth), 1.5) << "start " << k;
    EXPECT_TRUE(r.plausible) << "start " << k;
    EXPECT_GT(r.stage_evaluations[size_t(RefineStage::kDerivePixels)], 0) << "start " << k;
    EXPECT_EQ(used_terms(r.loss_used), (std::vector<std::string>{"rgb", "mask"})) << "start " << k;
    EXPECT_LT(r.loss_used.rgb_miss, test_options().loss.rgb_miss) << "start " << k;  // the colour's own error
    test::expect_within_plan(r, test_options(), "start " + std::to_string(k));
    RefinerOptions window = test_options();
    window.derive_mask = false;
    const RefineResult w = Refiner(window).refine(s.cam, colour, s.object, start);
    EXPECT_EQ(used_terms(w.loss_used), (std::vector<std::string>{"rgb"})) << "start " << k;
    colour_sum += add_error(points, r.pose, s.truth);
    window_sum += add_error(points, w.pose, s.truth);
  }
  EXPECT_LT(colour_sum, window_sum);
}

// The colours' weighing on a drawn image: the object red, its surroundings blue, a green patch in its reach that
// neither region shows (an occluder, a highlight) is near a half, undecided; starts that share no pixel still
// give the object's colours.
TEST(ObjectPixels, FromColourAColourNeitherRegionShowsIsUndecided) {
  const Camera cam(200, 200, 99.5, 99.5, 200, 200);
  cv::Mat rgb(200, 200, CV_32FC3, cv::Scalar(0.1f, 0.2f, 0.9f));
  rgb(cv::Rect(70, 70, 60, 60)).setTo(cv::Scalar(0.9f, 0.1f, 0.1f));
  rgb(cv::Rect(132, 90, 6, 20)).setTo(cv::Scalar(0.1f, 0.9f, 0.2f));  // beside the object, inside its reach
  const auto render_at = [&](const cv::Rect& r) {
    RenderImage img;
    img.roi = r;
    img.coverage = cv::Mat::zeros(200, 200, CV_32F);
    img.depth = cv::Mat::zeros(200, 200, CV_32F);
    img.coverage(r).setTo(1.0);
    img.depth(r).setTo(0.5);
    return img;
  };
  ObjectPixelsOptions po;
  po.margin = 0.025;  // 10 pixels at 0.5 m
  const cv::Mat p = derive_object_pixels_from_colour(cam, rgb, {render_at(cv::Rect(72, 70, 60, 60))}, po);
  ASSERT_FALSE(p.empty());
  EXPECT_GT(p.at<float>(100, 100), 0.95f);  // the object
  EXPECT_LT(p.at<float>(100, 65), 0.05f);   // its surroundings, in the reach
  EXPECT_NEAR(p.at<float>(100, 134), 0.5f, 0.1f);  // green: neither
  EXPECT_EQ(p.at<float>(100, 20), 0.0f);    // beyond the reach
  // Two starts that share no pixel, one of them right: the object's colour is still the likelier.
  const cv::Mat q = derive_object_pixels_from_colour(
      cam, rgb, {render_at(cv::Rect(72, 70, 60, 60)), render_at(cv::Rect(5, 5, 30, 30))}, po);
  ASSERT_FALSE(q.empty());
  EXPECT_GT(q.at<float>(100, 100), 0.5f);
  EXPECT_LT(q.at<float>(100, 65), 0.5f);
}

// A steady track's start is a frame's motion from the truth: refined on the track's budget (tracked_options()), its
// object's pixels derived from depth once before the descent and once about the result, it converges as closely
// among the table, the neighbour and the post as a start refined with the full budget.
TEST(ObjectPixels, ATrackedStartWithoutAMaskConvergesOnTheTrackBudget) {
  const ClutteredScene s = make_cluttered_scene(3);
  const std::vector<Eigen::Vector3d> points = metric_points(s.object);
  std::mt19937_64 rng(11);
  for (int k = 0; k < 3; ++k) {
    const Pose start = perturb_pose(s.truth, s.object.center(), 1.5 * M_PI / 180, 0.004, rng);
    ObjectTarget t;
    t.mesh = &s.object;
    t.initial = start;
    t.start_kind = StartKind::kTracked;
    Refiner refiner(test_options());
    const RefineResult tracked = refiner.refine_all(s.cam, s.obs, {t}, tracked_options(test_options(), TrackOptions()))[0];
    const RefineResult full = refiner.refine(s.cam, s.obs, s.object, start);
    ASSERT_TRUE(tracked.error.empty()) << tracked.error;
    EXPECT_TRUE(tracked.plausible) << "start " << k;
    const double add_tracked = 1e3 * add_error(points, tracked.pose, s.truth);
    EXPECT_LT(add_tracked, 1.0) << "start " << k << " from " << 1e3 * add_error(points, start, s.truth) << " mm";
    EXPECT_LT(add_tracked, 1e3 * add_error(points, full.pose, s.truth) + 0.5) << "start " << k;
    EXPECT_LT(tracked.evaluations, full.evaluations / 2) << "start " << k;
  }
}

// A colour image registered to depth with an error (the generator's colour offset: colour moves, depth and masks
// stay), and a segmenter's mask drawn on it, off depth as a whole: the result reports the shift, in camera pixels
// at any refining scale, that lays the mask on depth's edge; an exact mask needs none.
TEST(ObjectPixels, AMaskDrawnOnMisregisteredColourReportsItsShift) {
  const ClutteredScene registered = make_cluttered_scene(5), s = make_cluttered_scene(5, 4.0);
  // The generator moved the colour alone.
  EXPECT_EQ(cv::norm(registered.scene.depth, s.scene.depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(registered.scene.visible_masks[0], s.scene.visible_masks[0], cv::NORM_INF), 0.0);
  const cv::Rect inner(8, 8, s.cam.width - 16, s.cam.height - 16);
  EXPECT_EQ(cv::norm(registered.scene.rgb(inner), s.scene.rgb(inner + cv::Point(4, 0)), cv::NORM_INF), 0.0);
  const cv::Mat exact = s.scene.visible_masks[0];
  cv::Mat on_colour;  // the visible mask where the colour image shows the object
  cv::warpAffine(exact, on_colour, cv::Matx23d(1, 0, 4, 0, 1, 0), exact.size(), cv::INTER_NEAREST);
  for (const double scale : {1.0, 0.5}) {
    RefinerOptions o = test_options();
    o.image_scale = scale;
    o.iterations = 8;  // the shift is measured before the first step
    Observation given = s.obs;
    given.mask = exact;
    const RefineResult e = Refiner(o).refine(s.cam, given, s.object, s.truth);
    // (within a working pixel: drawn whole, without meshoptimizer's levels, the derived outline moves by one)
    EXPECT_LE(std::abs(e.given_mask_shift[0]), 1.0 / scale) << "scale " << scale;
    EXPECT_LE(std::abs(e.given_mask_shift[1]), 1.0 / scale) << "scale " << scale;
    EXPECT_LE(e.given_mask_shifted_offset, e.given_mask_offset) << "scale " << scale;
    given.mask = on_colour;
    const RefineResult m = Refiner(o).refine(s.cam, given, s.object, s.truth);
    EXPECT_NEAR(m.given_mask_shift[0], -4.0, 1.0 / scale) << "scale " << scale;
    EXPECT_NEAR(m.given_mask_shift[1], 0.0, 1.0 / scale) << "scale " << scale;
    EXPECT_LT(m.given_mask_shifted_offset, 0.5 * m.given_mask_offset) << "scale " << scale;
    RefinerOptions as_given = o;
    as_given.derive_mask = false;
    const RefineResult t = Refiner(as_given).refine(s.cam, given, s.object, s.truth);
    EXPECT_EQ(t.given_mask_shifted_offset, -1.0);
  }
}
