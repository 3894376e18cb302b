// One object's refinement as a state machine (refine_run.hpp): setup, the iterations' batches and steps, and
// the choice, polish, print alignment and scoring of the result.
#include "refine/refine_run.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

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

/// An initial pose whose object is outside the image, or projects smaller than a couple of pixels at the
/// refining scale, has nothing to be refined against: a refinement would only "converge" on noise.
void check_in_view(const Camera& cam, const Mesh& mesh, const Pose& pose, double near_plane) {
  if (mesh.content_id() == 0) return;  // not finalized: the renderer says so
  std::vector<Eigen::Vector3d> corners = mesh.bbox_corners();
  for (Eigen::Vector3d& c : corners) c = pose * c;
  const Eigen::AlignedBox2d box = cam.project_bounds(corners, near_plane);
  if (box.isEmpty()) return;  // the object reaches the camera plane: its projection is unbounded, so in view
  const Eigen::AlignedBox2d image(Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(cam.width - 0.5, cam.height - 0.5));
  std::ostringstream m;
  m.precision(4);
  if (!box.intersects(image)) {
    m << "refine: initial pose puts the object outside the image (t = " << pose.t.transpose() << " m)";
    throw std::invalid_argument(m.str());
  }
  const double z = (pose * mesh.center()).z();
  const double pixels = mesh.diameter() * std::max(cam.fx, cam.fy) / z;
  if (pixels < 2.0) {
    m << "refine: at the initial pose the object is " << pixels << " pixels across at the refining scale (z = "
      << z << " m); at least 2 are needed";
    throw std::invalid_argument(m.str());
  }
}

}  // namespace

