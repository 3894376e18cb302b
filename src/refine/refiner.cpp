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
  kept.retried = true;
  kept.time_ms = time_ms;
  return std::move(kept);
}

}  // namespace

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
  const auto start = std::chrono::steady_clock::now();
  RefineResult first;
  try {
    first = refine_once(o, camera, observed, mesh, initials);
  } catch (const std::exception& e) {
    return failed_result(initials.empty() ? Pose() : initials.front(), e.what());
  }
  if (!wants_retry(o, first)) return first;
  // The retry's starts are the same input turned: what the first pass accepted, it accepts.
  RefineResult retry = refine_once(o, camera, observed, mesh, retry_starts(o, mesh, initials));
  return keep_better(std::move(first), std::move(retry), milliseconds_since(start), weighs_print(o, mesh));
}

RefineResult Refiner::refine_once(const RefinerOptions& o, const Camera& camera, const Observation& observed,
                                  const Mesh& mesh, const std::vector<Pose>& initials) {
  RefineRun run(o, camera, observed, mesh, initials, shape_turns(o, mesh, StartKind::kFresh));
  run.set_print_axes(print_axes(o, mesh), o.print_search);
  run.set_polish(o.polish_iterations);
  run.set_newton(o.newton_rounds);
  return drive(run);
}

bool Refiner::wants_retry(const RefinerOptions& o, const RefineResult& first) {
  return o.retry_turn > 0 && first.error.empty() && !first.plausible;
}

