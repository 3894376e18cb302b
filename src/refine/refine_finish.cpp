// RefineRun::finish() (refine_run.hpp): the choice between the start's basin and the shape scan's candidate, the
// polish, the print alignment, the Newton steps, and the result's scores and verdict.
#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "diffdope/pose_curvature.hpp"
#include "diffdope/print_alignment.hpp"
#include "refine/refine_run.hpp"
#include "refine/refine_schedule.hpp"

namespace diffdope {

PrintRegistration RefineRun::register_render(const RenderImage& img) const {
  const Observation& obs = fine_[0].obs;
  if (meshes_.size() != 1 || !obs.has_rgb()) return PrintRegistration();
  // The object's interior where the observation shows it: inside the render's full coverage
  // (kPrintInteriorMargin) and, with a mask, inside the observed mask.
  cv::Mat interior = img.coverage >= 0.999f;
  if (has_mask_) interior &= cv::Mat(obs.mask >= 0.5f);
  const int side = 2 * kPrintInteriorMargin + 1;
  cv::erode(interior, interior, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(side, side)));
  return register_print(obs.rgb, img.color, interior, kPrintShiftRadius, loss_.texture_epsilon);
}

double RefineRun::print_significance(Renderer& renderer, const Pose& pose) {
  // A continuous declared symmetry turns the print with the object: it cannot be registered along that axis.
  if (meshes_.size() != 1 || !fine_[0].obs.has_rgb() || !meshes_[0]->symmetry.continuous.empty())
    return std::numeric_limits<double>::quiet_NaN();
  return register_render(render_view(renderer, 0, pose)).significance();
}

double jump_margin(double angle) { return kJumpMargin * (1.0 + 4.0 * std::abs(angle) / M_PI); }

bool jump_is_supported(const JumpEvidence& from, const JumpEvidence& to, double angle, double min_print_significance) {
  if (!(to.loss < from.loss)) return false;
  const bool weigh_print = min_print_significance > 0;
  if (weigh_print && std::isfinite(from.print) && !std::isfinite(to.print)) return false;  // the print is lost
  const bool weighed = weigh_print && std::isfinite(from.print) && std::isfinite(to.print);
  if (weighed && to.print < from.print - kPrintContradiction) return false;
  const double need = print_jump_bar(angle);
  if (weighed && to.print >= need && to.print - std::max(from.print, 0.0) >= need) return true;
  if (weighed && to.print < min_print_significance) return false;
  if (std::abs(angle) > kLossJumpMaxAngle) return false;
  return to.loss < (1.0 - jump_margin(angle)) * from.loss;
}

