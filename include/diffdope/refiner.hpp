#pragma once
// The refiner: the paper's Algorithm 1 (Diff-DOPE). B gradient-descent runs start from the same initial pose,
// run i with its own learning rate drawn from [lr_low, lr_high] and decayed as lr_i * lr_decay^(k/iters);
// plain gradient descent, no momentum; the run with the lowest loss wins.
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/pose.hpp"
#include "diffdope/pose_curvature.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/shape_rotations.hpp"
#include "diffdope/verdict.hpp"

namespace diffdope {

/// Every field has a default and the same name as its YAML key (see config/default.yaml). Names, ranges, units and
/// one-line docs are in one table (refiner_option_table(), option_table.hpp), from which the YAML reader,
/// validate() and to_yaml() work; ranges are generous (far beyond useful values) but bound the time and memory
/// one refinement can take.
struct RefinerOptions {
  int batch_size = 32;   // B: parallel runs (paper: 32); [1, kMaxBatchSize]
  /// Gradient steps per run (paper: 100). Fewer suffice with the coarse-to-fine schedule below and the Newton
  /// steps after it (newton_rounds), which converge what the steps leave short (docs/benchmarks.md).
  int iterations = 48;  // [0, kMaxIterations]
  /// Learning-rate bounds, dimensionless. A step moves the object's centre by about lr * 2 * diameter * (loss
  /// slope) and turns it by about 4 * lr * (slope) radians: translation gradients are scaled by diameter^2 and
  /// rotation gradients (taken about the object's centre) by 4, so one rate means the same for small and big
  /// objects and for translation and rotation. Every loss term is a mean in [0, ~1] whose slope is about one
  /// per object size of misalignment, so lr = 0.01 moves ~2 % of the diameter (or ~2.3 deg) per step. The
  /// paper's l = 0.001, h = 50 belong to its own loss scaling (a sum over pixels); the same behaviour (small
  /// rates polish easy starts, large ones escape hard starts) holds here for [0.0005, 0.03]: over 100 decayed
  /// steps the smallest rate travels ~4 % of the diameter, the largest ~2.3 diameters / 4 rad.
  double lr_low = 0.0005;  // (0, 10]
  double lr_high = 0.03;   // (0, 10], >= lr_low
  bool lr_log_uniform = false;  // draw log-uniformly (the paper's "exponent" variant) instead of uniformly
  double lr_decay = 0.1;        // rate multiplier reached at the last iteration (paper: 0.1); (0, 1]
  double image_scale = 0.5;     // images and intrinsics are resized by this before refining (paper: 0.5);
                                // [kMinImageScale, 4]
  /// Coarse to fine: the first coarse_fraction of the iterations run on images resized by
  /// image_scale * coarse_scale (at 0.5, a quarter of the pixels), the rest at image_scale; the best pose of
  /// each run is then sought among the fine iterations only. coarse_fraction 0 = every iteration at image_scale
  /// (the paper's algorithm). The coarse phase is where the large moves of a hard start happen; the fine phase
  /// polishes. At 0.75 the fine phase is the last quarter, where successive halving has left B / 8 runs.
  double coarse_fraction = 0.75;  // in [0, 1)
  double coarse_scale = 0.5;     // in [0.05, 1]; image_scale * coarse_scale >= kMinImageScale
  /// Near symmetries of the shape (shape_rotations.hpp): rotations about the surface's principal axes that move
  /// it by at most this share of its diameter (a bottle about its axis: every 30 degrees; a box: its half turns)
  /// give poses that silhouette and depth cannot tell apart, and gradient descent does not cross between them (a
  /// print's basin is a few pixels wide). They are the turns the shape scan tries (shape_scan) and the result's
  /// print is weighed at (min_print_significance), and their axes of near revolution are the ones the print
  /// alignment turns about (print_search). 0 = no turn counts as ambiguous, so none of these runs (the paper's
  /// algorithm). Its deprecated name explore_tolerance is still read (YAML and the node's ~parameters).
  double shape_tolerance = 0.01;  // [0, 0.2]
  /// Shape scan: when the fine phase begins (silhouette and depth have done their work), every run is evaluated
  /// turned by each of the shape's near symmetries (shape_tolerance; forward renders only, no step); of the turns
  /// whose loss is more than 1 % below some run's own, the lowest becomes a candidate run beside the others, which
  /// go on unturned. Once converged, the candidate replaces the start's basin only when the evidence is clear for
  /// how far it jumps (jump_is_supported() in refine_run.hpp: a lower loss, the print's registration not
  /// falling, and either clearly better print or a loss lower by a margin that grows with the angle). false =
  /// off (the print alignment and the result's shape turns still run: shape_tolerance 0 turns all off); never
  /// for tracked starts.
  bool shape_scan = true;
  /// Weight of the texture term (loss.weight_texture) added to the loss the scan compares turns with. Off by
  /// default: it settles ties on easy starts but misjudges hard ones, whose print is still a few pixels off
  /// when the scan comes (docs/benchmarks.md). Its deprecated name explore_texture_weight is still read.
  double scan_texture_weight = 0.0;  // [0, LossOptions::kMaxWeight]
  /// Print alignment (print_alignment.hpp): after the descent, the result is turned about each axis of near
  /// revolution of its shape (within shape_tolerance: a bottle's axis, or a mug's body axis, which the handle
  /// hides from silhouette and depth whenever it is out of sight; declared symmetries excluded) by up to
  /// +-print_search radians, and the turn where the print agrees best with the image is kept. Radians; 0 = off
  /// (the paper's algorithm), as is shape_tolerance = 0. Needs rgb and a mask or depth (they hold the other
  /// degrees of freedom while the print decides the turn); skipped with RGB alone, and with iterations 0 (scoring
  /// the start).
  double print_search = 0.7;  // [0, pi]
  /// Retry of a rejected result: when the verdict finds a refined pose implausible (RefineResult::plausible
  /// false, no error), the object is refined again from its initial pose(s) and from each turned by
  /// +-retry_turn about the surface's three principal axes (through its centroid; turns about a declared
  /// symmetry left out), the B runs shared out among these starts; the retry's result replaces the first only
  /// when the verdict accepts it and its loss is lower (RefineResult::retried). A hard start that descent took
  /// into a wrong basin (a box seen edge-on) mostly has a turned start in the right one. Costs a second
  /// refinement, for rejected results only; never for tracked starts (ObjectTarget::start_kind kTracked) or
  /// refine_views(). Radians; 0 = off (the paper's algorithm).
  double retry_turn = 0.52;  // [0, pi]
  /// Polish: after the descent and the shape scan's choice, before the print alignment, polish_runs runs go on
  /// from the chosen pose for polish_iterations more steps at image_scale, at small rates (lr_low, doubling
  /// per run, decayed as the descent's), and the lowest loss seen is kept: the descent's winners from hard
  /// starts are mostly large-rate runs whose decayed steps still hop about the minimum when the iterations end
  /// (figures: docs/benchmarks.md). 0 = off (the paper's algorithm); never for tracked starts (ObjectTarget::start_kind
  /// kTracked) nor with iterations 0 (scoring the start).
  int polish_iterations = 30;  // [0, kMaxIterations]
  int polish_runs = 4;         // [1, 16]
  /// Newton steps: after the polish and the print alignment, each of up to newton_rounds rounds probes the
  /// loss's curvature about the result (a secant Hessian from kSecantProbePoses gradients, ±h of surface
  /// displacement; h one working pixel at the object's distance at first) and tries a quarter, a half and all of
  /// the Newton step on it, damped to at most 2h (trust region). The best is taken when it lowers the loss by more
  /// than noise would (3 nats of the covariance's noise model, pose_covariance()). A round whose whole step the
  /// trust radius held back doubles h (the valley goes on; up to a quarter of the diameter), any other halves it;
  /// a round without a clear gain ends the rounds, or is tried again at half h when h had grown, and so does a
  /// step after which the round's quadratic model, from the gradient where it ended, promises less than a step
  /// needs (the next round is not probed). Plain
  /// gradient steps are bounded by the stiffest direction (a thin object across its width), so softer ones (its
  /// roll) are still converging when the iterations end (docs/benchmarks.md). When the steps lowered the loss by
  /// more than kPrintLossTolerance, the print alignment runs once more at the converged pose. 0 = off (the paper's
  /// algorithm, and the calibration's default); never with iterations 0 (scoring the start). Tracked starts get
  /// them too: their few iterations leave the soft directions shortest.
  int newton_rounds = 16;  // [0, 32]
  LossOptions loss;             // term weights (all 1 as in the paper) and robustness constants
  /// A plain model (Mesh::plain(): no print, one colour) gets no colour term: its flat render against a lit image
  /// sees only the lighting (the paper's T-LESS results are better without RGB). true = compare its colour anyway.
  /// Kept when nothing else observes the object (RGB alone, no mask): the colour term is then the silhouette's
  /// only evidence. RefineResult::loss_used says what was used.
  bool plain_model_rgb = false;
  uint64_t seed = 0;            // learning-rate draws; same seed, same inputs -> same result
  /// Stop when no run has improved its best loss by more than early_stop_tolerance (relative) for
  /// early_stop_patience iterations. 0 = always run all iterations.
  int early_stop_patience = 0;          // [0, kMaxIterations]
  double early_stop_tolerance = 1e-4;   // [0, 1]
  /// Speed: at 25 %, 50 % and 75 % of the iterations keep only the better half of the runs (by their best loss
  /// so far): less than half the evaluations; what it costs in accuracy: docs/benchmarks.md.
  /// false = the paper's algorithm exactly (every run goes to the end).
  bool successive_halving = true;
  /// Without an observed mask: how far the object may be from its start, as a fraction of its size. With
  /// derive_mask, its pixels are sought this many diameters around its render at the start (from depth, or
  /// without it from colour); otherwise the loss looks at the initial pose's projected bounding box grown by this
  /// fraction of its size on every side.
  double no_mask_window = 0.3;  // [0, 10]
  /// Without an observed mask but with depth (one view): the object's pixels are derived (derive_object_pixels():
  /// depth near its render, less what stands in front and the surfaces it stands among) at the start, when the
  /// fine phase begins and at the chosen result, each time nearer (no_mask_window diameters, a third of that,
  /// then inlier_threshold), and the loss, the polish, the Newton steps and the verdict use them as the mask.
  /// Without depth (one view, rgb): each pixel's probability from its colour (derive_object_pixels_from_colour())
  /// at the same three moments, and a pixel the render misses costs its median colour error on them; the loss
  /// uses them as the mask, the verdict does not (no silhouette to lean on).
  /// With an observed mask and depth, the start's derivation checks it: a mask whose outline lies more than half
  /// a pixel from the edge depth shows (a segmenter's, a few pixels off) is replaced by the derived pixels
  /// (RefineResult::given_mask_replaced). false: a mask is taken as given, and without one the window alone
  /// stands in (a table or a neighbour inside it then pulls the render onto itself).
  bool derive_mask = true;
  /// Quality: a depth reading within this distance (metres) of the render is an inlier, at least; the verdict
  /// widens the band to three times the depth noise it measures (depth_agreement() in verdict.hpp).
  double inlier_threshold = 0.01;  // (0, 10]
  /// The noisiest depth the verdict excuses: the noise's standard deviation at 1 m (metres; it grows with z^2).
  /// Measured noise beyond it counts as disagreement (about twice it leaves fewer than min_depth_inliers' 0.8
  /// inside the band). 0.01 is the RealSense D400 series' specified RMS error (2 % at 2 m, Intel's datasheet);
  /// 0 = a fixed band of inlier_threshold.
  double max_depth_noise = 0.01;  // [0, 1]
  /// Verdict thresholds (verdict.hpp): plausible when mask IoU >= min_mask_iou (if a mask was given or derived), the depth
  /// inlier fraction >= min_depth_inliers (if depth was given) and the print lines up with the image's at least
  /// min_print_significance standard deviations above its chance level (if the model has a print and rgb was
  /// given; 0 = not weighed, neither here nor in the shape scan's and print alignment's choices). The verdict asks
  /// whether the evidence contradicts the pose, not whether it proves it: a weak print (a white bottle's small
  /// label) lines up only 1-3 standard deviations above chance at the right pose, while a print that is not
  /// even one above it does not line up at all. Between the bar and clear evidence (kClearPrint, 3) the shape
  /// must fit better (judge() in verdict.hpp); the scan's choices use kClearPrint too.
  /// The shape's bars say that a fifth of the evidence disagreeing contradicts the pose: wrong results that keep
  /// much of their outline (a tilted cylinder, a box turned into a look-alike outline) fall below them on mask or
  /// depth, right ones stay above (figures: docs/benchmarks.md, "The verdict"). Lower min_mask_iou for a coarse
  /// detector mask.
  double min_mask_iou = 0.8;       // [0, 1]
  double min_depth_inliers = 0.8;  // [0, 1]
  double min_print_significance = 1.0;  // [0, 100]
  /// The loss is probed around the result at this mean displacement of the model surface (metres, the unit of
  /// ADD): RefineResult::curvature, the loss's curvature and its least constrained direction (pose_curvature.hpp;
  /// 15 evaluations). 0 = no probe.
  double probe_distance = 0.01;  // [0, 1]
  RenderOptions render;  // back-face culling, near plane, threads
  /// Backend: cpu, cuda (an error without a device) or auto (CUDA when a device is present, else the CPU with
  /// one line on stderr). Default cpu: the CUDA backend shares the CPU's maths but has not yet been run on a
  /// GPU by this project (docs/design.md, "CUDA backend").
  std::string device = "cpu";

