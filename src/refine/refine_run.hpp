#pragma once
// One object's refinement (Algorithm 1) as a state machine: the Refiner's one driver steps every object's run in
// lockstep, each iteration's hypotheses of all objects in one renderer call (internal header). Protocol: while
// !done(), next_step(), evaluate the step (the driver, or evaluate_step()), absorb(); then finish().
#include <chrono>
#include <functional>
#include <optional>
#include <vector>

#include "diffdope/refiner.hpp"
#include "refine/refine_schedule.hpp"

namespace diffdope {

/// What tells two converged poses apart: the refiner's loss and PrintRegistration::significance() (NaN: not
/// measured: no rgb, a plain model, a continuous declared symmetry).
struct JumpEvidence {
  double loss = 0, print = 0;
};
/// kJumpMargin * (1 + 4 * angle / pi): 1.7 % for a 30-degree turn, 3 % for a quarter turn (beyond it the loss
/// alone never jumps: kLossJumpMaxAngle).
double jump_margin(double angle);
/// Whether the evidence supports a jump from the start's basin (`from`) to a shape-scan candidate (`to`),
/// turned `angle` radians from the run it came from, both converged. Never without a lower loss. With the
/// print measured at both (and weighed: RefinerOptions::min_print_significance > 0): never when it contradicts
/// the jump (kPrintContradiction); always when it registers at the candidate, and by that much more than at the
/// basin, at least kClearPrint * (1 + angle / pi) standard deviations (half a turn needs twice the evidence of a
/// small one). Otherwise the loss decides, lower by more than jump_margin(angle), for turns of at most
/// kLossJumpMaxAngle, and only to a candidate whose print registers (at least `min_print_significance`): a pose
/// the verdict would reject for its print is no better supported than the start's basin, whatever the loss says
/// (on a camera's images a lit, slightly misregistered print fits a turned flat render by a few percent of loss).
/// A print measured at the basin but not at the candidate (it left the view, or no longer has contrast) is lost
/// evidence: no jump.
/// min_print_significance <= 0: the print is not weighed.
bool jump_is_supported(const JumpEvidence& from, const JumpEvidence& to, double angle, double min_print_significance);
/// Whether the print's registration allows the print alignment's turn from a pose whose print significance is
/// z_from to one whose is z_to: not lower by more than kPrintContradiction (the alignment's texture term found
/// the turn; a registration that falls says the turn moved the print away), and at least the verdict's bar
/// `min_significance` (a turn to where the print does not register is not the print's doing: a result still far
/// from converged compares labels drawn out of place). Always when the print is not weighed (min_significance
/// 0) or z_from not measured.
bool turn_is_supported(double z_from, double z_to, double min_significance);
/// The print significance a jump of `angle` radians needs, at the new pose and above the old one (one below
/// chance counting as 0): kClearPrint * (1 + angle / pi), so half a turn needs twice a small one's evidence.
double print_jump_bar(double angle);

class RefineRun {
 public:
  /// Validates the input and prepares the scaled images, the loss and the learning rates. Throws
  /// std::invalid_argument on unusable input (as Refiner::refine()). `views`: one for an object; several share
  /// the pose (Refiner::refine_views()). `scaled_frame` (refine_all, one view): the frame's rgb / depth / edges
  /// already at the refiner's scale, shared by the objects; then only the mask is resized. `coarse_frame`
  /// likewise at image_scale * coarse_scale (see RefinerOptions::coarse_fraction). `shape_turns`: the
  /// model-frame turns the shape scan tries on every run (RefinerOptions::shape_tolerance; empty: none).
  /// `pivot_model`: the model point the steps turn about (null: the first view's mesh centre).
  RefineRun(const RefinerOptions& options, const std::vector<RefineView>& views, const std::vector<Pose>& initials,
            std::vector<Pose> shape_turns = {}, const Observation* scaled_frame = nullptr,
            const Observation* coarse_frame = nullptr, const Eigen::Vector3d* pivot_model = nullptr);
  RefineRun(const RefinerOptions& options, const Camera& camera, const Observation& observed, const Mesh& mesh,
            const std::vector<Pose>& initials, std::vector<Pose> shape_turns = {},
            const Observation* scaled_frame = nullptr, const Observation* coarse_frame = nullptr)
      : RefineRun(options, {RefineView{camera, observed, &mesh}}, initials, std::move(shape_turns), scaled_frame,
                  coarse_frame) {}

