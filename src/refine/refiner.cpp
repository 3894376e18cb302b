// Algorithm 1 of Diff-DOPE with learning-rate randomisation, on top of the renderer backend.
#include "diffdope/refiner.hpp"

#include <cstdio>
#include <mutex>

#include "diffdope/device.hpp"
#include "diffdope/print_alignment.hpp"
#include "refine/refine_run.hpp"
#include "refine/refine_schedule.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

namespace diffdope {

Pose refiner_step(const Pose& pose, const Vector6d& g, double lr, double diameter, const Eigen::Vector3d& pivot) {
  // A twist about the pivot against the gradient, translation scaled by diameter^2 and rotation by 4.
  const Vector6d g_pivot = gradient_about(g, pivot);
  Vector6d step;
  step.head<3>() = -lr * diameter * diameter * g_pivot.head<3>();
  step.tail<3>() = -lr * 4.0 * g_pivot.tail<3>();
  return twist_about(pose, step, pivot);
}

Refiner::Refiner(const RefinerOptions& options) : options_(options) {
  options_.validate();
  std::string note;
  renderer_ = make_renderer(options_.device, options_.render, &note);  // "cuda" without a device throws
  static std::once_flag said;  // the auto fallback is said once per process, not per Refiner
  if (!note.empty()) std::call_once(said, [&] { std::fprintf(stderr, "diffdope: %s\n", note.c_str()); });
}

Refiner::Refiner(const RefinerOptions& options, std::unique_ptr<Renderer> renderer)
    : options_(options), renderer_(std::move(renderer)) {
  options_.validate();
  if (!renderer_) throw std::invalid_argument("Refiner: no renderer");
}

const RefinerOptions& Refiner::checked(const RefinerOptions& o) const {
  o.validate();
  if (o.device != options_.device)
    throw std::invalid_argument("device cannot change per call ('" + options_.device + "' -> '" + o.device +
                                "'): it needs a new Refiner");
  if (o.render != options_.render)
    throw std::invalid_argument("render options cannot change per call: they need a new Refiner");
  return o;
}

namespace {

/// An object's starts: its initial pose, then its alternatives.
std::vector<Pose> starts_of(const ObjectTarget& t) {
  std::vector<Pose> starts{t.initial};
  starts.insert(starts.end(), t.alternatives.begin(), t.alternatives.end());
  return starts;
}

/// The result of a refinement whose input was unusable: the start as it was, not plausible, and why.
RefineResult failed_result(const Pose& initial, const std::string& why) {
  RefineResult r;
  r.pose = r.initial_pose = initial;
  r.error = why;
  return r;
}

/// Whether the verdict weighs the print of `mesh`: not when turned off, nor about a continuous declared symmetry
/// (the print turns with the object).
bool weighs_print(const RefinerOptions& o, const Mesh& mesh) {
  return o.min_print_significance > 0 && mesh.symmetry.continuous.empty();
}

/// A rejected result and its retry's (RefinerOptions::retry_turn), the one retry_replaces() picks; initial_loss
/// stays the caller's starts' and time_ms covers both refinements.
RefineResult keep_better(RefineResult first, RefineResult retry, double time_ms, bool weigh_print) {
  const double initial_loss = first.initial_loss;
  RefineResult& kept = retry_replaces(first, retry, weigh_print) ? retry : first;
  kept.initial_loss = initial_loss;
  kept.evaluations = first.evaluations + retry.evaluations;
  for (size_t stage = 0; stage < size_t(kRefineStages); ++stage)
    kept.stage_evaluations[stage] = first.stage_evaluations[stage] + retry.stage_evaluations[stage];
  kept.retried = true;
  kept.time_ms = time_ms;
  return std::move(kept);
}

}  // namespace

RefinerOptions with_budget(const RefinerOptions& o, const RefineBudget& budget) {
  RefinerOptions out = o;
  out.batch_size = std::min(o.batch_size, budget.batch_size);
  out.iterations = std::min(o.iterations, budget.iterations);
  out.polish_iterations = std::min(o.polish_iterations, budget.polish_iterations);
  out.newton_rounds = std::min(o.newton_rounds, budget.newton_rounds);
  out.validate();
  return out;
}

std::vector<std::string> used_terms(const LossOptions& l) {
  std::vector<std::string> out;
  for (const auto& [name, weight] : {std::pair<const char*, double>{"rgb", l.weight_rgb}, {"depth", l.weight_depth},
                                     {"mask", l.weight_mask}, {"edges", l.weight_edges}, {"texture", l.weight_texture}})
    if (weight > 0) out.push_back(name);
  return out;
}

VerdictState verdict_state(const RefineResult& r) {
  if (!r.error.empty() || r.iterations == 0 || !r.judged) return VerdictState::kUndetermined;
  return r.plausible ? VerdictState::kPlausible : VerdictState::kImplausible;
}

const char* to_string(RefineStage stage) {
  switch (stage) {
    case RefineStage::kDescent: return "descent";
    case RefineStage::kWeighStarts: return "weigh_starts";
    case RefineStage::kWeighCandidate: return "weigh_candidate";
    case RefineStage::kDerivePixels: return "derive_pixels";
    case RefineStage::kPolish: return "polish";
    case RefineStage::kAlignPrintAndStep: return "align_print_and_step";
    case RefineStage::kWeighShapeTurns: return "weigh_shape_turns";
    case RefineStage::kScore: return "score";
  }
  return "?";
}

const char* to_string(VerdictState state) {
  switch (state) {
    case VerdictState::kPlausible: return "plausible";
    case VerdictState::kImplausible: return "implausible";
    case VerdictState::kUndetermined: return "undetermined";
  }
  return "?";
}

std::string undetermined_reason(const RefineResult& r) {
  if (!r.error.empty()) return "not refined: " + r.error;
  if (r.iterations == 0) return "not refined: no iteration run (iterations 0)";
  if (!r.judged)
    return "nothing could judge the pose: no mask, no depth, and a model without print to register (colour "
           "alone)";
  return "";
}

bool retry_replaces(const RefineResult& first, const RefineResult& retry, bool weigh_print) {
  if (!retry.error.empty() || !retry.plausible) return false;
  if (retry.loss.total < first.loss.total) return true;
  // The colour term compares a flat render with a lit image: a turned pose can fit the lighting better than the
  // truth does, and a better converged wrong basin then ends lower. The print tells them apart.
  const double z_first = first.print.significance(), z_retry = retry.print.significance();
  return weigh_print && std::isfinite(z_first) && std::isfinite(z_retry) &&
         z_retry - std::max(z_first, 0.0) >= kClearPrint;
}

void Refiner::prepare(const Mesh& mesh) {
  shape_rotations(mesh);
  print_axes(options_, mesh);
  // One small render, the object two diameters in front of the camera: the renderer takes in the mesh.
  const Camera camera(64, 64, 31.5, 31.5, 64, 64);
  const Pose pose(Eigen::Matrix3d::Identity(),
                  Eigen::Vector3d(0, 0, 2 * mesh.diameter() + options_.render.near_plane) - mesh.center().cast<double>());
  renderer_->render(camera, mesh, {pose}, cv::Mat());
}

RefineResult Refiner::refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                             const Pose& initial, const RefinerOptions& options) {
  return refine(camera, observed, mesh, std::vector<Pose>{initial}, options);
}

