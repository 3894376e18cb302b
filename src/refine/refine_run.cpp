// One object's refinement as a state machine (refine_run.hpp): set-up, the iterations' batches and steps.
// finish() and its steps: refine_finish.cpp.
#include "refine/refine_run.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

#include "diffdope/mask_agreement.hpp"
#include "diffdope/object_pixels.hpp"
#include "diffdope/print_alignment.hpp"
#include "refine/refine_schedule.hpp"

namespace diffdope {
namespace {

/// Without a mask: the initial projection's bounding box grown by `grow` of its size on each side (the mask
/// term then has no observation; the window keeps the loss to the object's neighbourhood).
cv::Mat window_mask(const Camera& cam, const Mesh& mesh, const Pose& pose, double grow) {
  const Eigen::AlignedBox2d b = cam.project_bounds(mesh.bbox_corners(pose), 1e-3);
  if (b.isEmpty()) return cv::Mat(cam.height, cam.width, CV_32F, cv::Scalar(1.0));
  const Eigen::Vector2d g = grow * b.sizes();
  cv::Mat m = cv::Mat::zeros(cam.height, cam.width, CV_32F);
  const cv::Rect r(cv::Point(int(std::floor(b.min().x() - g.x())), int(std::floor(b.min().y() - g.y()))),
                   cv::Point(int(std::ceil(b.max().x() + g.x())) + 1, int(std::ceil(b.max().y() + g.y())) + 1));
  m(r & cv::Rect(0, 0, cam.width, cam.height)).setTo(1.0);
  return m;
}

/// The median colour error (|I - R| / 3 per channel) of `render` where it covers pixels that are likely the
/// object's (`pixels` >= 0.5); NaN where there are none.
double median_colour_error(const cv::Mat& rgb, const RenderImage& render, const cv::Mat& pixels) {
  std::vector<float> errors;
  for (int y = render.roi.y; y < render.roi.y + render.roi.height; ++y)
    for (int x = render.roi.x; x < render.roi.x + render.roi.width; ++x) {
      if (render.coverage.at<float>(y, x) < 0.99f || pixels.at<float>(y, x) < 0.5f) continue;
      const cv::Vec3f i = rgb.at<cv::Vec3f>(y, x), c = render.color.at<cv::Vec3f>(y, x);
      errors.push_back((std::abs(i[0] - c[0]) + std::abs(i[1] - c[1]) + std::abs(i[2] - c[2])) / 3.f);
    }
  if (errors.empty()) return NAN;
  std::nth_element(errors.begin(), errors.begin() + long(errors.size() / 2), errors.end());
  return errors[errors.size() / 2];
}

/// Where a detector's box lets the object's pixels be (kBoxSlack).
cv::Rect search_box(const cv::Rect& box) {
  const int gx = int(std::ceil(kBoxSlack * box.width)) + 1, gy = int(std::ceil(kBoxSlack * box.height)) + 1;
  return cv::Rect(box.x - gx, box.y - gy, box.width + 2 * gx, box.height + 2 * gy);
}

/// Why an initial pose has nothing to be refined against ("" when it has): its object is outside the image, or
/// projects smaller than kMinProjectedPixels at the refining scale.
std::string out_of_view(const Camera& cam, const Mesh& mesh, const Pose& pose, double near_plane) {
  if (mesh.content_id() == 0) return "";  // not finalized: the renderer says so
  std::vector<Eigen::Vector3d> corners = mesh.bbox_corners();
  for (Eigen::Vector3d& c : corners) c = pose * c;
  const Eigen::AlignedBox2d box = cam.project_bounds(corners, near_plane);
  if (box.isEmpty()) return "";  // the object reaches the camera plane: its projection is unbounded, so in view
  const Eigen::AlignedBox2d image(Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(cam.width - 0.5, cam.height - 0.5));
  std::ostringstream m;
  m.precision(4);
  if (!box.intersects(image)) {
    m << "refine: initial pose puts the object outside the image (t = " << pose.t.transpose() << " m)";
    return m.str();
  }
  const double z = (pose * mesh.center()).z();
  const double pixels = mesh.diameter() * std::max(cam.fx, cam.fy) / z;
  if (pixels < kMinProjectedPixels) {
    m << "refine: at the initial pose the object is " << pixels << " pixels across at the refining scale (z = "
      << z << " m); at least " << kMinProjectedPixels << " are needed";
    return m.str();
  }
  return "";
}

}  // namespace

std::string start_problem(const Camera& camera, const Mesh& mesh, const Pose& start, const RefinerOptions& o) {
  if (!start.is_valid(1e-4)) return "refine: initial pose is not finite or its rotation is not orthonormal";
  const Eigen::Vector3d centre = start * mesh.center();
  if (!(centre.z() > o.render.near_plane))
    return centre.z() > 0 ? "refine: the initial pose puts the object's centre at z = " + std::to_string(centre.z()) +
                                " m, not beyond render.near_plane (" + std::to_string(o.render.near_plane) + " m)"
                          : "refine: initial pose puts the object behind the camera (z = " + std::to_string(centre.z()) +
                                " m)";
  return out_of_view(scaled_camera(camera, o.image_scale), mesh, start, o.render.near_plane);
}

std::vector<size_t> usable_starts(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& starts,
                                  const RefinerOptions& o) {
  std::vector<size_t> usable;
  for (size_t k = 0; k < starts.size(); ++k)
    if (start_problem(camera, mesh, starts[k], o).empty()) usable.push_back(k);
  if (usable.empty())
    for (size_t k = 0; k < starts.size(); ++k) usable.push_back(k);
  return usable;
}

namespace {

/// The checks of RefineRun's input that need no images resized: views, meshes, starts in front of the camera and
/// in view. Throws std::invalid_argument naming the view (of several) that fails.
void validate_views(const RefinerOptions& o, const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                    bool shares_frames) {
  if (views.empty()) throw std::invalid_argument("refine: no view");
  if (views.size() > 1 && shares_frames) throw std::logic_error("RefineRun: shared frames of one view");
  if (initials.empty()) throw std::invalid_argument("refine: no initial pose");
  const bool given_mask = views.front().observed.has_mask();
  for (size_t v = 0; v < views.size(); ++v) {
    const RefineView& view = views[v];
    const std::string which = views.size() > 1 ? " (view " + std::to_string(v) + ")" : "";
    if (!view.mesh) throw std::invalid_argument("refine: no mesh" + which);
    view.observed.validate(view.camera);
    if (!view.observed.has_rgb() && !view.observed.has_depth())
      throw std::invalid_argument("refine: need at least an rgb or a depth image" + which);
    if (view.observed.has_mask() != given_mask)
      throw std::invalid_argument("refine: either every view has a mask or none" + which);
    for (const Pose& initial : initials)
      if (const std::string problem = start_problem(view.camera, *view.mesh, initial, o); !problem.empty())
        throw std::invalid_argument(problem + which);
  }
}

}  // namespace

RefineRun::RefineRun(const RefinerOptions& o, const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                     std::vector<Pose> shape_turns, const Observation* scaled_frame, const Observation* coarse_frame,
                     const Eigen::Vector3d* pivot_model)
    : options_(o), start_time_(std::chrono::steady_clock::now()), initials_(initials), turns_(std::move(shape_turns)) {
  validate_views(o, views, initials, scaled_frame || coarse_frame);
  for (const RefineView& view : views) meshes_.push_back(view.mesh);
  loss_ = o.loss;
  set_up_levels(views, scaled_frame, coarse_frame);
  set_up_loss(views);
  pivot_model_ = pivot_model ? *pivot_model : meshes_.front()->center();
  diameter_ = 1e-6;
  for (const Mesh* m : meshes_) diameter_ = std::max(diameter_, m->diameter());
  if (!turns_.empty()) scan_at_ = scan_iteration(o);
  start_runs();
}

RefineRun::Level RefineRun::make_level(const RefineView& view, double scale, const Observation* shared,
                                       Phase phase) const {
  const Observation& observed = view.observed;
  Level l;
  l.cam = scaled_camera(view.camera, scale);
  if (shared) {  // the frame's images (refine_all), this object's mask resized
    const Observation own = Observation().with_mask(observed.mask);
    l.obs = shared->with_mask(scale == 1.0 ? own.mask : own.resized(l.cam).mask,
                              scaled_box(observed.box, cv::Size(view.camera.width, view.camera.height),
                                         cv::Size(l.cam.width, l.cam.height)));
  } else {
    l.obs = scale == 1.0 ? observed : observed.resized(l.cam);
  }
  // The paper's edge term: Canny edges of the observed image, computed at this scale.
  if (loss_.weight_edges > 0 && l.obs.has_rgb() && !l.obs.has_edges()) l.obs.edges = observed_edges(l.obs.rgb);
  if (uses_texture(options_, phase) && l.obs.has_rgb() && !l.obs.has_texture())
    l.obs.texture = observed_texture(l.obs.rgb, loss_.texture_epsilon);
  // Without a mask: the detector's box, or a window around the initial projections (the mask term then has no
  // observation).
  if (!l.obs.has_mask() && l.obs.has_box()) {
    l.obs.mask = cv::Mat::zeros(l.cam.height, l.cam.width, CV_32F);
    l.obs.mask(search_box(l.obs.box) & cv::Rect(0, 0, l.cam.width, l.cam.height)).setTo(1.0);
  } else if (!l.obs.has_mask()) {
    const double grow = options_.no_mask_window;
    l.obs.mask = window_mask(l.cam, *view.mesh, initials_.front(), grow);
    for (size_t j = 1; j < initials_.size(); ++j)
      l.obs.mask = cv::max(l.obs.mask, window_mask(l.cam, *view.mesh, initials_[j], grow));
  }
  return l;
}

void RefineRun::set_up_levels(const std::vector<RefineView>& views, const Observation* scaled_frame,
                              const Observation* coarse_frame) {
  const RefinerOptions& o = options_;
  switch_at_ = coarse_iterations(o);
  const bool given_mask = views.front().observed.has_mask();
  for (const RefineView& view : views) {
    mask_from_depth_.push_back(view.mask_from_depth && view.observed.has_mask());
    fine_.push_back(make_level(view, o.image_scale, scaled_frame, Phase::kFine));
    if (given_mask && cv::countNonZero(fine_.back().obs.mask > 0) == 0)
      throw std::invalid_argument(views.size() > 1 ? "refine: the object mask of view " +
                                                         std::to_string(fine_.size() - 1) + " is empty"
                                                   : "refine: the object mask is empty");
    if (switch_at_ > 0) coarse_.push_back(make_level(view, o.image_scale * o.coarse_scale, coarse_frame, Phase::kCoarse));
  }
}

void RefineRun::set_up_loss(const std::vector<RefineView>& views) {
  const RefinerOptions& o = options_;
  const bool given_mask = views.front().observed.has_mask();
  // Without a mask the object's pixels are derived from depth (one view), or the window stands in for them, which
  // is not an observation of the silhouette. With a mask the first derivation checks it (update_object_pixels()).
  // Without depth either, from colour: the window's uncovered pixels would otherwise each cost a miss, pulling
  // the render toward the camera until it fills the window.
  const Observation& observed = views.front().observed;
  const bool one_view = o.derive_mask && views.size() == 1;
  pixels_from_colour_ = one_view && !given_mask && !observed.has_depth() && observed.has_rgb();
  derives_pixels_ = one_view && (observed.has_depth() || pixels_from_colour_);
  weighs_given_mask_ = given_mask && derives_pixels_;
  has_mask_ = given_mask || (derives_pixels_ && !pixels_from_colour_);
  rederive_at_ = switch_at_ > 0 ? switch_at_ : o.iterations / 2;
  if (!has_mask_ && !pixels_from_colour_) loss_.weight_mask = 0;
  if (derives_pixels_ && !given_mask) loss_.weight_mask *= kDerivedMaskWeight;
  bool all_plain = true, any_depth = false, any_rgb = false;
  for (const RefineView& view : views) {
    all_plain = all_plain && view.mesh->plain();
    any_depth = any_depth || view.observed.has_depth();
    any_rgb = any_rgb || view.observed.has_rgb();
  }
  if (all_plain && !o.plain_model_rgb && (has_mask_ || any_depth)) loss_.weight_rgb = 0;
  res_.loss_used = loss_;
  if (!any_depth) res_.loss_used.weight_depth = 0;
  if (!any_rgb) res_.loss_used.weight_rgb = res_.loss_used.weight_edges = res_.loss_used.weight_texture = 0;
  scan_loss_ = loss_;
  scan_loss_.weight_texture += o.scan_texture_weight;
}

void RefineRun::start_runs() {
  const RefinerOptions& o = options_;
  const int B = o.batch_size, starts = int(initials_.size());
  std::mt19937_64 rng(o.seed);
  res_.initial_pose = initials_.front();
  res_.learning_rates.resize(B);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int i = 0; i < B; ++i) {
    const double u = U(rng);
    res_.learning_rates[i] = o.lr_log_uniform ? o.lr_low * std::pow(o.lr_high / o.lr_low, u)
                                              : o.lr_low + (o.lr_high - o.lr_low) * u;
  }
  if (B == 1) res_.learning_rates[0] = 0.5 * (o.lr_low + o.lr_high);
  // Several initial poses (e.g. a new detection and the previous frame's result): run i starts from
  // initials[i % starts], so every start gets a spread of learning rates and the loss picks the winner.
  poses_.resize(B);
  for (int i = 0; i < B; ++i) poses_[i] = initials_[i % starts];
  best_pose_ = poses_;
  best_.assign(B, LossValue());
  for (auto& b : best_) b.total = std::numeric_limits<double>::infinity();
  res_.run_histories.assign(B, {});
  active_.resize(B);
  for (int i = 0; i < B; ++i) active_[i] = i;
  source_.assign(B, -1);
  jump_angle_.assign(B, 0.0);
  best_overall_ = std::numeric_limits<double>::infinity();
}