  /// Overrides fields present in a YAML file / string; unknown keys are an error (typos must not pass
  /// silently). Throws std::runtime_error naming the file and key.
  /// `base` supplies the values of keys the YAML does not set (the defaults when omitted).
  static RefinerOptions from_yaml_file(const std::string& path);
  static RefinerOptions from_yaml_file(const std::string& path, const RefinerOptions& base);
  static RefinerOptions from_yaml_string(const std::string& yaml, const std::string& origin = "<string>");
  static RefinerOptions from_yaml_string(const std::string& yaml, const RefinerOptions& base,
                                         const std::string& origin);
  /// Every option as YAML with a comment and range per key, in the table's order (option_table.hpp);
  /// from_yaml_string() reads it back to the same values. config/default.yaml is RefinerOptions().to_yaml().
  std::string to_yaml() const;
  static constexpr int kMaxBatchSize = 1024;
  static constexpr int kMaxIterations = 10000;
  static constexpr double kMinImageScale = 0.02;
  /// Throws std::invalid_argument naming the first field that is not finite or outside its range (loss and
  /// render included).
  void validate() const;
};

/// The stages of one object's refinement, in the order they run: the descent (every run's iterations, the shape
/// scan, and without a mask the derivations of the object's pixels), then the stages the chosen result goes
/// through. RefineResult::stage_evaluations counts what each made; planned_evaluations(o, stage) bounds it.
enum class RefineStage {
  kDescent,
  kWeighStarts,        // the starts' losses at the fine scale, after a coarse phase
  kWeighCandidate,     // the shape scan's candidate against the start's basin
  kDerivePixels,       // without a mask: the object's pixels derived about the result
  kPolish,             // RefinerOptions::polish_iterations
  kAlignPrintAndStep,  // RefinerOptions::print_search, then RefinerOptions::newton_rounds
  kWeighShapeTurns,    // the result's shape-equivalent turns weighed by the print
  kScore,              // the result's scores, curvature and verdict
};
constexpr int kRefineStages = 8;
/// "descent", "weigh_starts", "weigh_candidate", "derive_pixels", "polish", "align_print_and_step",
/// "weigh_shape_turns", "score".
const char* to_string(RefineStage stage);

/// What a refinement did, with scores a caller can threshold.
struct RefineResult {
  Pose pose;                          // refined model pose in the camera frame (metres)
  Pose initial_pose;                  // the initial pose the winning run started from
  LossValue loss;                     // the result's loss, per term (unweighted means) and total: the winner's
                                      // best, or lower after the polish and the Newton steps
  /// The loss as used: RefinerOptions::loss with the refiner's own choices, a term without its observation at
  /// weight 0 (no mask: weight_mask; no depth: weight_depth; no rgb: weight_rgb and weight_edges) and a plain
  /// model's colour term off (RefinerOptions::plain_model_rgb).
  LossOptions loss_used;
  double initial_loss = 0;            // loss of the initial pose (at image_scale)
  /// Best loss of every run (at image_scale; +inf for runs dropped in the coarse phase): the batch_size runs from
  /// the starts, then the shape scan's candidates (scan_turns). The winner has the lowest loss among the first
  /// unless a candidate was taken (scan_taken).
  std::vector<double> run_losses;
  std::vector<double> learning_rates; // every run's drawn rate
  std::vector<Pose> run_poses;        // every run's best pose (its start for runs dropped in the coarse phase)
  std::vector<double> history;        // winner's loss at every iteration (the coarse phase's at its own scale)
  /// Every run's loss at every iteration it ran; a candidate's is NaN before the shape scan.
  std::vector<std::vector<double>> run_histories;
  int winner = -1;                    // the run whose best pose is the result (its start's run when no run's
                                      // fine-phase best beat the start itself)
  int start = 0;                      // index of the initial pose the winning run started from
  int scan_turns = 0;                 // candidates the shape scan (shape_scan) added: runs from turned poses
  bool scan_taken = false;            // the result is such a candidate, not the start's own basin (the evidence
                                      // was clear: jump_is_supported() in src/refine/refine_run.hpp)
  double shape_turn = 0;              // radians of the shape-equivalent turn the print preferred at the end (0: none)
  double rival_print = std::numeric_limits<double>::quiet_NaN();  // the print's significance at the result's
                                      // best-registering shape-equivalent turn, converged from (NaN: not
                                      // measured); a rival that registers as well as the result leaves its face
                                      // undetermined, and the verdict rejects it
  double print_turn = 0;              // radians the print alignment (print_search) turned the result by (0: none;
                                      // the sum of both turns' angles when it ran again after the Newton
                                      // steps); a turn may raise the loss up to kPrintLossTolerance (2 %) above
                                      // the winning run's best (and so, rarely, above initial_loss)
  bool retried = false;               // the first result was rejected and refined again from turned starts
                                      // (retry_turn): the fields are the kept one's (initial_loss the
                                      // caller's starts'), start may then index a turned start, time_ms is both
  int iterations = 0;                 // iterations actually run (early stop)
  int polish_iterations = 0;          // iterations of the polish (RefinerOptions::polish_iterations) run
  int newton_steps = 0;               // Newton steps taken (RefinerOptions::newton_rounds)
  double time_ms = 0;                 // wall time of refine() (refine_all(): from the call's start to this object's end)
  long evaluations = 0;               // hypothesis evaluations made (renders of one pose, with or without loss and
                                      // gradient; a retry's included): what planned_evaluations() bounds
  std::array<long, kRefineStages> stage_evaluations{};  // evaluations by RefineStage (a retry's included):
                                      // their sum is `evaluations`
  // Quality scores at the refined pose (at the refiner's image scale).
  double mask_iou = -1;               // IoU of rendered and observed masks (with depth, the render less where the
                                      // observed depth shows an occluder in front: loss.occlusion_margin);
                                      // without a mask, against the pixels derived from depth (derive_mask); -1
                                      // with neither
  double given_mask_offset = -1;      // pixels at the refining scale: how far a given mask's outline lies from the
                                      // edge depth shows at the start (outline_offset()); -1 when not measured
                                      // (no mask, no depth, several views, derive_mask false)
  bool given_mask_replaced = false;   // that offset exceeded half a pixel: the derived pixels stood in for the
                                      // mask in the loss, the later steps and the verdict
  std::array<double, 2> given_mask_shift{{0, 0}};  // camera pixels (+x right, +y down): the translation that
                                      // lays the given mask's outline nearest to that edge (best_outline_shift(), up
                                      // to kMaxMaskShift); a mask off the image as a whole shows here (a colour
                                      // image not registered to depth, a label drawn from a pose off the image)
  double given_mask_shifted_offset = -1;  // pixels at the refining scale: the offset left after that shift; near
                                      // given_mask_offset for a grown, shrunk or wandering mask; -1 when not measured
  double depth_inliers = -1;          // fraction of object pixels (observed or derived mask, else the render's) with a depth
                                      // reading within the noise's band of the render (depth_agreement()); -1
                                      // without depth
  double depth_noise = -1;            // the depth noise measured against the render (metres at 1 m; the
                                      // noisiest view's); -1 without depth
  bool converged = false;             // the winner's loss stopped improving (relative change < 1 % over the last 10 %)
  bool plausible = false;             // every available score passes its threshold in RefinerOptions
  bool judged = false;                // some score could judge the pose (not so: colour alone without a mask, on
                                      // a model without print; plausible is then false)
  double confidence = 0;              // [0, 1], the weakest score, 0.5 at its threshold (verdict.hpp)
  PrintRegistration print;            // whether the print lines up at the refined pose (ncc = -1: not measured)
  PoseCurvature curvature;            // the loss around the refined pose (valid = false when not probed:
                                      // probe_distance = 0, or a probe left the image)
  bool curvature_carried = false;     // the curvature is ObjectTarget::carried_curvature's, carried to the pose
  /// From the curvature (pose_covariance()): of the twist about `pivot` (v m, w rad, camera axes); zero when not
  /// probed. covariance_at_origin(covariance, pivot, frame_origin) gives ROS's PoseWithCovariance layout.
  Matrix6d covariance = Matrix6d::Zero();
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();  // the object's centre at the refined pose (camera frame)
  std::string error;                  // why the input could not be refined (empty = refined; then pose = the start)
  /// refine_views(): each view's scores at the result (loss at image_scale; -1 = not available).
  struct ViewScores {
    double loss = 0, mask_iou = -1, depth_inliers = -1, depth_noise = -1;
  };
  std::vector<ViewScores> view_scores;
};

/// The names of the terms a loss weighs (weight > 0): "rgb", "depth", "mask", "edges", "texture".
std::vector<std::string> used_terms(const LossOptions& loss);

/// A result's verdict in three states. Undetermined: nothing was refined (an `error`, or no iteration run) or
/// no evidence could judge the pose (`judged` false: colour alone without a mask, on a model without print).
enum class VerdictState { kPlausible, kImplausible, kUndetermined };
VerdictState verdict_state(const RefineResult& r);
const char* to_string(VerdictState state);  // "plausible", "implausible", "undetermined"
/// Why a result's verdict is undetermined, for a user ("" when it was judged).
std::string undetermined_reason(const RefineResult& r);

/// Whether the retry of a rejected result (RefinerOptions::retry_turn) replaces the first: only when the verdict
/// accepts it, and its loss is lower or (`weigh_print`: the verdict weighs this object's print) its print
/// registers kClearPrint standard deviations better than the first's (one below chance counting as 0): the colour
/// term can favour a wrong turn, the print's registration cannot be lit into agreement. A retry rejected too keeps
/// the first result, the one nearer the caller's start: with weak evidence (RGB alone) a start turned 30-40
/// degrees can end a fraction of a percent lower.
bool retry_replaces(const RefineResult& first, const RefineResult& retry, bool weigh_print);

/// Where an object's starts come from. kFresh: a detection, or a caller's pose: the full refinement. kTracked: a
/// live track (its last refined pose and its prediction): no shape scan (shape_scan), retry (retry_turn)
/// nor polish, and the print alignment searches only +-kTrackedPrintSearch (print_alignment.hpp). A live track is
/// right or nearly so; a scan could only flip it between frames on a weakly printed object.
enum class StartKind { kFresh, kTracked };

/// A smaller budget for one object of a Refiner::refine_all() call than the call's options give (a steady track's:
/// tracked_budget() in object_track.hpp): each a cap on the option of that name, never a raise.
struct RefineBudget {
  int batch_size = std::numeric_limits<int>::max();
  int iterations = std::numeric_limits<int>::max();
  int polish_iterations = std::numeric_limits<int>::max();
  int newton_rounds = std::numeric_limits<int>::max();
};
/// `o` within `budget` (validated: a budget can make options invalid, e.g. a batch of 0).
RefinerOptions with_budget(const RefinerOptions& o, const RefineBudget& budget);

/// One object of a frame for Refiner::refine_all().
struct ObjectTarget {
  const Mesh* mesh = nullptr;
  Pose initial;
  cv::Mat mask;  // this object's visible mask (CV_32FC1, or any type to_mask_float takes); may be empty
  std::vector<Pose> alternatives;  // further initial poses; the runs are shared out among all of them
  StartKind start_kind = StartKind::kFresh;  // (start_kind() in object_track.hpp gives a track's)
  cv::Rect box;  // without a mask: a detector's 2D box around it (Observation::box); may be empty
  /// A tracked start (start_kind kTracked) only: the curvature an earlier frame of the track measured
  /// (ObjectTrack::carried_curvature()), carried to the result (carry_pose_curvature()) instead of probed again.
  std::optional<MeasuredCurvature> carried_curvature;
  /// This object's budget when smaller than the call's (a steady track among fresh detections: each object costs
  /// what its own start needs, in the same pass); none: the call's options.
  std::optional<RefineBudget> budget;
};

class RefineRun;  // (src/refine/refine_run.hpp)

/// One view of a rigid target for Refiner::refine_views(): a camera, its images and the mesh as it is in that
/// view. Every view has the same pose (model -> camera) and the same camera frame: e.g. captures of a robot by
/// one static camera, each with the robot's links placed as in that capture (calibration.hpp).
struct RefineView {
  Camera camera;
  Observation observed;  // rgb and / or depth, optional mask (all views have one or none)
  const Mesh* mesh = nullptr;
  /// The mask was derived from depth alone (Calibrator::derive_mask()): where there is no depth reading it knows
  /// nothing (its holes are 0.5), so the verdict's IoU leaves those pixels out.
  bool mask_from_depth = false;
};

/// Refines poses. Options are passed per call (as Ceres passes Solver::Options to Solve); a call without them uses
/// the options the Refiner was made with. A call's options must keep the Refiner's `device` and `render` (they
/// built its renderer); every other option is free per call. Invalid options throw std::invalid_argument.
/// Unusable input (a NaN or empty start, the object behind the camera or outside the image, images that do not
/// match the camera, neither rgb nor depth) is never thrown: the result's `error` says what was wrong (pose =
/// the first start, plausible = false), for refine(), refine_views() and refine_all() alike.
class Refiner {
 public:
  explicit Refiner(const RefinerOptions& options = RefinerOptions());
  /// With a renderer of the caller's choosing (options.device is then not used).
  Refiner(const RefinerOptions& options, std::unique_ptr<Renderer> renderer);
  /// The options of calls that pass none (those the Refiner was made with).
  const RefinerOptions& options() const { return options_; }
  /// The backend in use ("cpu" or "cuda").
  std::string backend() const { return renderer_->name(); }
  /// Does now what the first refinement of `mesh` would otherwise pay: the shape analysis and print axes (cached
  /// per mesh and options) and the renderer's copy of its geometry and textures (48 MB for a 2048^2 atlas). A
  /// node calls it while loading its objects, so its first detection is refined as fast as the later ones.
  void prepare(const Mesh& mesh);