RefineResult Refiner::refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                             const std::vector<Pose>& initials, const RefinerOptions& options) {
  const RefinerOptions& o = checked(options);
  if (initials.empty()) return failed_result(Pose(), "refine: no initial pose");
  ObjectTarget target;
  target.mesh = &mesh;
  target.initial = initials.front();
  target.alternatives.assign(initials.begin() + 1, initials.end());
  target.mask = observed.mask;
  target.box = observed.box;
  return refine_targets(o, camera, observed, {target}, on_iteration).front();
}

bool Refiner::wants_retry(const RefinerOptions& o, const RefineResult& first) {
  return o.retry_turn > 0 && first.error.empty() && !first.plausible;
}

std::vector<Pose> Refiner::retry_starts(const RefinerOptions& o, const Mesh& mesh, const std::vector<Pose>& initials) {
  // The principal axes (through the centroid) the shape analysis turned about, each once.
  std::vector<ShapeRotation> axes;
  for (const ShapeRotation& c : shape_rotations(mesh)) {
    bool seen = false;
    for (const ShapeRotation& a : axes) seen = seen || std::abs(a.axis.dot(c.axis)) > std::cos(kSameAxisAngle);
    if (!seen) axes.push_back(ShapeRotation{c.axis, c.pivot, 0.0, 0.0});
  }
  std::vector<Pose> turns;
  for (ShapeRotation a : axes)
    for (const double angle : {o.retry_turn, 2 * M_PI - o.retry_turn}) {
      a.angle = angle;
      if (!is_declared_turn(o, mesh, a.as_pose())) turns.push_back(a.as_pose());
    }
  std::vector<Pose> starts = initials;
  for (const Pose& initial : initials)
    for (const Pose& turn : turns) starts.push_back(initial * turn);
  return starts;
}