  /// The axes finish() aligns the print about (Refiner::print_axes()) and the range searched about each
  /// (radians; RefinerOptions::print_search, or less about a tracked start).
  void set_print_axes(std::vector<ShapeRotation> axes, double range) {
    print_axes_ = std::move(axes);
    print_range_ = range;
  }
  bool done() const { return done_; }
  /// The first of the starts (a failed run's result keeps it).
  const Pose& first_start() const { return initials_.front(); }

  /// One iteration's evaluation: what the driver renders and scores, and what absorb() takes back with the values.
  struct Step {
    std::vector<Pose> poses;  // the active runs' poses; in the shape scan, each run turned by every shape turn
    LossOptions loss;         // the scan's adds the texture term (RefinerOptions::scan_texture_weight)
    bool with_gradient = true;  // not on the last iteration nor in the scan
    bool scan = false;
    const Camera* camera = nullptr;  // this iteration's scale (coarse, then fine); view 0
    cv::Mat mask;                    // the object's observed mask at that scale (given, derived or the window)
  };
  /// The next iteration's step. Without a mask (RefinerOptions::derive_mask) it first derives the
  /// object's pixels when they are due: about the starts before the first step and about the best runs when the
  /// fine phase begins (finish() derives them once more about the chosen result).
  Step next_step(Renderer& renderer);
  /// Evaluates `step` alone, in every view (a run whose images no other run shares); absorb() counts it.
  void evaluate_step(Renderer& renderer, const Step& step, std::vector<LossValue>& values);
  /// Takes the values of `step` (from next_step()), counts its evaluations, keeps each run's best and steps the
  /// runs (after the scan: adds the candidate run, without a step). `on_iteration`: Refiner::on_iteration.
  void absorb(const Step& step, const std::vector<LossValue>& values, const Refiner::Progress& on_iteration);
  enum class Gradients { kSkip, kCompute };
  /// Evaluates `poses` in every view at the fine scale and gives each pose the mean over the views (terms, total
  /// and gradient: the views share the camera frame the gradient is in). Counted in RefineResult::evaluations.
  void evaluate_fine(Renderer& renderer, const std::vector<Pose>& poses, const LossOptions& loss,
                     Gradients gradients, std::vector<LossValue>& out);
  /// Winner and quality scores (renders the refined pose once per view).
  RefineResult finish(Renderer& renderer);
  /// Iterations of the last descent from the chosen pose (RefinerOptions::polish_iterations; 0: none).
  void set_polish(int iterations) { polish_iterations_ = iterations; }
  /// Rounds of Newton steps after the print alignment (RefinerOptions::newton_rounds; 0: none).
  void set_newton(int rounds) { newton_rounds_ = rounds; }
  /// A tracked start (StartKind::kTracked) is about a frame's motion from the truth: without a mask its object's
  /// pixels are derived from depth once before the descent, already within the reach the fresh start's second
  /// derivation narrows to, and then only about the result (the verdict's pixels: about the starts, a track and
  /// its prediction a few frames apart widen them).
  void set_tracked_start(bool tracked) { tracked_start_ = tracked; }
  /// The curvature an earlier frame measured (ObjectTarget::carried_curvature): carried to the result instead of
  /// probed (one view only).
  void set_carried_curvature(std::optional<MeasuredCurvature> carried) { carried_curvature_ = std::move(carried); }
  /// How the print of a render registers with the image (one view with rgb; else not measured).
  PrintRegistration register_render(const RenderImage& img) const;
  /// PrintRegistration::significance() at `pose` (one render at the fine scale); NaN when not measurable (no
  /// rgb, several views, a plain model, a continuous declared symmetry).
  double print_significance(Renderer& renderer, const Pose& pose);

  /// Whether the next step is at the coarse scale (its images differ from the fine phase's).
  bool coarse() const { return k_ < switch_at_; }
  const Mesh& mesh(size_t v = 0) const { return *meshes_[v]; }
  size_t views() const { return meshes_.size(); }