RefineRun::RefineRun(const RefinerOptions& o, const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                     std::vector<Pose> shape_turns, const Observation* scaled_frame, const Observation* coarse_frame,
                     const Eigen::Vector3d* pivot_model)
    : options_(o), start_time_(std::chrono::steady_clock::now()), initials_(initials), turns_(std::move(shape_turns)) {
  if (views.empty()) throw std::invalid_argument("refine: no view");
  if (views.size() > 1 && (scaled_frame || coarse_frame)) throw std::logic_error("RefineRun: shared frames of one view");
  if (initials.empty()) throw std::invalid_argument("refine: no initial pose");
  has_mask_ = views.front().observed.has_mask();
  for (size_t v = 0; v < views.size(); ++v) {
    const RefineView& view = views[v];
    const std::string which = views.size() > 1 ? " (view " + std::to_string(v) + ")" : "";
    if (!view.mesh) throw std::invalid_argument("refine: no mesh" + which);
    view.observed.validate(view.camera);
    if (!view.observed.has_rgb() && !view.observed.has_depth())
      throw std::invalid_argument("refine: need at least an rgb or a depth image" + which);
    if (view.observed.has_mask() != has_mask_)
      throw std::invalid_argument("refine: either every view has a mask or none" + which);
    meshes_.push_back(view.mesh);
    for (const Pose& initial : initials) {
      if (!initial.is_valid(1e-4))
        throw std::invalid_argument("refine: initial pose is not finite or its rotation is not orthonormal");
      const Eigen::Vector3d centre0 = initial * view.mesh->center();
      if (!(centre0.z() > o.render.near_plane))
        throw std::invalid_argument("refine: initial pose puts the object behind the camera (z = " +
                                    std::to_string(centre0.z()) + " m)" + which);
      check_in_view(scaled_camera(view.camera, o.image_scale), *view.mesh, initial, o.render.near_plane);
    }
  }
  const Pose& initial = initials.front();
  const int starts = int(initials.size());

  loss_ = o.loss;
  // The images at each scale: the frame's shared ones (refine_all) or resized here, this object's mask resized,
  // and without a mask a window around the initial projections (the mask term then has no observation).
  const auto make_level = [&](const RefineView& view, double scale, const Observation* shared, bool fine) {
    const Observation& observed = view.observed;
    const Mesh& mesh = *view.mesh;
    Level l;
    l.cam = scaled_camera(view.camera, scale);
    if (shared) {
      const Observation own = Observation().with_mask(observed.mask);
      l.obs = shared->with_mask(scale == 1.0 ? own.mask : own.resized(l.cam).mask);
    } else {
      l.obs = scale == 1.0 ? observed : observed.resized(l.cam);
    }
    // The paper's edge term: Canny edges of the observed image, computed at this scale.
    if (loss_.weight_edges > 0 && l.obs.has_rgb() && !l.obs.has_edges()) l.obs.edges = observed_edges(l.obs.rgb);
    if (uses_texture(o, fine) && l.obs.has_rgb() && !l.obs.has_texture())
      l.obs.texture = observed_texture(l.obs.rgb, loss_.texture_epsilon);
    if (!l.obs.has_mask()) {
      l.obs.mask = window_mask(l.cam, mesh, initial, o.no_mask_window);
      for (int j = 1; j < starts; ++j) l.obs.mask = cv::max(l.obs.mask, window_mask(l.cam, mesh, initials[j], o.no_mask_window));
    }
    return l;
  };
  switch_at_ = coarse_iterations(o);
  for (const RefineView& view : views) {
    fine_.push_back(make_level(view, o.image_scale, scaled_frame, true));
    if (has_mask_ && cv::countNonZero(fine_.back().obs.mask > 0) == 0)
      throw std::invalid_argument(views.size() > 1 ? "refine: the object mask of view " +
                                                         std::to_string(fine_.size() - 1) + " is empty"
                                                   : "refine: the object mask is empty");
    if (switch_at_ > 0) coarse_.push_back(make_level(view, o.image_scale * o.coarse_scale, coarse_frame, false));
  }
  if (!has_mask_) loss_.weight_mask = 0;  // the window is not an observation of the silhouette
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
  pivot_model_ = pivot_model ? *pivot_model : meshes_.front()->center();
  scan_loss_ = loss_;
  scan_loss_.weight_texture += o.explore_texture_weight;
  if (!turns_.empty()) scan_at_ = scan_iteration(o);

  const int B = o.batch_size;
  std::mt19937_64 rng(o.seed);
  res_.initial_pose = initial;
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
  poses_.assign(B, initial);
  for (int i = 0; i < B; ++i) poses_[i] = initials[i % starts];
  best_pose_ = poses_;
  best_.assign(B, LossValue());
  for (auto& b : best_) b.total = std::numeric_limits<double>::infinity();
  res_.run_histories.assign(B, {});
  diameter_ = 1e-6;
  for (const Mesh* m : meshes_) diameter_ = std::max(diameter_, m->diameter());
  active_.resize(B);
  for (int i = 0; i < B; ++i) active_[i] = i;
  source_.assign(B, -1);
  jump_angle_.assign(B, 0.0);
  best_overall_ = std::numeric_limits<double>::infinity();
}