namespace {

using Progress = Refiner::Progress;

/// The frame at the refiner's scales, shared by single-view runs (refine_all); null: each run evaluates its own
/// images (refine_views()).
struct SharedImages {
  const Observation* fine = nullptr;
  const Observation* coarse = nullptr;
};

/// Evaluates the steps of runs `which` (values[j] for steps[j]): on the shared `images` in one renderer call,
/// or each run alone without them. Returns per step the error that kept it from being evaluated (empty: none).
std::vector<std::string> evaluate_steps(Renderer& renderer, std::vector<std::unique_ptr<RefineRun>>& runs,
                                        const std::vector<size_t>& which, const std::vector<RefineRun::Step>& steps,
                                        const Observation* images, std::vector<std::vector<LossValue>>& values) {
  std::vector<std::string> errors(which.size());
  const auto alone = [&](size_t j, const auto& evaluate) {
    try {
      evaluate();
    } catch (const std::exception& e) {
      errors[j] = e.what();
    }
  };
  if (!images) {  // runs of their own images (several views): each alone
    for (size_t j = 0; j < which.size(); ++j)
      alone(j, [&] { runs[which[j]]->evaluate_step(renderer, steps[j], values[j]); });
    return errors;
  }
  // Every object's hypotheses in one renderer call (the CUDA backend launches them together); the objects share
  // the frame's scaled rgb / depth / edges, each brings its own mask.
  std::vector<ObjectBatch> batches(which.size());
  bool with_gradient = false;
  for (size_t j = 0; j < which.size(); ++j) {
    batches[j].mesh = &runs[which[j]]->mesh();
    batches[j].mask = steps[j].mask;
    batches[j].poses = steps[j].poses;
    batches[j].loss = steps[j].loss;
    with_gradient = with_gradient || steps[j].with_gradient;
  }
  const Camera& camera = *steps[0].camera;  // the same scaled camera for every object of the phase
  try {
    renderer.evaluate_objects(camera, *images, batches, with_gradient, values);
  } catch (const std::exception&) {
    // One object's input broke the joint call: evaluate them one by one so only that object fails.
    for (size_t j = 0; j < which.size(); ++j)
      alone(j, [&] {
        std::vector<std::vector<LossValue>> one;
        renderer.evaluate_objects(camera, *images, {batches[j]}, with_gradient, one);
        values[j] = std::move(one[0]);
      });
  }
  return errors;
}

/// The one driver: steps `runs` in lockstep until each is done, then finishes them. A run that throws gets its
/// first start and the reason as its result, and the others go on. `progress`: Refiner::on_iteration, or null.
std::vector<RefineResult> run_to_results(Renderer& renderer, std::vector<std::unique_ptr<RefineRun>>& runs,
                                         const SharedImages& shared, const Progress& progress) {
  std::vector<RefineResult> out(runs.size());
  const auto fail = [&](size_t k, const std::string& why) {
    out[k] = failed_result(runs[k]->first_start(), why);
    runs[k].reset();
  };
  std::vector<size_t> which;
  std::vector<RefineRun::Step> steps;
  std::vector<std::vector<LossValue>> values;
  for (bool any = true; any;) {
    any = false;
    // Runs in the coarse phase and runs in the fine phase are evaluated in separate calls (other images).
    for (const bool coarse : {true, false}) {
      which.clear();
      steps.clear();
      for (size_t k = 0; k < runs.size(); ++k) {
        if (!runs[k] || runs[k]->done() || runs[k]->coarse() != coarse) continue;
        try {
          steps.push_back(runs[k]->next_step(renderer));
          which.push_back(k);
        } catch (const std::exception& e) {
          fail(k, e.what());
        }
      }
      if (which.empty()) continue;
      any = true;
      const Observation* images = coarse ? shared.coarse : shared.fine;
      values.assign(which.size(), {});
      std::vector<std::string> errors = evaluate_steps(renderer, runs, which, steps, images, values);
      for (size_t j = 0; j < which.size(); ++j) {
        if (!errors[j].empty()) {
          fail(which[j], errors[j]);
          continue;
        }
        try {
          runs[which[j]]->absorb(steps[j], values[j], progress);
        } catch (const std::exception& e) {
          fail(which[j], e.what());
        }
      }
    }
  }
  for (size_t k = 0; k < runs.size(); ++k) {
    if (!runs[k]) continue;
    try {
      out[k] = runs[k]->finish(renderer);
    } catch (const std::exception& e) {
      fail(k, e.what());
    }
  }
  return out;
}

}  // namespace