cv::Mat RefineRun::derived_pixels(Renderer& renderer, const std::vector<Pose>& poses, double margin) {
  const Level& fine = fine_.front();
  ObjectPixelsOptions po;
  po.margin = std::min(margin, 1.0);
  po.surface_search = std::min(0.5 * diameter_, 1.0);  // the object's surroundings, at its own scale
  po.touching_render = true;
  po.holes_from_colour = true;
  if (fine.obs.has_box()) po.bounds = search_box(fine.obs.box);
  evaluations_ += long(poses.size());
  if (pixels_from_colour_) {
    const std::vector<RenderImage> renders = renderer.render(fine.cam, mesh(), poses, cv::Mat());
    const cv::Mat pixels = derive_object_pixels_from_colour(fine.cam, fine.obs.rgb, renders, po);
    if (pixels.empty() || cv::countNonZero(pixels >= 0.5f) == 0) return cv::Mat();
    colour_match_error_ = median_colour_error(fine.obs.rgb, renders.front(), pixels);
    return pixels;
  }
  cv::Mat pixels = derive_object_pixels(fine.cam, fine.obs.depth, renderer.render(fine.cam, mesh(), poses, cv::Mat()),
                                        po, fine.obs.rgb);
  if (cv::countNonZero(pixels >= 0.5f) == 0) return cv::Mat();
  return pixels;
}