void RefineRun::evaluate(Renderer& renderer, const std::vector<Pose>& poses, const LossOptions& loss,
                         bool with_gradient, std::vector<LossValue>& out, bool fine) {
  const auto level = [&](size_t v) -> const Level& { return fine || !coarse() ? fine_[v] : coarse_[v]; };
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

const std::vector<Pose>& RefineRun::batch() {
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
  if (k_ == switch_at_ && switch_at_ > 0) {
    // The fine phase begins: losses at the coarse scale do not compare with fine ones, so each run's best is
    // sought again from here.
    for (LossValue& b : best_) b.total = std::numeric_limits<double>::infinity();
    best_overall_ = std::numeric_limits<double>::infinity();
    stale_ = 0;
  }
  if (k_ == scan_at_ && !scanned_ && !last) {  // every run turned by every shape turn (itself first)
    scanning_ = true;
    const size_t n = 1 + turns_.size();
    batch_.resize(active_.size() * n);
    for (size_t j = 0; j < active_.size(); ++j) {
      batch_[j * n] = poses_[active_[j]];
      for (size_t t = 0; t < turns_.size(); ++t) batch_[j * n + 1 + t] = poses_[active_[j]] * turns_[t];
    }
    return batch_;
  }
  batch_.resize(active_.size());
  for (size_t j = 0; j < active_.size(); ++j) batch_[j] = poses_[active_[j]];
  return batch_;
}

void RefineRun::absorb(const std::vector<LossValue>& values, const std::function<void(int, int, double)>& on_iteration) {
  const RefinerOptions& o = options_;
  const int iters = o.iterations, starts = int(initials_.size());
  const bool last = k_ == iters;
  if (scanning_) {  // candidates: a new run from each turn some run prefers; the runs go on unturned; no step
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
      poses_.push_back(batch_[from[t] * n + t]);
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
    scanning_ = false;
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

PrintRegistration RefineRun::register_render(const RenderImage& img) const {
  const Observation& obs = fine_[0].obs;
  if (meshes_.size() != 1 || !obs.has_rgb()) return PrintRegistration();
  // The object's interior where the observation shows it: 2 px inside the render's full coverage (the
  // silhouette's gradients fit whenever the shape does) and, with a mask, inside the observed mask.
  cv::Mat interior = img.coverage >= 0.999f;
  if (has_mask_) interior &= cv::Mat(obs.mask >= 0.5f);
  cv::erode(interior, interior, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  return register_print(obs.rgb, img.color, interior, 8, loss_.texture_epsilon);
}

double RefineRun::print_significance(Renderer& renderer, const Pose& pose) const {
  // A continuous declared symmetry turns the print with the object: it cannot be registered along that axis.
  if (meshes_.size() != 1 || !fine_[0].obs.has_rgb() || !meshes_[0]->symmetry.continuous.empty())
    return std::numeric_limits<double>::quiet_NaN();
  return register_render(renderer.render(fine_[0].cam, *meshes_[0], {pose}, fine_[0].obs.mask)[0]).significance();
}

double jump_margin(double angle) { return kJumpMargin * (1.0 + 4.0 * std::abs(angle) / M_PI); }

bool jump_is_supported(const JumpEvidence& from, const JumpEvidence& to, double angle, bool weigh_print) {
  if (!(to.loss < from.loss)) return false;
  if (weigh_print && std::isfinite(from.print) && !std::isfinite(to.print)) return false;  // the print is lost
  const bool weighed = weigh_print && std::isfinite(from.print) && std::isfinite(to.print);
  if (weighed && to.print < from.print - kPrintContradiction) return false;
  const double need = kClearPrint * (1.0 + std::abs(angle) / M_PI);
  if (weighed && to.print >= need && to.print - std::max(from.print, 0.0) >= need) return true;
  return to.loss < (1.0 - jump_margin(angle)) * from.loss;
}

bool turn_is_supported(double z_from, double z_to, bool weigh_print) {
  if (!weigh_print || !std::isfinite(z_from)) return true;
  return std::isfinite(z_to) && z_to >= z_from - kPrintContradiction;
}

void RefineRun::polish(Renderer& renderer, RefineResult& res) {
  const RefinerOptions& o = options_;
  const int iters = polish_iterations_;
  if (iters <= 0 || o.iterations == 0 || !std::isfinite(res.loss.total)) return;  // (0 iterations: score the start)
  // Small rates, doubling from lr_low: the descent's runs that won the coarse phase were often large-rate ones,
  // whose decayed steps still hop around the minimum when the iterations end.
  std::vector<Pose> poses(size_t(o.polish_runs), res.pose);
  std::vector<LossValue> v;
  int stale = 0;
  for (int k = 0; k <= iters; ++k) {
    if (k == 0) {  // every run starts at the result: one evaluation gives them all their first gradient
      evaluate(renderer, {res.pose}, loss_, true, v, true);
      const LossValue first = v[0];
      v.assign(poses.size(), first);
    } else {
      evaluate(renderer, poses, loss_, k < iters, v, true);
    }
    const double decay = std::pow(o.lr_decay, double(k) / iters);
    const double before = res.loss.total;
    for (size_t j = 0; j < poses.size(); ++j)
      if (v[j].total < res.loss.total) res.loss = v[j], res.pose = poses[j];
    stale = res.loss.total < (1.0 - kPolishTolerance) * before ? 0 : stale + 1;
    res.polish_iterations = k;
    if (stale >= kPolishPatience) return;  // converged
    for (size_t j = 0; j < poses.size(); ++j) {
      if (k == iters || !std::isfinite(v[j].total)) continue;
      const double rate = o.lr_low * std::pow(2.0, double(j)) * decay;
      poses[j] = refiner_step(poses[j], v[j].gradient, rate, diameter_, poses[j] * pivot_model_);
    }
  }
}

int RefineRun::lowest(const RefineResult& res, int first, int last) const {
  int best = -1;
  for (int i = first; i < last; ++i)
    if (best < 0 || res.run_losses[size_t(i)] < res.run_losses[size_t(best)]) best = i;
  return best;
}

void RefineRun::take(RefineResult& res, int i) const {
  res.winner = i;
  res.pose = best_pose_[size_t(i)];
  res.start = (source_[size_t(i)] >= 0 ? source_[size_t(i)] : i) % int(initials_.size());
  res.initial_pose = initials_[size_t(res.start)];
  res.loss = best_[size_t(i)];
  res.history = res.run_histories[size_t(i)];
}

double RefineRun::ResultPrint::at(Renderer& renderer, const RefineResult& res) {
  if (!known) z = run.print_significance(renderer, res.pose), known = true;
  return z;
}

RefineResult RefineRun::finish(Renderer& renderer) {
  RefineResult res = std::move(res_);
  const int runs = int(best_.size());
  res.run_losses.resize(size_t(runs));
  for (int i = 0; i < runs; ++i) res.run_losses[size_t(i)] = best_[size_t(i)].total;
  res.run_poses = best_pose_;
  take(res, lowest(res, 0, options_.batch_size));  // the start's own basin
  if (switch_at_ > 0) weigh_starts(renderer, res);
  ResultPrint print{*this};
  weigh_candidate(renderer, res, print);
  const Pose before_polish = res.pose;
  polish(renderer, res);
  if (!(res.pose.R == before_polish.R && res.pose.t == before_polish.t)) print.known = false;  // measured elsewhere
  align_result_print(renderer, res, print);
  // Of the poses a declared symmetry makes equivalent, the one nearest the start: a track does not spin.
  if (meshes_.size() == 1) res.pose = meshes_.front()->symmetry.nearest_equivalent(res.pose, res.initial_pose.R);
  const int rendered_pixels = score_views(renderer, res);
  judge_result(renderer, res, rendered_pixels);
  return res;
}

void RefineRun::weigh_starts(Renderer& renderer, RefineResult& res) {
  // The first iteration was at the coarse scale: the initial loss at the fine one, of the starts that got a run
  // (as at k = 0).
  std::vector<LossValue> v;
  const int starts = std::min(int(initials_.size()), options_.batch_size);
  const std::vector<Pose> started(initials_.begin(), initials_.begin() + starts);
  evaluate(renderer, started, loss_, false, v, true);
  const size_t j = size_t(std::min_element(v.begin(), v.end(), [](auto& a, auto& b) { return a.total < b.total; }) - v.begin());
  res.initial_loss = v[j].total;
  // The start is a pose seen too (at k = 0, at the coarse scale): when no run's fine-phase best beats it (a
  // start that was already right: a track), it is the result, from the run that started there.
  if (v[j].total < res.loss.total) {
    res.winner = int(j);
    res.start = int(j);
    res.pose = res.initial_pose = initials_[j];
    res.loss = v[j];
    res.run_losses[j] = v[j].total;
    res.history = res.run_histories[j];
  }
}

void RefineRun::weigh_candidate(Renderer& renderer, RefineResult& res, ResultPrint& print) {
  // A shape-scan candidate replaces the start's basin only when, both converged, the evidence is clear enough
  // for how far it jumps (jump_is_supported): silhouette and depth barely tell such turns apart.
  const int candidate = lowest(res, options_.batch_size, int(best_.size()));
  if (candidate < 0) return;
  const double candidate_loss = res.run_losses[size_t(candidate)];
  if (!std::isfinite(res.loss.total) && std::isfinite(candidate_loss)) {
    take(res, candidate);  // every run from the starts left the image: the candidate is all there is
    res.scan_taken = true;
  } else if (std::isfinite(res.loss.total) && candidate_loss < res.loss.total) {
    const JumpEvidence basin{res.loss.total, print.at(renderer, res)};
    const JumpEvidence jump{candidate_loss, print_significance(renderer, best_pose_[size_t(candidate)])};
    if (jump_is_supported(basin, jump, jump_angle_[size_t(candidate)], options_.min_print_significance > 0)) {
      take(res, candidate);
      res.scan_taken = true;
      print.z = jump.print, print.known = true;
    }
  }
}

void RefineRun::align_result_print(Renderer& renderer, RefineResult& res, ResultPrint& print) {
  // The turn may cost up to kPrintLossTolerance of loss only because a mask or depth holds every other degree of
  // freedom: with RGB alone that loss is the print comparison itself, and a turn that moves the handle (unseen
  // without a mask) to where the print fits slightly better would be taken 30-40 degrees from the truth.
  const Observation& obs0 = fine_[0].obs;
  if (meshes_.size() != 1 || !std::isfinite(res.loss.total) || !obs0.has_texture() ||
      !(has_mask_ || obs0.has_depth()))
    return;
  LossOptions with_print = loss_;
  with_print.weight_texture = 1.0;
  const PrintEvaluator evaluate_print = [&](const std::vector<Pose>& poses, std::vector<LossValue>& out) {
    evaluate(renderer, poses, with_print, false, out, true);
  };
  Pose aligned = res.pose;
  bool turned = false;
  for (const ShapeRotation& axis : print_axes_) {
    const PrintAlignment a = align_print(aligned, axis, print_range_, loss_.weight_texture, evaluate_print);
    aligned = a.pose;
    turned = turned || a.angle != 0;
  }
  if (!turned) return;
  std::vector<LossValue> v;
  evaluate(renderer, {aligned}, loss_, false, v, true);
  const double angle = Eigen::AngleAxisd(res.pose.R.transpose() * aligned.R).angle();
  // The turns of several axes together may cost no more than one may (kPrintLossTolerance), and the print's
  // registration must not contradict the turn (turn_is_supported).
  if (v[0].total <= (1.0 + kPrintLossTolerance) * res.loss.total &&
      turn_is_supported(print.at(renderer, res), print_significance(renderer, aligned),
                        options_.min_print_significance > 0)) {
    res.print_turn = angle;
    res.pose = aligned;
    res.loss = v[0];
  }
}

int RefineRun::score_views(Renderer& renderer, RefineResult& res) const {
  // Quality scores at the refined pose, per view; the result's are the weakest view's.
  const bool one_view = meshes_.size() == 1;
  int rendered_pixels = 0;
  for (size_t v = 0; v < meshes_.size(); ++v) {
    const Camera& cam = fine_[v].cam;
    const Observation& obs = fine_[v].obs;
    RefineResult::ViewScores scores;
    const RenderImage img = renderer.render(cam, *meshes_[v], {res.pose}, obs.mask)[0];
    const cv::Mat rendered = img.coverage >= 0.5f;
    rendered_pixels += cv::countNonZero(rendered);
    if (has_mask_) {
      // Where the observed depth shows an occluder in front of the render (as the loss's mask term), the object
      // is hidden: its visible mask rightly leaves it out, so the render's IoU leaves it out too.
      cv::Mat visible = rendered;
      if (obs.has_depth() && loss_.occlusion_margin > 0) {
        cv::Mat in_front = (obs.depth > 0) & (obs.depth < img.depth - loss_.occlusion_margin);
        visible = rendered & ~in_front;
      }
      const cv::Mat observed_mask = obs.mask >= 0.5f;
      const double inter = cv::countNonZero(visible & observed_mask), uni = cv::countNonZero(visible | observed_mask);
      scores.mask_iou = uni > 0 ? inter / uni : 0.0;
    }
    if (obs.has_depth()) {
      // Over the observed object, or (without a mask) over what the render covers: the window is not the object.
      const cv::Mat object = (has_mask_ ? cv::Mat(obs.mask >= 0.5f) : rendered) & (obs.depth > 0);
      const int n = cv::countNonZero(object);
      cv::Mat diff;
      cv::absdiff(obs.depth, img.depth, diff);
      const cv::Mat inlier = object & (img.depth > 0) & (diff < options_.inlier_threshold);
      scores.depth_inliers = n > 0 ? double(cv::countNonZero(inlier)) / n : 0.0;
    }
    if (one_view && obs.has_rgb()) res.print = register_render(img);
    if (!one_view) {
      std::vector<LossValue> value;
      renderer.evaluate(cam, *meshes_[v], obs, {res.pose}, loss_, false, value);
      scores.loss = value[0].total;
    }
    const auto weakest = [](double a, double b) { return a < 0 ? b : b < 0 ? a : std::min(a, b); };
    res.mask_iou = v == 0 ? scores.mask_iou : weakest(res.mask_iou, scores.mask_iou);
    res.depth_inliers = v == 0 ? scores.depth_inliers : weakest(res.depth_inliers, scores.depth_inliers);
    if (!one_view) res.view_scores.push_back(scores);
  }
  return rendered_pixels;
}

void RefineRun::judge_result(Renderer& renderer, RefineResult& res, int rendered_pixels) const {
  const RefinerOptions& o = options_;
  const bool one_view = meshes_.size() == 1;
  const Mesh& mesh0 = *meshes_.front();
  if (one_view && o.probe_distance > 0 && std::isfinite(res.loss.total))
    res.curvature = probe_pose_curvature(renderer, fine_[0].cam, mesh0, fine_[0].obs, loss_, res.pose,
                                         o.probe_distance, mesh0.symmetry.free_twists(res.pose, res.pose * mesh0.center()));
  res.pivot = res.pose * pivot_model_;
  res.covariance = pose_covariance(res.curvature, rendered_pixels, diameter_);
  const size_t n = res.history.size(), tail = std::max<size_t>(2, n / 10);
  if (n >= tail) {
    const double a = res.history[n - tail], b = res.history.back();
    res.converged = std::abs(a - b) <= 0.01 * std::max(std::abs(a), 1e-12);
  }
  VerdictEvidence evidence;
  evidence.mask_iou = res.mask_iou;
  evidence.depth_inliers = res.depth_inliers;
  // A continuous declared symmetry turns the print with the object: it cannot be registered along that axis.
  if (one_view && mesh0.symmetry.continuous.empty()) evidence.print_significance = res.print.significance();
  const Verdict verdict = judge(evidence, o.min_mask_iou, o.min_depth_inliers, o.min_print_significance);
  res.plausible = std::isfinite(res.loss.total) && verdict.plausible;
  res.confidence = std::isfinite(res.loss.total) ? verdict.confidence : 0.0;
  res.time_ms = milliseconds_since(start_time_);
}

}  // namespace diffdope