RefineResult Refiner::refine_views(const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                                   const Eigen::Vector3d& pivot_model, const RefinerOptions& options) {
  const RefinerOptions& o = checked(options);
  std::vector<std::unique_ptr<RefineRun>> runs(1);
  try {
    if (!pivot_model.allFinite()) throw std::invalid_argument("refine_views: the pivot is not finite");
    runs[0] = std::make_unique<RefineRun>(o, views, initials, std::vector<Pose>{}, nullptr, nullptr, &pivot_model);
    runs[0]->set_polish(o.polish_iterations);
    runs[0]->set_newton(o.newton_rounds);
  } catch (const std::exception& e) {
    return failed_result(initials.empty() ? Pose() : initials.front(), e.what());
  }
  return run_to_results(*renderer_, runs, SharedImages{}, on_iteration).front();
}

const std::vector<ShapeRotation>& Refiner::shape_rotations(const Mesh& mesh) {
  auto cached = shape_rotations_.find(mesh.content_id());
  if (cached == shape_rotations_.end()) {
    if (shape_rotations_.size() >= kMaxCachedMeshes) shape_rotations_.clear();
    cached = shape_rotations_.emplace(mesh.content_id(), analyse_shape_rotations(mesh)).first;
  }
  return cached->second;
}

bool Refiner::is_declared_turn(const RefinerOptions& o, const Mesh& mesh, const Pose& turn) const {
  const double radius = 0.5 * mesh.diameter();
  return mesh.symmetry.contains(turn, kDeclaredTurnAngle, o.shape_tolerance * mesh.diameter(), radius);
}

std::vector<Pose> Refiner::shape_turns(const RefinerOptions& o, const Mesh& mesh, StartKind kind) {
  if (kind != StartKind::kFresh || !(o.shape_tolerance > 0) || mesh.content_id() == 0) return {};
  std::vector<Pose> turns;
  // A declared symmetry's turns look the same by design: no loss can choose among them.
  for (const ShapeRotation& r : ambiguous_rotations(shape_rotations(mesh), o.shape_tolerance, kMaxShapeTurns))
    if (!is_declared_turn(o, mesh, r.as_pose())) turns.push_back(r.as_pose());
  return turns;
}

std::vector<ShapeRotation> Refiner::print_axes(const RefinerOptions& o, const Mesh& mesh) {
  if (!(o.print_search > 0) || !(o.shape_tolerance > 0) || mesh.content_id() == 0) return {};
  std::vector<ShapeRotation> candidates = revolution_axes(shape_rotations(mesh), o.shape_tolerance);
  // The axis of revolution of most of the surface (a mug's body: no principal axis when a handle tilts them),
  // unless a principal one is already that axis.
  const auto key = std::make_pair(mesh.content_id(), o.shape_tolerance);
  auto fitted = revolution_fits_.find(key);
  if (fitted == revolution_fits_.end()) {
    if (revolution_fits_.size() >= kMaxCachedMeshes) revolution_fits_.clear();
    fitted = revolution_fits_.emplace(key, fit_revolution_axis(mesh, o.shape_tolerance)).first;
  }
  // Several principal axes of revolution (a ball): every direction is one; the fit adds nothing.
  if (fitted->second && candidates.size() < 2) {
    const ShapeRotation& f = *fitted->second;
    const double same_direction = std::cos(kSameAxisAngle), same_line = kSameAxisOffset * mesh.diameter();
    bool added = false;
    for (ShapeRotation& c : candidates)
      if (std::abs(c.axis.dot(f.axis)) > same_direction) {
        // The same axis, unless the principal one runs beside it (its centroid pulled off by an appendage):
        // then the fitted one, about which most of the surface turns into itself.
        if ((f.pivot - c.pivot).cross(c.axis).norm() > same_line) c = f;
        added = true;
      }
    if (!added) candidates.push_back(f);
  }
  // About a declared continuous symmetry the print turns with the object: nothing to align.
  std::vector<ShapeRotation> axes;
  for (const ShapeRotation& c : candidates) {
    ShapeRotation turn = c;
    turn.angle = 2 * M_PI / kShapeAngleSteps;  // (the analysis' step)
    if (!is_declared_turn(o, mesh, turn.as_pose())) axes.push_back(c);
  }
  return axes;
}