std::vector<Pose> Refiner::retry_starts(const RefinerOptions& o, const Mesh& mesh, const std::vector<Pose>& initials) {
  // The principal axes (through the centroid) the shape analysis turned about, each once.
  std::vector<ShapeRotation> axes;
  for (const ShapeRotation& c : shape_rotations(mesh)) {
    bool seen = false;
    for (const ShapeRotation& a : axes) seen = seen || std::abs(a.axis.dot(c.axis)) > 0.999;
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

RefineResult Refiner::refine_views(const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                                   const Eigen::Vector3d& pivot_model, const RefinerOptions& options) {
  const RefinerOptions& o = checked(options);
  try {
    if (!pivot_model.allFinite()) throw std::invalid_argument("refine_views: the pivot is not finite");
    RefineRun run(o, views, initials, {}, nullptr, nullptr, &pivot_model);
    run.set_polish(o.polish_iterations);
    run.set_newton(o.newton_rounds);
    return drive(run);
  } catch (const std::exception& e) {
    return failed_result(initials.empty() ? Pose() : initials.front(), e.what());
  }
}

RefineResult Refiner::drive(RefineRun& run) {
  std::vector<LossValue> values;
  while (!run.done()) {
    run.update_object_pixels(*renderer_);
    const std::vector<Pose>& poses = run.batch();  // (before with_gradient() and loss(): a scan differs)
    run.evaluate(*renderer_, poses, run.loss(), run.with_gradient(), values);
    run.absorb(values, on_iteration);
  }
  return run.finish(*renderer_);
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
  const double radius = 0.5 * mesh.diameter(), angle_tol = 0.1;  // (30-degree steps: 0.1 rad tells them apart)
  return mesh.symmetry.contains(turn, angle_tol, o.explore_tolerance * mesh.diameter(), radius);
}

std::vector<Pose> Refiner::shape_turns(const RefinerOptions& o, const Mesh& mesh, StartKind kind) {
  if (kind != StartKind::kFresh || !(o.explore_tolerance > 0) || mesh.content_id() == 0) return {};
  std::vector<Pose> turns;
  // A declared symmetry's turns look the same by design: no loss can choose among them.
  for (const ShapeRotation& r : ambiguous_rotations(shape_rotations(mesh), o.explore_tolerance, kMaxShapeTurns))
    if (!is_declared_turn(o, mesh, r.as_pose())) turns.push_back(r.as_pose());
  return turns;
}

std::vector<ShapeRotation> Refiner::print_axes(const RefinerOptions& o, const Mesh& mesh) {
  if (!(o.print_search > 0) || !(o.explore_tolerance > 0) || mesh.content_id() == 0) return {};
  std::vector<ShapeRotation> candidates = revolution_axes(shape_rotations(mesh), o.explore_tolerance);
  // The axis of revolution of most of the surface (a mug's body: no principal axis when a handle tilts them),
  // unless a principal one is already that axis.
  const auto key = std::make_pair(mesh.content_id(), o.explore_tolerance);
  auto fitted = revolution_fits_.find(key);
  if (fitted == revolution_fits_.end()) {
    if (revolution_fits_.size() >= kMaxCachedMeshes) revolution_fits_.clear();
    fitted = revolution_fits_.emplace(key, fit_revolution_axis(mesh, o.explore_tolerance)).first;
  }
  // Several principal axes of revolution (a ball): every direction is one; the fit adds nothing.
  if (fitted->second && candidates.size() < 2) {
    const ShapeRotation& f = *fitted->second;
    const double kSameDirection = std::cos(3.0 * M_PI / 180.0), kSameLine = 0.005 * mesh.diameter();
    bool added = false;
    for (ShapeRotation& c : candidates)
      if (std::abs(c.axis.dot(f.axis)) > kSameDirection) {
        // The same axis, unless the principal one runs beside it (its centroid pulled off by an appendage):
        // then the fitted one, about which most of the surface turns into itself.
        if ((f.pivot - c.pivot).cross(c.axis).norm() > kSameLine) c = f;
        added = true;
      }
    if (!added) candidates.push_back(f);
  }
  // About a declared continuous symmetry the print turns with the object: nothing to align.
  std::vector<ShapeRotation> axes;
  for (const ShapeRotation& c : candidates) {
    ShapeRotation turn = c;
    turn.angle = M_PI / 6;
    if (!is_declared_turn(o, mesh, turn.as_pose())) axes.push_back(c);
  }
  return axes;
}

std::vector<RefineResult> Refiner::refine_all(const Camera& camera, const Observation& frame,
                                              const std::vector<ObjectTarget>& objects,
                                              const RefinerOptions& options) {
  const RefinerOptions& o = checked(options);
  const auto start = std::chrono::steady_clock::now();
  std::vector<RefineResult> out = refine_all_once(o, camera, frame, objects);
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
  std::vector<RefineResult> retried = refine_all_once(o, camera, frame, again);
  const double ms = milliseconds_since(start);
  for (size_t j = 0; j < which.size(); ++j)
    out[which[j]] =
        keep_better(std::move(out[which[j]]), std::move(retried[j]), ms, weighs_print(o, *objects[which[j]].mesh));
  return out;
}

std::vector<RefineResult> Refiner::refine_all_once(const RefinerOptions& options, const Camera& camera,
                                                   const Observation& frame, const std::vector<ObjectTarget>& objects) {
  std::vector<RefineResult> out(objects.size());
  std::vector<std::unique_ptr<RefineRun>> runs(objects.size());
  // The frame is resized (and its edges found) once for all objects. A frame that does not fit the camera is
  // reported by each object's own check below.
  std::optional<Observation> shared_frame, coarse_frame;
  try {
    shared_frame = scale_frame(camera, frame, options, options.image_scale, true);
    if (coarse_iterations(options) > 0)
      coarse_frame = scale_frame(camera, frame, options, options.image_scale * options.coarse_scale, false);
  } catch (const std::invalid_argument&) {
  }
  const auto fail = [&](size_t k, const std::string& why) {
    out[k] = failed_result(objects[k].initial, why);
    runs[k].reset();
  };
  for (size_t k = 0; k < objects.size(); ++k) {
    const ObjectTarget& t = objects[k];
    try {
      if (!t.mesh) throw std::invalid_argument("no mesh");
      const Observation o =
          frame.with_mask(t.mask.empty() || t.mask.type() == CV_32FC1 ? t.mask : to_mask_float(t.mask), t.box);
      runs[k] = std::make_unique<RefineRun>(options, camera, o, *t.mesh, starts_of(t),
                                            shape_turns(options, *t.mesh, t.start_kind),
                                            shared_frame ? &*shared_frame : nullptr,
                                            coarse_frame ? &*coarse_frame : nullptr);
      const bool fresh = t.start_kind == StartKind::kFresh;
      runs[k]->set_print_axes(print_axes(options, *t.mesh), fresh ? options.print_search
                                                                  : std::min(options.print_search, kTrackedPrintSearch));
      runs[k]->set_polish(fresh ? options.polish_iterations : 0);
      runs[k]->set_newton(options.newton_rounds);
    } catch (const std::exception& e) {
      fail(k, e.what());
    }
  }
  // Lockstep: each iteration evaluates the active runs of every object in one renderer call (the CUDA backend
  // launches them together). The objects share the scaled rgb / depth / edges; each brings its own mask.
  if (!shared_frame) return out;  // every object has failed its check
  std::vector<ObjectBatch> batches;
  std::vector<size_t> which;
  std::vector<std::vector<LossValue>> values;
  for (bool any = true; any;) {
    any = false;
    // Runs in the coarse phase and runs in the fine phase are evaluated in separate calls (other images).
    for (const bool coarse : {true, false}) {
      batches.clear();
      which.clear();
      bool with_gradient = false;
      for (size_t k = 0; k < runs.size(); ++k) {
        if (!runs[k] || runs[k]->done() || runs[k]->coarse() != coarse) continue;
        RefineRun& r = *runs[k];
        try {
          r.update_object_pixels(*renderer_);
        } catch (const std::exception& e) {
          fail(k, e.what());
          continue;
        }
        ObjectBatch b;
        b.mesh = &r.mesh();
        b.mask = r.observation().mask;
        b.poses = r.batch();  // (before with_gradient() and loss(): a scan differs)
        b.loss = r.loss();
        batches.push_back(std::move(b));
        which.push_back(k);
        with_gradient = with_gradient || r.with_gradient();
      }
      if (batches.empty()) continue;
      any = true;
      const Camera& cam = runs[which[0]]->camera();  // the same scaled camera for every object of the phase
      const Observation& images = coarse ? *coarse_frame : *shared_frame;
      try {
        renderer_->evaluate_objects(cam, images, batches, with_gradient, values);
      } catch (const std::exception&) {
        // One object's input broke the joint call: evaluate them one by one so only that object fails.
        values.assign(which.size(), {});
        for (size_t j = 0; j < which.size(); ++j) {
          std::vector<std::vector<LossValue>> one;
          try {
            renderer_->evaluate_objects(cam, images, {batches[j]}, with_gradient, one);
            values[j] = std::move(one[0]);
          } catch (const std::exception& e) {
            fail(which[j], e.what());
          }
        }
      }
      for (size_t j = 0; j < which.size(); ++j)
        if (runs[which[j]]) {
          runs[which[j]]->count_evaluations(long(batches[j].poses.size()));
          runs[which[j]]->absorb(values[j], nullptr);
        }
    }
  }
  for (size_t k = 0; k < runs.size(); ++k) {
    if (!runs[k]) continue;
    try {
      out[k] = runs[k]->finish(*renderer_);
    } catch (const std::exception& e) {
      fail(k, e.what());
    }
  }
  return out;
}

long planned_evaluations(const RefinerOptions& o) {
  long total = 0;
  int active = std::max(o.batch_size, 1), candidates = 0, halvings = 0;
  const int scan_at = scan_iteration(o);  // with as many turns as any shape gets
  for (int k = 0; k <= o.iterations; ++k) {  // as RefineRun::batch(): k == iterations only evaluates
    for (const int due = halvings_due(k, o.iterations); o.successive_halving && k < o.iterations && halvings < due;
         ++halvings)
      active = (active + 1) / 2, candidates = (candidates + 1) / 2;
    if (k == scan_at && k < o.iterations) {
      total += long(active) * (1 + kMaxShapeTurns);
      candidates = std::min({active, kMaxShapeTurns, RefineRun::kScanCandidates});  // runs from preferred turns
    }
    total += active + candidates;
  }
  // finish(): the initial loss at the fine scale, a candidate's print registration (two renders), the polish,
  // the print alignment (one axis, and the loss and registration at its turn), the Newton steps (a render for
  // the pixel count, then per round a probe and three tries), both once more when the steps moved far, the
  // scoring render and the curvature probe.
  const long candidate = scan_at >= 0 && scan_at < o.iterations ? 2 : 0;
  const long print = o.explore_tolerance > 0 ? print_alignment_evaluations(o.print_search) + 2 : 0;
  const long polish = o.polish_iterations > 0 && o.iterations > 0 ? 1 + long(o.polish_runs) * o.polish_iterations : 0;
  const long newton = o.newton_rounds > 0 && o.iterations > 0 ? 1 + long(o.newton_rounds) * (kSecantProbePoses + 3) : 0;
  const long passes = print > 0 && newton > 0 ? 2 : 1;
  // Without a mask (derive_mask): the renders the object's pixels are derived about (the starts, at most one per
  // run; the better half of the runs; the result), and the result's and the starts' losses under the last ones.
  const long batch = std::max(o.batch_size, 1);
  const long derive = o.derive_mask ? batch + (batch + 1) / 2 + 2 + batch : 0;
  return total + 2 + candidate + polish + passes * (print + newton) + derive +
         (o.probe_distance > 0 ? kCurvatureProbeEvaluations : 0);
}

}  // namespace diffdope