  /// Refines one object. `observed` holds the full-resolution images (any of rgb / depth / mask may be
  /// empty; at least one of rgb or depth is needed), `camera` their intrinsics.
  RefineResult refine(const Camera& camera, const Observation& observed, const Mesh& mesh, const Pose& initial,
                      const RefinerOptions& options);
  RefineResult refine(const Camera& camera, const Observation& observed, const Mesh& mesh, const Pose& initial) {
    return refine(camera, observed, mesh, initial, options_);
  }
  /// Several initial poses (say a fresh detection and the previous frame's refined pose): run i starts from
  /// initials[i % n]; the lowest loss wins whichever start it came from (RefineResult::start says which).
  /// initial_loss is the lowest loss among the starts.
  RefineResult refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                      const std::vector<Pose>& initials, const RefinerOptions& options);
  RefineResult refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                      const std::vector<Pose>& initials) {
    return refine(camera, observed, mesh, initials, options_);
  }

  /// Refines one pose seen in several views (the same algorithm; each hypothesis' loss and gradient are the mean
  /// over the views). No shape scan; `pivot_model` (model frame) is the point the steps turn about, e.g. the
  /// centre of what the views show. RefineResult::view_scores holds each view's scores; mask_iou /
  /// depth_inliers and the verdict are the weakest view's; no print registration or curvature probe.
  RefineResult refine_views(const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                            const Eigen::Vector3d& pivot_model, const RefinerOptions& options);
  RefineResult refine_views(const std::vector<RefineView>& views, const std::vector<Pose>& initials,
                            const Eigen::Vector3d& pivot_model) {
    return refine_views(views, initials, pivot_model, options_);
  }

  /// Refines every object of one frame (the frame's rgb and depth, each object's own mask). An object whose
  /// input is unusable gets its reason in RefineResult::error; the others are still refined. The objects run in
  /// lockstep: each iteration evaluates the runs of all objects in one renderer call (one launch per stage on
  /// CUDA; one parallel loop over all their runs on the CPU), and the frame is resized once for all of them.
  /// Each result is what refine() would give for that object alone; on_iteration is not called.
  std::vector<RefineResult> refine_all(const Camera& camera, const Observation& frame,
                                       const std::vector<ObjectTarget>& objects, const RefinerOptions& options);
  std::vector<RefineResult> refine_all(const Camera& camera, const Observation& frame,
                                       const std::vector<ObjectTarget>& objects) {
    return refine_all(camera, frame, objects, options_);
  }

  /// Optional progress callback, called once per iteration of refine() (iteration 0..total, total = the
  /// configured iterations) with the best loss of any run so far; a retried refinement (retry_turn) counts
  /// 0..total again for its second pass.
  using Progress = std::function<void(int iteration, int total, double best_loss)>;
  Progress on_iteration;

 private:
  /// `o`, validated and checked against the renderer's device and render options.
  const RefinerOptions& checked(const RefinerOptions& o) const;
  /// The model-frame turns of `mesh`'s near symmetries (RefinerOptions::shape_tolerance): what the shape scan
  /// tries and the result's print is weighed at; none for a tracked start or at shape_tolerance 0.
  std::vector<Pose> shape_turns(const RefinerOptions& o, const Mesh& mesh, StartKind kind);
  /// The axes the print alignment turns `mesh` about (RefinerOptions::print_search; none when it is off).
  std::vector<ShapeRotation> print_axes(const RefinerOptions& o, const Mesh& mesh);
  /// Whether the model-frame `turn` is one of the mesh's declared symmetries.
  bool is_declared_turn(const RefinerOptions& o, const Mesh& mesh, const Pose& turn) const;
  /// The shape analysis of `mesh`, computed once per mesh.
  const std::vector<ShapeRotation>& shape_rotations(const Mesh& mesh);
  /// refine() and refine_all(): a pass, then the retry of the rejected fresh starts (RefinerOptions::retry_turn).
  /// `progress`: on_iteration (refine()), or null.
  std::vector<RefineResult> refine_targets(const RefinerOptions& o, const Camera& camera, const Observation& frame,
                                           const std::vector<ObjectTarget>& objects, const Progress& progress);
  /// One pass of refine_targets(), without the retry: every object's run in lockstep on the frame resized once.
  std::vector<RefineResult> refine_pass(const RefinerOptions& o, const Camera& camera, const Observation& frame,
                                        const std::vector<ObjectTarget>& objects, const Progress& progress);
  /// Whether `first` is rejected and due for a retry (RefinerOptions::retry_turn).
  static bool wants_retry(const RefinerOptions& o, const RefineResult& first);
  /// The retry's starts: `initials`, then each turned by +-retry_turn about the principal axes of `mesh`.
  std::vector<Pose> retry_starts(const RefinerOptions& o, const Mesh& mesh, const std::vector<Pose>& initials);

  RefinerOptions options_;
  std::unique_ptr<Renderer> renderer_;
  std::map<uint64_t, std::vector<ShapeRotation>> shape_rotations_;  // by Mesh::content_id(), analysed once
  std::map<std::pair<uint64_t, double>, std::optional<ShapeRotation>> revolution_fits_;  // by (mesh, tolerance)
};