bool RefineRun::derive_pixels(Renderer& renderer, const std::vector<Pose>& poses, double margin) {
  const cv::Mat pixels = derived_pixels(renderer, poses, margin);
  if (pixels.empty()) return false;
  // From colour, a likely-object pixel the render misses costs what the render's colour error on the object's
  // pixels is: the colour term then neither grows the silhouette (a miss dearer than a match) nor shrinks it (a
  // miss free), and the pixels' probabilities decide it through the mask term.
  if (pixels_from_colour_ && std::isfinite(colour_match_error_))
    loss_.rgb_miss = scan_loss_.rgb_miss = res_.loss_used.rgb_miss =
        std::min(colour_match_error_, options_.loss.rgb_miss);
  use_pixels(pixels);
  return true;
}

void RefineRun::use_pixels(const cv::Mat& pixels) {
  fine_.front().obs.mask = pixels;
  mask_from_depth_.front() = !pixels_from_colour_ && !fine_.front().obs.has_rgb();  // its holes: no evidence
  if (!coarse_.empty()) {
    Level& coarse = coarse_.front();
    cv::resize(pixels, coarse.obs.mask, cv::Size(coarse.cam.width, coarse.cam.height), 0, 0, cv::INTER_AREA);
  }
  ++pixels_version_;
}