std::vector<RefineResult> Refiner::refine_all(const Camera& camera, const Observation& frame,
                                              const std::vector<ObjectTarget>& objects,
                                              const RefinerOptions& options) {
  return refine_targets(checked(options), camera, frame, objects, nullptr);
}

std::vector<RefineResult> Refiner::refine_targets(const RefinerOptions& o, const Camera& camera,
                                                  const Observation& frame, const std::vector<ObjectTarget>& objects,
                                                  const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  std::vector<RefineResult> out = refine_pass(o, camera, frame, objects, progress);
  // The rejected objects (not tracked starts) again, in lockstep among themselves, from turned starts.
  std::vector<ObjectTarget> again;
  std::vector<size_t> which;
  for (size_t k = 0; k < objects.size(); ++k) {
    if (objects[k].start_kind != StartKind::kFresh || !objects[k].mesh || !wants_retry(o, out[k])) continue;
    ObjectTarget t = objects[k];
    const std::vector<Pose> starts = retry_starts(o, *t.mesh, starts_of(t));
    t.alternatives.assign(starts.begin() + 1, starts.end());
    again.push_back(std::move(t));
    which.push_back(k);
  }
  if (again.empty()) return out;
  // The retry's starts are the same input turned: what the first pass accepted, it accepts.
  std::vector<RefineResult> retried = refine_pass(o, camera, frame, again, progress);
  const double ms = milliseconds_since(start);
  for (size_t j = 0; j < which.size(); ++j)
    out[which[j]] =
        keep_better(std::move(out[which[j]]), std::move(retried[j]), ms, weighs_print(o, *objects[which[j]].mesh));
  return out;
}

std::vector<RefineResult> Refiner::refine_pass(const RefinerOptions& options, const Camera& camera,
                                               const Observation& frame, const std::vector<ObjectTarget>& objects,
                                               const Progress& progress) {
  // The frame is resized (and its edges found) once for all objects. A frame that does not fit the camera is
  // reported by each object's own check below.
  std::optional<Observation> fine_frame, coarse_frame;
  try {
    fine_frame = scale_frame(camera, frame, options, options.image_scale, Phase::kFine);
    if (coarse_iterations(options) > 0)
      coarse_frame = scale_frame(camera, frame, options, options.image_scale * options.coarse_scale, Phase::kCoarse);
  } catch (const std::invalid_argument&) {
  }
  const SharedImages shared{fine_frame ? &*fine_frame : nullptr, coarse_frame ? &*coarse_frame : nullptr};
  std::vector<RefineResult> out(objects.size());
  std::vector<std::unique_ptr<RefineRun>> runs(objects.size());
  std::vector<RefinerOptions> object_options(objects.size(), options);  // (each run holds its own by reference)
  for (size_t k = 0; k < objects.size(); ++k) {
    const ObjectTarget& t = objects[k];
    try {
      if (!t.mesh) throw std::invalid_argument("no mesh");
      if (t.budget) object_options[k] = with_budget(options, *t.budget);
      const RefinerOptions& o_k = object_options[k];
      const Observation o =
          frame.with_mask(t.mask.empty() || t.mask.type() == CV_32FC1 ? t.mask : to_mask_float(t.mask), t.box);
      runs[k] = std::make_unique<RefineRun>(o_k, camera, o, *t.mesh, starts_of(t),
                                            shape_turns(o_k, *t.mesh, t.start_kind), shared.fine, shared.coarse);
      const bool fresh = t.start_kind == StartKind::kFresh;
      runs[k]->set_print_axes(print_axes(o_k, *t.mesh),
                              fresh ? o_k.print_search : std::min(o_k.print_search, kTrackedPrintSearch));
      runs[k]->set_polish(fresh ? o_k.polish_iterations : 0);
      runs[k]->set_newton(o_k.newton_rounds);
      runs[k]->set_tracked_start(!fresh);
      if (!fresh) runs[k]->set_carried_curvature(t.carried_curvature);
    } catch (const std::exception& e) {
      out[k] = failed_result(t.initial, e.what());
    }
  }
  if (!shared.fine) return out;  // every object has failed its check
  std::vector<RefineResult> results = run_to_results(*renderer_, runs, shared, progress);
  for (size_t k = 0; k < runs.size(); ++k)
    if (out[k].error.empty()) out[k] = std::move(results[k]);
  return out;
}