/// Hypothesis evaluations (one render + loss + gradient of one pose, in one view) that refining one object with
/// `o` costs at most: the sum of every stage's planned_evaluations(o, stage). An early stop (of the descent, the
/// polish or the Newton rounds) only lowers it; a retry of a rejected result (retry_turn) doubles it for that
/// object. The unit of RefineTimeEstimator (refine_time.hpp).
long planned_evaluations(const RefinerOptions& o);
/// What `stage` costs at most, in the same unit, with one start (a tracked start's two cost one evaluation more):
///   - kDescent: the runs of every iteration, less those successive halving drops; the shape scan as for a shape
///     with the most turns (kMaxShapeTurns; an asymmetric one has none) and its candidate run; without a mask
///     (derive_mask), the renders the object's pixels are derived about (the starts, then the better half of the
///     runs);
///   - kWeighStarts: the start's loss at the fine scale; kWeighCandidate: the print's registration at the
///     candidate and at the start's basin;
///   - kDerivePixels (derive_mask): the render the pixels are derived about at the result, and the result's and
///     the starts' losses under them;
///   - kPolish; kAlignPrintAndStep: the print alignment about one axis (a shape with several axes of near
///     revolution costs more) and the Newton steps, each twice (they run again when the steps move far);
///   - kWeighShapeTurns: a registration at the result and per shape turn, then the loss, polish, alignment and
///     steps from the one the print prefers, and its registration;
///   - kScore: the scoring render and the curvature probe.
long planned_evaluations(const RefinerOptions& o, RefineStage stage);

/// Why refine() would refuse `start` as an initial pose of `mesh` seen by `camera` with `o` ("" when it would
/// not): not finite, its centre not beyond render.near_plane (behind the camera), outside the image or too small
/// in it at the refining scale. The check refine() makes of every start.
std::string start_problem(const Camera& camera, const Mesh& mesh, const Pose& start, const RefinerOptions& o);
/// The indices of `starts` that refine() accepts (start_problem() empty), in order; every index when none is, so
/// that refining them still says why. A caller's own guesses (a track's constant-velocity prediction, which a
/// wrong frame can throw behind the camera) are dropped this way rather than failing the object with them.
std::vector<size_t> usable_starts(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& starts,
                                  const RefinerOptions& o);

/// One plain gradient step of the refiner's parametrisation: translation of the object's centre `pivot`
/// (camera frame) and rotation about it, with the scaling described at RefinerOptions::lr_low.
Pose refiner_step(const Pose& pose, const Vector6d& gradient, double lr, double diameter,
                  const Eigen::Vector3d& pivot);

}  // namespace diffdope