void RefineRun::update_object_pixels(Renderer& renderer) {
  if (!derives_pixels_ || done_) return;
  const double reach = options_.no_mask_window * diameter_;
  if (derivations_ == 0 && weighs_given_mask_) {
    ++derivations_;
    // A segmenter's mask is evidence: its outline is taken as given only where depth puts the object's edge
    // too. Otherwise the pixels derived from depth and colour replace it, as they stand in for a missing one.
    const cv::Mat pixels = derived_pixels(renderer, initials_, std::max(reach, options_.inlier_threshold));
    const double offset = pixels.empty() ? NAN : outline_offset(fine_.front().obs.mask, pixels);
    if (!std::isnan(offset)) res_.given_mask_offset = offset;
    if (!pixels.empty()) {
      const double scale = options_.image_scale;
      const OutlineShift shift =
          best_outline_shift(fine_.front().obs.mask, pixels, int(std::ceil(kMaxMaskShift * scale)));
      if (!std::isnan(shift.offset)) {
        res_.given_mask_shift = {shift.dx / scale, shift.dy / scale};
        res_.given_mask_shifted_offset = shift.offset;
      }
    }
    if (!(offset > kTrustedOutlineOffset)) {
      derives_pixels_ = false;
      return;
    }
    res_.given_mask_replaced = true;
    use_pixels(pixels);
    loss_.weight_mask *= kDerivedMaskWeight;
    scan_loss_.weight_mask *= kDerivedMaskWeight;
    res_.loss_used.weight_mask *= kDerivedMaskWeight;
  } else if (derivations_ == 0) {
    // A tracked start is a frame's motion from the truth: from depth its pixels are derived before the descent
    // already at the narrowed reach, and once more about the result (derives_twice()). (From colour alone that
    // cost two of bench_tracking's three objects accuracy: it keeps all three derivations.)
    derivations_ = derives_twice() ? 2 : 1;
    const double margin = derives_twice() ? reach / 3 : reach;
    if (derive_pixels(renderer, initials_, std::max(margin, options_.inlier_threshold))) return;
    // Nothing near the starts in depth (or no colour likely the object's): the window stays, and it is no
    // observation of the silhouette.
    derives_pixels_ = has_mask_ = false;
    loss_.weight_mask = scan_loss_.weight_mask = res_.loss_used.weight_mask = 0;
  } else if (derivations_ == 1 && k_ == rederive_at_ && k_ > 0) {
    ++derivations_;
    // About the best poses of the runs most likely to survive the halving at this iteration (the better half, by
    // their best loss): a large-rate run may have stepped far from its best since.
    std::vector<int> runs = active_;
    std::stable_sort(runs.begin(), runs.end(), [&](int a, int b) { return best_[a].total < best_[b].total; });
    runs.resize(std::min<size_t>(runs.size(), std::max<size_t>(1, (runs.size() + 1) / 2)));
    std::vector<Pose> poses;
    for (int i : runs) poses.push_back(best_pose_[size_t(i)]);
    derive_pixels(renderer, poses, std::max(reach / 3, options_.inlier_threshold));
  }
}