 private:
  const RefinerOptions& options_;
  std::vector<const Mesh*> meshes_;  // per view
  Eigen::Vector3d pivot_model_;      // model point the steps turn about
  std::chrono::steady_clock::time_point start_time_;
  std::vector<Pose> initials_;
  struct Level {
    Camera cam;
    Observation obs;
  };
  std::vector<Level> fine_, coarse_;  // per view
  // The constructor's steps (after the input's checks): the images at each scale, the loss the input allows, the
  // runs with their learning rates.
  Level make_level(const RefineView& view, double scale, const Observation* shared, Phase phase) const;
  void set_up_levels(const std::vector<RefineView>& views, const Observation* scaled_frame,
                     const Observation* coarse_frame);
  void set_up_loss(const std::vector<RefineView>& views);
  void start_runs();
  std::vector<std::vector<LossValue>> view_values_;  // evaluate()'s scratch
  int switch_at_ = 0;  // first iteration at the fine scale (0: no coarse phase)
  LossOptions loss_, scan_loss_;
  bool has_mask_ = false;  // the loss has a mask that holds the silhouette: given, or derived from depth
  // Derived object pixels: whether they are derived (from depth, or without it from colour: a probability, not a
  // silhouette the verdict or the print's turns may lean on), how often so far, the iteration of the second
  // derivation, and which pixels the runs' best losses were measured under (under others they must be sought
  // again).
  bool derives_pixels_ = false;
  bool pixels_from_colour_ = false;
  // Per view: the mask was derived from depth without colour (given so, or derived here without rgb): the IoU
  // leaves the pixels without a depth reading out (its holes are unknown).
  std::vector<bool> mask_from_depth_;
  double colour_match_error_ = NAN;  // from colour: the last derivation's median colour error, its miss cost
  bool weighs_given_mask_ = false;  // a mask was given and depth can check it (derive_mask, one view)
  int derivations_ = 0;
  int rederive_at_ = 0;
  int pixels_version_ = 0;  // counts use_pixels(): what a measurement at a pose was made under
  int bests_pixels_ = 0;    // pixels_version_ the runs' bests were measured under
  /// derive_object_pixels() (without depth: derive_object_pixels_from_colour()) about `poses` within `margin`
  /// metres, at the fine scale and area-resized to the coarse one; false (the masks unchanged) when no pixel was
  /// found (none at least 0.5).
  bool derive_pixels(Renderer& renderer, const std::vector<Pose>& poses, double margin);
  cv::Mat derived_pixels(Renderer& renderer, const std::vector<Pose>& poses, double margin);  // empty: none
  void use_pixels(const cv::Mat& pixels);  // as the mask, at both scales
  /// A tracked start's pixels from depth: derived twice (set_tracked_start()).
  bool derives_twice() const { return tracked_start_ && !pixels_from_colour_; }
  double diameter_ = 1.0;
  RefineResult res_;
  std::vector<Pose> poses_, best_pose_;
  std::vector<LossValue> best_;
  std::vector<int> active_;  // runs still descending (successive halving drops the worst)
  // Per run: the run a shape-scan candidate was turned from (-1: a run from the starts, indices < batch_size)
  // and the angle of its turn (radians).
  std::vector<int> source_;
  std::vector<double> jump_angle_;
  int k_ = 0, stale_ = 0;
  int steps_ = 0;  // iterations stepped (k_ jumps when the coarse phase stalls)
  int halvings_ = 0;  // successive halvings done (of three)
  // The shape's near symmetries (RefinerOptions::shape_tolerance): the turns the shape scan tries on every run
  // (RefinerOptions::shape_scan: once, when the fine phase begins; kScanMargin) and the result's print is weighed at.
  std::vector<Pose> turns_;
  std::vector<ShapeRotation> print_axes_;
  double print_range_ = 0;
  int polish_iterations_ = 0;
  int newton_rounds_ = 0;
  bool tracked_start_ = false;
  std::optional<MeasuredCurvature> carried_curvature_;
  long evaluations_ = 0;          // hypothesis evaluations (and plain renders) so far, every view
  /// The last descent (RefinerOptions::polish_iterations) from res.pose, keeping the lowest loss seen.
  void polish(Renderer& renderer, RefineResult& res);
  /// The Newton steps (RefinerOptions::newton_rounds) from res.pose, each taken on kNewtonEvidence.
  void newton(Renderer& renderer, RefineResult& res);
  /// The noise model's count of independent residuals at `pose` (kCorrelatedPixels; one render per view).
  double residual_count(Renderer& renderer, const Pose& pose);
  // finish()'s steps.
  /// The run of lowest loss among runs [first, last) (-1: none).
  int lowest(const RefineResult& res, int first, int last) const;
  /// Makes run `i`'s best the result.
  void take(RefineResult& res, int i) const;
  /// What finish()'s stages carry from one to the next: the result so far (its pose and loss, and what each
  /// stage records in it) and the evidence measured at its pose. The print's significance is measured once per
  /// pose and per derivation of the object's pixels (pixels_version_), when a stage needs it: a stage that moves
  /// the pose or derives the pixels leaves nothing stale behind.
  class Candidate {
   public:
    Candidate(RefineRun& run, RefineResult result) : result(std::move(result)), run_(run) {}
    RefineResult result;
    /// PrintRegistration::significance() at result.pose (NaN: not measurable; print_significance()).
    double print(Renderer& renderer);
    /// The print's significance at result.pose, measured by the caller.
    void set_print(double significance);