bool turn_is_supported(double z_from, double z_to, double min_significance) {
  if (!(min_significance > 0) || !std::isfinite(z_from)) return true;
  return std::isfinite(z_to) && z_to >= z_from - kPrintContradiction && z_to >= min_significance;
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
      evaluate_fine(renderer, {res.pose}, loss_, Gradients::kCompute, v);
      const LossValue first = v[0];
      v.assign(poses.size(), first);
    } else {
      evaluate_fine(renderer, poses, loss_, k < iters ? Gradients::kCompute : Gradients::kSkip, v);
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

double RefineRun::residual_count(Renderer& renderer, const Pose& pose) {
  // The pixels the loss compares at `pose` (the observed mask, or without one the window about the start, and
  // the render), in every view.
  double pixels = 0;
  for (size_t v = 0; v < meshes_.size(); ++v) {
    const RenderImage img = render_view(renderer, v, pose);
    pixels += cv::countNonZero((fine_[v].obs.mask >= 0.5f) | (img.coverage >= 0.5f));
  }
  return std::max(1.0, pixels / kCorrelatedPixels);
}

void RefineRun::newton(Renderer& renderer, RefineResult& res) {
  if (newton_rounds_ <= 0 || options_.iterations == 0 || !std::isfinite(res.loss.total)) return;
  Matrix6d metric = Matrix6d::Zero();
  for (const Mesh* mesh : meshes_) metric += surface_displacement_metric(*mesh, res.pose.R, pivot_model_);
  const Eigen::LLT<Matrix6d> llt(metric / double(meshes_.size()));
  if (llt.info() != Eigen::Success) return;
  const Matrix6d L = llt.matrixL(), Linv = L.inverse(), LinvT = Linv.transpose();
  const double residuals = residual_count(renderer, res.pose);
  // The first probe reaches one working pixel at the object's distance: the scale below which the plain steps'
  // hopping and the antialiased silhouette blur the loss. The trust radius is twice the probe's reach: a round
  // whose whole step was held back by it (the loss's valley goes on) doubles both, up to a quarter of the
  // object's diameter; any other round halves them. A round without a clear gain (or whose probe left the image)
  // ends the steps, unless the reach had grown: it is then tried again at half.
  const Camera& cam = fine_[0].cam;
  const double first_reach = (res.pose * pivot_model_).z() / std::max(cam.fx, cam.fy);
  const double max_reach = std::max(first_reach, kNewtonMaxReach * diameter_);
  double h = first_reach;
  std::vector<Vector6d> free;  // a declared symmetry's free twists, whitened (as the curvature probe leaves out)
  if (meshes_.size() == 1)
    for (const Vector6d& f : meshes_[0]->symmetry.free_twists(res.pose, res.pose * pivot_model_)) free.push_back(L.transpose() * f);
  std::vector<LossValue> v, tried;
  std::vector<Vector6d> gradients(kSecantProbePoses);
  for (int round = 0; round < newton_rounds_ && h > 0; ++round) {
    const Eigen::Vector3d pivot = res.pose * pivot_model_;
    evaluate_fine(renderer, secant_probe_poses(res.pose, LinvT, h, pivot), loss_, Gradients::kCompute, v);
    const bool probed = std::all_of(v.begin(), v.end(), [](const LossValue& x) { return std::isfinite(x.total); });
    Vector6d step = Vector6d::Zero();  // (zero: a probe left the image, or nothing curves upwards)
    const double trust = kNewtonTrustPerReach * h;
    Matrix6d Hq = Matrix6d::Zero();
    if (probed) {
      for (int k = 0; k < kSecantProbePoses; ++k) gradients[size_t(k)] = gradient_about(v[size_t(k)].gradient, pivot);
      Hq = secant_hessian(gradients, Linv, h);
      step = newton_step(Hq, Linv * gradients.back(), trust, free);
    }
    std::vector<Pose> poses;
    size_t best = 0;
    double gain = 0;
    if (!step.isZero()) {
      for (const double share : kNewtonStepShares) poses.push_back(twist_about(res.pose, share * (LinvT * step), pivot));
      evaluate_fine(renderer, poses, loss_, Gradients::kCompute, tried);
      for (size_t j = 1; j < poses.size(); ++j)
        if (std::isfinite(tried[j].total) && !(tried[best].total <= tried[j].total)) best = j;  // (never a non-finite one)
      gain = residuals * (res.loss.total - tried[best].total) / std::max(res.loss.total, 1e-12);
    }
    if (!(gain > kNewtonEvidence)) {
      if (h <= first_reach) return;
      h *= 0.5;
      continue;
    }
    res.pose = poses[best];
    res.loss = tried[best];
    ++res.newton_steps;
    const bool held_back = best + 1 == poses.size() && step.norm() >= (1.0 - 1e-3) * trust;
    // Another round gains at most what this round's quadratic model promises from the gradient where the step
    // ended (the secant underestimates the curvature of the L1 terms' kinks, so the promise is generous): below
    // the evidence a step needs, the round is not made. A step the trust radius held back has its valley ahead.
    const Vector6d g_next = Linv * gradient_about(res.loss.gradient, res.pose * pivot_model_);
    const double promised = residuals * newton_decrease(Hq, g_next, free) / std::max(res.loss.total, 1e-12);
    if (!held_back && promised < kNewtonEvidence) return;
    h = held_back ? std::min(2 * h, max_reach) : 0.5 * h;
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

namespace {
bool same_pose(const Pose& a, const Pose& b) { return a.R == b.R && a.t == b.t; }
}  // namespace

double RefineRun::Candidate::print(Renderer& renderer) {
  if (pixels_ != run_.pixels_version_ || !same_pose(result.pose, measured_))
    set_print(run_.print_significance(renderer, result.pose));
  return z_;
}

void RefineRun::Candidate::set_print(double significance) {
  measured_ = result.pose;
  pixels_ = run_.pixels_version_;
  z_ = significance;
}

namespace {

/// Books the evaluations made (a running count) to each stage as it ends.
class StageLedger {
 public:
  StageLedger(std::array<long, kRefineStages>& booked, const long& made) : booked_(booked), made_(made) {}
  void end(RefineStage stage) {
    booked_[size_t(stage)] += made_ - at_;
    at_ = made_;
  }

 private:
  std::array<long, kRefineStages>& booked_;
  const long& made_;
  long at_ = 0;
};

}  // namespace

RefineResult RefineRun::finish(Renderer& renderer) {
  Candidate c = start_candidate();
  RefineResult& res = c.result;
  StageLedger ledger(res.stage_evaluations, evaluations_);
  ledger.end(RefineStage::kDescent);
  if (switch_at_ > 0) weigh_starts(renderer, c);
  ledger.end(RefineStage::kWeighStarts);
  weigh_candidate(renderer, c);
  ledger.end(RefineStage::kWeighCandidate);
  derive_pixels_at_result(renderer, c);
  ledger.end(RefineStage::kDerivePixels);
  polish(renderer, res);
  ledger.end(RefineStage::kPolish);
  align_print_and_step(renderer, c);
  ledger.end(RefineStage::kAlignPrintAndStep);
  weigh_shape_turns(renderer, c);
  ledger.end(RefineStage::kWeighShapeTurns);
  // Of the poses a declared symmetry makes equivalent, the one nearest the start: a track does not spin.
  if (meshes_.size() == 1) res.pose = meshes_.front()->symmetry.nearest_equivalent(res.pose, res.initial_pose.R);
  judge_result(renderer, res, meshes_.size() == 1 ? score_view(renderer, res) : score_views(renderer, res));
  ledger.end(RefineStage::kScore);
  return std::move(res);
}

RefineRun::Candidate RefineRun::start_candidate() {
  RefineResult res = std::move(res_);
  const int runs = int(best_.size());
  res.run_losses.resize(size_t(runs));
  for (int i = 0; i < runs; ++i) res.run_losses[size_t(i)] = best_[size_t(i)].total;
  res.run_poses = best_pose_;
  take(res, lowest(res, 0, options_.batch_size));  // the start's own basin
  return Candidate(*this, std::move(res));
}

void RefineRun::derive_pixels_at_result(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  if (!derives_pixels_ || !std::isfinite(res.loss.total) ||
      !derive_pixels(renderer, {res.pose}, options_.inlier_threshold))
    return;
  // The object's pixels about the chosen result, within what the verdict calls an inlier: the polish, the print
  // alignment, the Newton steps and the scores weigh them. Losses under other pixels do not compare: the result's
  // and the starts' again (a start no run beat stays the result).
  res.loss_used.rgb_miss = loss_.rgb_miss;  // (from colour, the render's colour error on them)
  std::vector<LossValue> v;
  evaluate_fine(renderer, {res.pose}, loss_, Gradients::kSkip, v);
  res.loss = v[0];
  weigh_starts(renderer, c);
}

void RefineRun::align_print_and_step(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  for (int pass = 0; pass < kAlignmentPasses; ++pass) {
    const Pose before = res.pose;
    align_result_print(renderer, c);
    if (pass > 0 && same_pose(res.pose, before)) return;  // nothing turned: the steps have converged there
    const double aligned_loss = res.loss.total;
    newton(renderer, res);
    // Steps that went on well past what the alignment compared its turns against: it weighed the turns of a
    // result that was not yet converged. Once more from the converged one.
    if (!(res.loss.total < (1.0 - kPrintLossTolerance) * aligned_loss)) return;
  }
}

void RefineRun::weigh_starts(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  // The first iteration was at the coarse scale: the initial loss at the fine one, of the starts that got a run
  // (as at k = 0).
  std::vector<LossValue> v;
  const int starts = std::min(int(initials_.size()), options_.batch_size);
  const std::vector<Pose> started(initials_.begin(), initials_.begin() + starts);
  evaluate_fine(renderer, started, loss_, Gradients::kSkip, v);
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

void RefineRun::weigh_candidate(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  // A shape-scan candidate replaces the start's basin only when, both converged, the evidence is clear enough
  // for how far it jumps (jump_is_supported): silhouette and depth barely tell such turns apart.
  const int candidate = lowest(res, options_.batch_size, int(best_.size()));
  if (candidate < 0) return;
  const double candidate_loss = res.run_losses[size_t(candidate)];
  if (!std::isfinite(res.loss.total) && std::isfinite(candidate_loss)) {
    take(res, candidate);  // every run from the starts left the image: the candidate is all there is
    res.scan_taken = true;
  } else if (std::isfinite(res.loss.total) && candidate_loss < res.loss.total) {
    const JumpEvidence basin{res.loss.total, c.print(renderer)};
    const JumpEvidence jump{candidate_loss, print_significance(renderer, best_pose_[size_t(candidate)])};
    if (jump_is_supported(basin, jump, jump_angle_[size_t(candidate)], options_.min_print_significance)) {
      take(res, candidate);
      res.scan_taken = true;
      c.set_print(jump.print);
    }
  }
}

void RefineRun::align_result_print(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  // The turn may cost up to kPrintLossTolerance of loss only because a mask or depth holds every other degree of
  // freedom: with RGB alone that loss is the print comparison itself, and a turn that moves the handle (unseen
  // without a mask) to where the print fits slightly better would be taken 30-40 degrees from the truth.
  const Observation& obs0 = fine_[0].obs;
  if (meshes_.size() != 1 || options_.iterations == 0 || !std::isfinite(res.loss.total) || !obs0.has_texture() ||
      !(has_mask_ || obs0.has_depth()))
    return;  // (0 iterations: score the start)
  LossOptions with_print = loss_;
  with_print.weight_texture = 1.0;
  const PrintEvaluator evaluate_print = [&](const std::vector<Pose>& poses, std::vector<LossValue>& out) {
    evaluate_fine(renderer, poses, with_print, Gradients::kSkip, out);
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
  evaluate_fine(renderer, {aligned}, loss_, Gradients::kSkip, v);
  const double angle = Eigen::AngleAxisd(res.pose.R.transpose() * aligned.R).angle();
  // The turns of several axes together may cost no more than one may (kPrintLossTolerance), and the print's
  // registration must not contradict the turn, and must register where it turned (turn_is_supported).
  if (!(v[0].total <= (1.0 + kPrintLossTolerance) * res.loss.total)) return;
  const double z_aligned = print_significance(renderer, aligned);
  if (!turn_is_supported(c.print(renderer), z_aligned, options_.min_print_significance)) return;
  res.print_turn += angle;
  res.pose = aligned;
  res.loss = v[0];
  c.set_print(z_aligned);
}

double print_jump_bar(double angle) { return kClearPrint * (1.0 + std::abs(angle) / M_PI); }

void RefineRun::weigh_shape_turns(Renderer& renderer, Candidate& c) {
  RefineResult& res = c.result;
  // The scan compared the shape-equivalent turns early, by a loss that barely sees the print, and a hard start
  // (or a detector's cuboid, ambiguous by the same turns) can converge on a box's back face. Between such poses
  // silhouette and depth cannot decide; the print and the colour can, once converged. Only with a mask or depth:
  // they hold the other degrees of freedom while it converges from the turn (with RGB alone the colour term would
  // be the print comparison itself, as for the print alignment).
  const bool held = has_mask_ || fine_[0].obs.has_depth();
  if (turns_.empty() || !held || !(options_.min_print_significance > 0) || options_.iterations == 0 ||
      !std::isfinite(res.loss.total))
    return;  // (0 iterations: score the start)
  const double z = c.print(renderer);
  if (!std::isfinite(z)) return;
  int best = -1;
  double best_z = z;
  for (size_t t = 0; t < turns_.size(); ++t) {
    const double z_t = print_significance(renderer, res.pose * turns_[t]);
    if (z_t > best_z) best = int(t), best_z = z_t;
  }
  if (best < 0) return;
  // The turn the print prefers, converged as the result was (polish, print alignment, Newton steps).
  Candidate turned_candidate(*this, res);
  RefineResult& turned = turned_candidate.result;
  turned.pose = res.pose * turns_[size_t(best)];
  std::vector<LossValue> v;
  evaluate_fine(renderer, {turned.pose}, loss_, Gradients::kSkip, v);
  turned.loss = v[0];
  polish(renderer, turned);
  align_print_and_step(renderer, turned_candidate);
  const double z_turned = turned_candidate.print(renderer);
  if (!std::isfinite(turned.loss.total) || !std::isfinite(z_turned)) return;
  const double turn = Eigen::AngleAxisd(res.pose.R.transpose() * turned.pose.R).angle();
  // It replaces the result when its print registers clearly better: converged, silhouette and depth fit both alike.
  if (z_turned >= kClearPrint && z_turned - std::max(z, 0.0) >= kClearPrint) {
    turned.shape_turn = turn;
    turned.rival_print = z;
    res = std::move(turned);
    c.set_print(z_turned);
    return;
  }
  // Otherwise it is the result's rival when it stayed a pose of its own (one that converged back nearer the
  // result than to where it was turned, as the print alignment undoes a small turn about a bottle's axis, is the
  // result again) and the loss does not prefer the result: the verdict weighs their prints.
  const double turned_by = Eigen::AngleAxisd(turns_[size_t(best)].R).angle();
  if (turn > 0.5 * turned_by && turned.loss.total <= res.loss.total) res.rival_print = z_turned;
}

RefineResult::ViewScores RefineRun::view_scores(const RenderImage& img, size_t v) const {
  const Observation& obs = fine_[v].obs;
  RefineResult::ViewScores scores;
  const cv::Mat rendered = img.coverage >= 0.5f;
  if (has_mask_) {
    // Where the observed depth shows an occluder in front of the render (as the loss's mask term), the object is
    // hidden: its visible mask rightly leaves it out, so the render's IoU leaves it out too.
    cv::Mat visible = rendered;
    if (obs.has_depth() && loss_.occlusion_margin > 0) {
      cv::Mat in_front = (obs.depth > 0) & (obs.depth < img.depth - loss_.occlusion_margin);
      visible = rendered & ~in_front;
    }
    cv::Mat observed_mask = obs.mask >= 0.5f;
    if (mask_from_depth_[v] && obs.has_depth()) {  // a sensor's dropouts: neither the object's nor not
      const cv::Mat reading = obs.depth > 0;
      visible = visible & reading;
      observed_mask = observed_mask & reading;
    }
    const double inter = cv::countNonZero(visible & observed_mask), uni = cv::countNonZero(visible | observed_mask);
    scores.mask_iou = uni > 0 ? inter / uni : 0.0;
  }
  if (obs.has_depth()) {
    // Over the observed object, or (without a mask) over what the render covers: the window is not the object.
    const cv::Mat object = has_mask_ ? cv::Mat(obs.mask >= 0.5f) : rendered;
    const DepthAgreement agreement =
        depth_agreement(obs.depth, img.depth, object, options_.inlier_threshold, options_.max_depth_noise);
    scores.depth_inliers = std::max(agreement.inliers, 0.0);
    scores.depth_noise = agreement.noise_at_1m;
  }
  return scores;
}

RenderImage RefineRun::render_view(Renderer& renderer, size_t v, const Pose& pose) {
  ++evaluations_;
  return renderer.render(fine_[v].cam, *meshes_[v], {pose}, fine_[v].obs.mask)[0];
}

int RefineRun::score_view(Renderer& renderer, RefineResult& res) {
  const RenderImage img = render_view(renderer, 0, res.pose);
  const RefineResult::ViewScores scores = view_scores(img, 0);
  res.mask_iou = scores.mask_iou;
  res.depth_inliers = scores.depth_inliers;
  res.depth_noise = std::max(res.depth_noise, scores.depth_noise);
  if (fine_[0].obs.has_rgb()) res.print = register_render(img);
  return cv::countNonZero(img.coverage >= 0.5f);
}

int RefineRun::score_views(Renderer& renderer, RefineResult& res) {
  // Each view's scores and loss; the result's scores are the weakest view's (-1: not measured in any).
  const auto weakest = [](double a, double b) { return a < 0 ? b : b < 0 ? a : std::min(a, b); };
  int rendered_pixels = 0;
  for (size_t v = 0; v < meshes_.size(); ++v) {
    const RenderImage img = render_view(renderer, v, res.pose);
    rendered_pixels += cv::countNonZero(img.coverage >= 0.5f);
    RefineResult::ViewScores scores = view_scores(img, v);
    std::vector<LossValue> value;
    renderer.evaluate(fine_[v].cam, *meshes_[v], fine_[v].obs, {res.pose}, loss_, false, value);
    ++evaluations_;
    scores.loss = value[0].total;
    res.mask_iou = v == 0 ? scores.mask_iou : weakest(res.mask_iou, scores.mask_iou);
    res.depth_inliers = v == 0 ? scores.depth_inliers : weakest(res.depth_inliers, scores.depth_inliers);
    res.depth_noise = std::max(res.depth_noise, scores.depth_noise);
    res.view_scores.push_back(scores);
  }
  return rendered_pixels;
}

void RefineRun::probe_curvature(Renderer& renderer, RefineResult& res) {
  const double distance = options_.probe_distance;
  if (!(distance > 0) || !std::isfinite(res.loss.total)) return;
  if (meshes_.size() == 1 && carried_curvature_) {
    const Mesh& mesh = *meshes_[0];
    const std::vector<Vector6d> free = mesh.symmetry.free_twists(res.pose, res.pose * mesh.center());
    res.curvature = carry_pose_curvature(renderer, {{fine_[0].cam, mesh, fine_[0].obs}}, loss_,
                                         carried_curvature_->curvature, carried_curvature_->pose, res.pose,
                                         mesh.center(), distance, free);
    res.curvature_carried = true;
    evaluations_ += kCarriedCurvatureEvaluations;
    return;
  }
  if (meshes_.size() == 1) {
    const Mesh& mesh = *meshes_[0];
    res.curvature = probe_pose_curvature(renderer, fine_[0].cam, mesh, fine_[0].obs, loss_, res.pose, distance,
                                         mesh.symmetry.free_twists(res.pose, res.pose * mesh.center()));
  } else {  // views of one pose (a calibration's captures): their mean loss, about the common pivot
    std::vector<ProbeView> views;
    for (size_t v = 0; v < meshes_.size(); ++v) views.push_back({fine_[v].cam, *meshes_[v], fine_[v].obs});
    res.curvature = probe_pose_curvature(renderer, views, loss_, res.pose, pivot_model_, distance);
  }
  evaluations_ += long(kCurvatureProbeEvaluations * meshes_.size());
}

void RefineRun::judge_result(Renderer& renderer, RefineResult& res, int rendered_pixels) {
  const RefinerOptions& o = options_;
  probe_curvature(renderer, res);
  res.pivot = res.pose * pivot_model_;
  res.covariance = pose_covariance(res.curvature, rendered_pixels, diameter_);
  const size_t n = res.history.size(), tail = std::max<size_t>(2, n / kConvergedTailDivisor);
  if (n >= tail) {
    const double a = res.history[n - tail], b = res.history.back();
    res.converged = std::abs(a - b) <= kConvergedChange * std::max(std::abs(a), 1e-12);
  }
  VerdictEvidence evidence;
  evidence.mask_iou = res.mask_iou;
  evidence.depth_inliers = res.depth_inliers;
  // The print is registered in one view only; a continuous declared symmetry turns it with the object, so it
  // cannot be registered along that axis.
  if (meshes_.size() == 1 && meshes_[0]->symmetry.continuous.empty()) {
    evidence.print_significance = res.print.significance();
    evidence.rival_print_significance = res.rival_print;
  }
  const Verdict verdict = judge(evidence, o.min_mask_iou, o.min_depth_inliers, o.min_print_significance);
  res.judged = verdict.judged;
  res.plausible = std::isfinite(res.loss.total) && verdict.plausible;
  res.confidence = std::isfinite(res.loss.total) ? verdict.confidence : 0.0;
  res.time_ms = milliseconds_since(start_time_);
  res.evaluations = evaluations_;
}

}  // namespace diffdope