void RefineRun::evaluate_fine(Renderer& renderer, const std::vector<Pose>& poses, const LossOptions& loss,
                              Gradients gradients, std::vector<LossValue>& out) {
  evaluations_ += long(poses.size() * meshes_.size());
  evaluate_views(renderer, poses, loss, gradients == Gradients::kCompute, out, Phase::kFine);
}

void RefineRun::evaluate_views(Renderer& renderer, const std::vector<Pose>& poses, const LossOptions& loss,
                               bool with_gradient, std::vector<LossValue>& out, Phase phase) {
  const auto level = [&](size_t v) -> const Level& { return phase == Phase::kFine ? fine_[v] : coarse_[v]; };
  if (meshes_.size() == 1) {
    renderer.evaluate(level(0).cam, *meshes_[0], level(0).obs, poses, loss, with_gradient, out);
    return;
  }
  view_values_.resize(meshes_.size());
  for (size_t v = 0; v < meshes_.size(); ++v)
    renderer.evaluate(level(v).cam, *meshes_[v], level(v).obs, poses, loss, with_gradient, view_values_[v]);
  out.assign(poses.size(), LossValue());
  const double w = 1.0 / double(meshes_.size());
  for (size_t j = 0; j < poses.size(); ++j)
    for (const std::vector<LossValue>& vv : view_values_) {
      const LossValue& x = vv[j];
      LossValue& y = out[j];
      y.rgb += w * x.rgb, y.depth += w * x.depth, y.mask += w * x.mask, y.edges += w * x.edges;
      y.texture += w * x.texture, y.total += w * x.total;
      y.gradient += w * x.gradient;
    }
}