   private:
    RefineRun& run_;
    Pose measured_;
    int pixels_ = -1;  // pixels_version_ when measured (-1: never)
    double z_ = 0;
  };
  /// The runs' bests as the result's, and the start's own basin (the runs from the starts) chosen.
  Candidate start_candidate();
  /// After a coarse phase, and under newly derived pixels: the initial loss at the fine scale, and a start no run
  /// beat as the result.
  void weigh_starts(Renderer& renderer, Candidate& c);
  /// The shape scan's best candidate replaces the start's basin when the evidence supports the jump.
  void weigh_candidate(Renderer& renderer, Candidate& c);
  /// Without a mask: the object's pixels derived once more, about the chosen result.
  void derive_pixels_at_result(Renderer& renderer, Candidate& c);
  /// The print alignment's turn about print_axes_, kept when the loss and the print's registration allow it.
  void align_result_print(Renderer& renderer, Candidate& c);
  /// The print alignment then the Newton steps, again (kAlignmentPasses) when the steps went on far.
  void align_print_and_step(Renderer& renderer, Candidate& c);
  /// The shape-equivalent turn of the result (turns_) whose print registers best, if better than the result's,
  /// converged from; it replaces the result when its print registers clearly better there (kClearPrint), and
  /// is otherwise the result's rival (RefineResult::rival_print) when it stayed a pose of its own at a loss no
  /// higher. Only with a mask or depth.
  void weigh_shape_turns(Renderer& renderer, Candidate& c);
  /// The render of view `v` at `pose` at the fine scale (counted).
  RenderImage render_view(Renderer& renderer, size_t v, const Pose& pose);
  /// Mask IoU and depth agreement of view `v`'s render `img` (no loss).
  RefineResult::ViewScores view_scores(const RenderImage& img, size_t v) const;
  /// One view's scores at the result: mask IoU, depth agreement and the print's registration. Returns the
  /// rendered pixels.
  int score_view(Renderer& renderer, RefineResult& res);
  /// Several views' (refine_views()): each view's scores and loss (RefineResult::view_scores), the result's the
  /// weakest view's. Returns the rendered pixels over all views.
  int score_views(Renderer& renderer, RefineResult& res);
  /// The loss's curvature about the result (RefinerOptions::probe_distance; one view's, or the views' mean).
  void probe_curvature(Renderer& renderer, RefineResult& res);
  /// Curvature, covariance, convergence, verdict and time of the result.
  void judge_result(Renderer& renderer, RefineResult& res, int rendered_pixels);
  int scan_at_ = -1;         // the iteration whose step is preceded by the scan (-1: none)
  /// The evaluation in `phase`'s images, not counted (evaluate_fine() counts; absorb() counts the steps).
  void evaluate_views(Renderer& renderer, const std::vector<Pose>& poses, const LossOptions& loss,
                      bool with_gradient, std::vector<LossValue>& out, Phase phase);
  /// Derives the object's pixels when they are due (next_step()).
  void update_object_pixels(Renderer& renderer);
  /// The scan's candidates: a new run from each turn some run prefers (absorb()).
  void add_scan_candidates(const Step& scan, const std::vector<LossValue>& values);
  bool scanned_ = false;
  double best_overall_;
  bool done_ = false;
};

}  // namespace diffdope