namespace {

long descent_evaluations(const RefinerOptions& o) {
  long total = 0;
  int active = std::max(o.batch_size, 1), candidates = 0, halvings = 0;
  const int scan_at = scan_iteration(o);  // with as many turns as any shape gets
  for (int k = 0; k <= o.iterations; ++k) {  // as RefineRun::next_step(): k == iterations only evaluates
    for (const int due = halvings_due(k, o.iterations); o.successive_halving && k < o.iterations && halvings < due;
         ++halvings)
      active = (active + 1) / 2, candidates = (candidates + 1) / 2;
    if (k == scan_at && k < o.iterations) {
      total += long(active) * (1 + kMaxShapeTurns);
      candidates = std::min({active, kMaxShapeTurns, kScanCandidates});  // runs from preferred turns
    }
    total += active + candidates;
  }
  const long batch = std::max(o.batch_size, 1);
  return total + (o.derive_mask ? batch + (batch + 1) / 2 : 0);
}

bool scans(const RefinerOptions& o) {
  const int scan_at = scan_iteration(o);
  return scan_at >= 0 && scan_at < o.iterations;
}

// The polish, then the print alignment and the Newton steps (both again when the steps moved far).
long converge_evaluations(const RefinerOptions& o) {
  return planned_evaluations(o, RefineStage::kPolish) + planned_evaluations(o, RefineStage::kAlignPrintAndStep);
}

}  // namespace

long planned_evaluations(const RefinerOptions& o, RefineStage stage) {
  switch (stage) {
    case RefineStage::kDescent:
      return descent_evaluations(o);
    case RefineStage::kWeighStarts:
      return 1;
    case RefineStage::kWeighCandidate:
      return scans(o) ? 2 : 0;
    case RefineStage::kDerivePixels:
      return o.derive_mask ? 2 + std::max(o.batch_size, 1) : 0;
    case RefineStage::kPolish:
      return o.polish_iterations > 0 && o.iterations > 0 ? 1 + long(o.polish_runs) * o.polish_iterations : 0;
    case RefineStage::kAlignPrintAndStep: {
      // The alignment about one axis, then the loss and the registration at its turn, and the registration at the
      // result when not measured yet; the Newton steps' render for the pixel count, then per round a probe and
      // three tries.
      const long print =
          o.shape_tolerance > 0 && o.iterations > 0 ? print_alignment_evaluations(o.print_search) + 3 : 0;
      const long newton =
          o.newton_rounds > 0 && o.iterations > 0 ? 1 + long(o.newton_rounds) * (kSecantProbePoses + 3) : 0;
      return (print > 0 && newton > 0 ? kAlignmentPasses : 1) * (print + newton);
    }
    case RefineStage::kWeighShapeTurns:
      // The registration at the result and at each turn, the loss at the one it prefers, the convergence from there
      // and the registration where it ends. With or without the scan (a single iteration has none, and the turns
      // are weighed all the same).
      return o.shape_tolerance > 0 && o.min_print_significance > 0 && o.iterations > 0
                 ? kMaxShapeTurns + 3 + converge_evaluations(o)
                 : 0;
    case RefineStage::kScore:
      return 1 + (o.probe_distance > 0 ? kCurvatureProbeEvaluations : 0);
  }
  return 0;
}

long planned_evaluations(const RefinerOptions& o) {
  long total = 0;
  for (int stage = 0; stage < kRefineStages; ++stage) total += planned_evaluations(o, RefineStage(stage));
  return total;
}

}  // namespace diffdope