RefineRun::Step RefineRun::next_step(Renderer& renderer) {
  update_object_pixels(renderer);
  const int iters = options_.iterations;
  const bool last = k_ == iters;
  const int due = halvings_due(k_, iters);
  for (; options_.successive_halving && !last && halvings_ < due; ++halvings_) {
    // The runs from the starts and the shape scan's candidates are halved apart: a candidate never displaces
    // the start's own basin before both have converged.
    std::vector<int> kept;
    for (const bool candidates : {false, true}) {
      std::vector<int> group;
      for (int i : active_)
        if ((source_[size_t(i)] >= 0) == candidates) group.push_back(i);
      std::stable_sort(group.begin(), group.end(), [&](int a, int b) { return best_[a].total < best_[b].total; });
      group.resize((group.size() + 1) / 2);
      kept.insert(kept.end(), group.begin(), group.end());
    }
    active_ = kept;
    std::sort(active_.begin(), active_.end());
  }
  if ((k_ == switch_at_ && switch_at_ > 0) || bests_pixels_ != pixels_version_) {
    // The fine phase begins, or the object's pixels were derived again: losses at the coarse scale, or under the
    // previous pixels, do not compare with these, so each run's best is sought again from here.
    for (LossValue& b : best_) b.total = std::numeric_limits<double>::infinity();
    best_overall_ = std::numeric_limits<double>::infinity();
    stale_ = 0;
    bests_pixels_ = pixels_version_;
  }
  const Level& level = coarse() ? coarse_.front() : fine_.front();
  Step step;
  step.camera = &level.cam;
  step.mask = level.obs.mask;
  step.scan = k_ == scan_at_ && !scanned_ && !last;
  step.with_gradient = !step.scan && !last;
  step.loss = step.scan ? scan_loss_ : loss_;
  if (step.scan) {  // every run turned by every shape turn (itself first)
    const size_t n = 1 + turns_.size();
    step.poses.resize(active_.size() * n);
    for (size_t j = 0; j < active_.size(); ++j) {
      step.poses[j * n] = poses_[active_[j]];
      for (size_t t = 0; t < turns_.size(); ++t) step.poses[j * n + 1 + t] = poses_[active_[j]] * turns_[t];
    }
    return step;
  }
  step.poses.resize(active_.size());
  for (size_t j = 0; j < active_.size(); ++j) step.poses[j] = poses_[active_[j]];
  return step;
}

void RefineRun::evaluate_step(Renderer& renderer, const Step& step, std::vector<LossValue>& values) {
  // (absorb() counts it)
  evaluate_views(renderer, step.poses, step.loss, step.with_gradient, values, coarse() ? Phase::kCoarse : Phase::kFine);
}

void RefineRun::add_scan_candidates(const Step& scan, const std::vector<LossValue>& values) {
  const size_t n = 1 + turns_.size();
  std::vector<size_t> from(n, SIZE_MAX);  // per turn, the batch row of the run it is lowest for
  for (size_t j = 0; j < active_.size(); ++j) {
    size_t best = 0;
    for (size_t t = 1; t < n; ++t)
      if (values[j * n + t].total < values[j * n + best].total) best = t;
    // A turn must be clearly better: on a print the loss barely sees, near ties would pick one at random.
    if (best == 0 || !(values[j * n + best].total < (1.0 - kScanMargin) * values[j * n].total)) continue;
    if (from[best] == SIZE_MAX || values[j * n + best].total < values[from[best] * n + best].total) from[best] = j;
  }
  // The lowest of them (kScanCandidates): the final choice weighs only the best candidate, and each costs a
  // run through the fine phase (measured: one instead of one per turn, the same results on the dev sets).
  std::vector<size_t> order;
  for (size_t t = 1; t < n; ++t)
    if (from[t] != SIZE_MAX) order.push_back(t);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return values[from[a] * n + a].total < values[from[b] * n + b].total;
  });
  if (order.size() > size_t(kScanCandidates)) order.resize(size_t(kScanCandidates));
  for (size_t t : order) {
    const int source = active_[from[t]];
    const int i = int(poses_.size());
    poses_.push_back(scan.poses[from[t] * n + t]);
    best_pose_.push_back(poses_.back());
    best_.push_back(LossValue());
    best_.back().total = std::numeric_limits<double>::infinity();
    res_.learning_rates.push_back(res_.learning_rates[size_t(source)]);
    // (NaN until the scan: its history lines up with the other runs' iterations)
    res_.run_histories.emplace_back(res_.run_histories[size_t(source)].size(),
                                    std::numeric_limits<double>::quiet_NaN());
    source_.push_back(source);
    jump_angle_.push_back(Eigen::AngleAxisd(turns_[t - 1].R).angle());
    active_.push_back(i);
    ++res_.scan_turns;
  }
}

void RefineRun::absorb(const Step& step, const std::vector<LossValue>& values, const Refiner::Progress& on_iteration) {
  const RefinerOptions& o = options_;
  const int iters = o.iterations, starts = int(initials_.size());
  const bool last = k_ == iters;
  evaluations_ += long(step.poses.size() * meshes_.size());
  if (step.scan) {  // candidates; the runs go on unturned; no step
    add_scan_candidates(step, values);
    scanned_ = true;
    return;
  }
  if (k_ == 0) {
    res_.initial_loss = values[0].total;
    for (int j = 1; j < std::min(starts, int(values.size())); ++j)
      res_.initial_loss = std::min(res_.initial_loss, values[j].total);
  }
  for (size_t j = 0; j < active_.size(); ++j) {
    const int i = active_[j];
    res_.run_histories[i].push_back(values[j].total);
    if (values[j].total < best_[i].total) {
      best_[i] = values[j];
      best_pose_[i] = poses_[i];
    }
  }
  const double round_best =
      std::min_element(best_.begin(), best_.end(), [](auto& a, auto& b) { return a.total < b.total; })->total;
  const bool improved = round_best < best_overall_ * (1.0 - o.early_stop_tolerance);
  best_overall_ = std::min(best_overall_, round_best);
  if (on_iteration) on_iteration(k_, iters, best_overall_);
  stale_ = improved ? 0 : stale_ + 1;
  const bool stalled = o.early_stop_patience > 0 && stale_ >= o.early_stop_patience;
  if (stalled && !last && coarse()) {  // the coarse phase has done its work: go on at the fine scale
    k_ = switch_at_ - 1;
    stale_ = 0;
  } else if (last || stalled) {
    res_.iterations = steps_;
    done_ = true;
    return;
  }
  const double decay = std::pow(o.lr_decay, double(k_) / iters);
  for (size_t j = 0; j < active_.size(); ++j) {
    const int i = active_[j];
    if (!std::isfinite(values[j].total)) continue;  // a run that left the image keeps its pose
    const Eigen::Vector3d pivot = poses_[i] * pivot_model_;
    poses_[i] = refiner_step(poses_[i], values[j].gradient, res_.learning_rates[i] * decay, diameter_, pivot);
  }
  ++k_;
  ++steps_;
}

}  // namespace diffdope
