#pragma once
// The refiner's tuning constants, in one place: each with its unit, what it guards and why it has that value.
// None was fitted to a dev set; where a value was checked on one, docs/benchmarks.md gives the figures. The
// options a user may change (RefinerOptions) are not here: these are the refiner's own judgement.
#include <cmath>

namespace diffdope {

// ---- The start -------------------------------------------------------------------------------------------------

/// Pixels across (at the refining scale) below which an initial pose is refused: a smaller object has nothing to
/// be refined against, and a refinement would only "converge" on noise.
constexpr double kMinProjectedPixels = 2.0;
/// A detector's box (Observation::box) bounds the object's pixels grown by this fraction of its size on every side,
/// and by a pixel: a detector's box is seldom exact to the pixel, and at a coarser scale its rounding grows it too.
constexpr double kBoxSlack = 0.05;

// ---- The shape analysis and the shape scan ---------------------------------------------------------------------

/// Turns the shape analysis tries about each principal axis: multiples of 360 / 12 = 30 degrees, the coarsest
/// step at which the descent still finds the basin of the truth from the nearest one.
constexpr int kShapeAngleSteps = 12;
/// Turns the scan tries at most: 11 about an axis of revolution and a few flips. Bounds the scan's cost
/// (planned_evaluations() counts it).
constexpr int kMaxShapeTurns = 15;
/// Surface samples of the shape analysis (per sample set): enough for a discrepancy of a few thousandths of the
/// diameter, the scale shape_tolerance is given in.
constexpr int kShapeSamples = 1024;
/// Reweighting rounds of the fit of an axis of revolution: the inlier set settles within a few.
constexpr int kRevolutionFitRounds = 12;
/// A fitted sample's distance to the axis' normal-line model counts as an inlier within this many times the median
/// (a robust cut: a mug's handle is not the body).
constexpr double kRevolutionInlierCut = 3.0;
/// Share of the surface that must map onto itself about a fitted axis of revolution (a mug's body: most of it, not
/// the handle), checked at turns of 10, 20 and 40 degrees (every scale the print search spans).
constexpr double kRevolutionShare = 0.75;
constexpr double kRevolutionCheckDegrees[] = {10.0, 20.0, 40.0};
/// Two axes are the same when their directions are within this angle (radians) and their lines pass within
/// kSameAxisOffset (of the diameter) of each other: the analysis' axes are exact to a degree or so.
constexpr double kSameAxisAngle = 3.0 * M_PI / 180.0;
constexpr double kSameAxisOffset = 0.005;
/// A turn is a declared symmetry's when within this angle (radians) of one: the analysis' 30-degree steps are
/// told apart by far less.
constexpr double kDeclaredTurnAngle = 0.1;
/// A turned pose in the scan is a candidate only when its loss is lower than its run's own by more than this
/// fraction: on a print the loss barely sees, near ties would pick one at random.
constexpr double kScanMargin = 0.01;
/// Candidate runs the scan adds at most: of the turns some run prefers, those of lowest loss. The final choice
/// weighs only the best, and each costs a run through the fine phase (one instead of one per turn gave the same
/// results on the dev sets).
constexpr int kScanCandidates = 1;

// ---- The jump from the start's basin to a scan candidate -----------------------------------------------------

/// Standard deviations above its chance level at which a print's registration is clear evidence on its own: the
/// usual bar of a significant peak.
constexpr double kClearPrint = 3.0;
/// A print registration this many standard deviations of its chance level below another's contradicts a move
/// from that pose to this one, whatever the loss says (a flipped label that the flat colour term barely sees).
constexpr double kPrintContradiction = 1.0;
/// The relative loss gain a candidate needs without clear print evidence, for a small turn; it grows with the
/// turn's angle (jump_margin()): the detector's pose is a prior, not noise.
constexpr double kJumpMargin = 0.01;
/// Beyond a quarter turn the loss alone never justifies a jump, only the print: a turn that swaps the object's
/// ends or faces swaps where the light falls on it, and the flat colour term's difference then measures the
/// lighting (a can lit from one end fits 51 % better flipped), not the pose.
constexpr double kLossJumpMaxAngle = M_PI / 2;

// ---- The object's pixels without a mask ------------------------------------------------------------------------

/// The mask term's share of its weight (LossOptions::weight_mask) when the mask is derived, for an object or a
/// robot: the derived silhouette is no independent observation, its pixels come from the depth the depth term
/// already compares (and carry its noise), so it counts half (figures: docs/benchmarks.md, docs/calibration.md).
constexpr double kDerivedMaskWeight = 0.5;
/// A given mask is taken as given when its outline lies on average within half a pixel, at the refining scale, of
/// the edge depth shows (outline_offset()): what rounding an outline to that grid leaves. Beyond it the derived
/// pixels replace the mask (derive_mask).
constexpr double kTrustedOutlineOffset = 0.5;
/// How far (camera pixels) a given mask's translation onto the edge depth shows is sought (best_outline_shift(),
/// reported, not acted on): a colour camera misregistered to depth, or a label drawn from a pose off the image,
/// puts a mask a few pixels off as a whole (3-7 px on a real RGB-D camera's frames, docs/benchmarks.md).
constexpr double kMaxMaskShift = 8.0;
/// A pixel of a mask's outline counts at most this far (pixels) from the reference's: a blob, or a stretch of
/// outline the depth cannot see (a dark or shiny edge, the foot on a table), weighs no more than a clear miss.
constexpr double kOutlineOffsetCap = 3.0;
/// A surface is a plane found by RANSAC when at least kPlaneNormalShare of its points face as it does, within
/// kPlaneNormalAngle (radians), their faces measured kNormalBaseline (metres) to each side: nearly all of a
/// plane's points face as it does, few of a slab's through other surfaces; a centimetre averages a sensor's noise.
constexpr double kPlaneNormalShare = 0.5;
/// The planes beside the object (a table, a wall): RANSAC's tolerance (metres) admits a sensor's noise at a few
/// metres; a plane must cover kMinPlaneShare of the image; at most kMaxPlanes are removed; what is removed lies
/// within kPlaneBandSigmas of the plane's own spread, and at least kMinPlaneBand (metres) of it.
constexpr double kPlaneTolerance = 0.02;
constexpr double kMinPlaneShare = 0.005;
constexpr int kMaxPlanes = 6;
constexpr double kPlaneBandSigmas = 3.0;
constexpr double kMinPlaneBand = 0.005;
constexpr double kPlaneNormalAngle = 30.0 * 3.14159265358979323846 / 180.0;
constexpr double kNormalBaseline = 0.01;
/// Colour histogram bins per channel for the holes depth leaves: 16 bins of RGB keep an object's print apart from
/// a table's grain while a few thousand pixels still fill the bins that matter.
constexpr int kColourBins = 16;

// ---- The polish ------------------------------------------------------------------------------------------------

/// The polish stops once its best loss has not fallen by kPolishTolerance (relative) for kPolishPatience
/// iterations: a result that was already converged (an easy start) costs a few evaluations, not all.
constexpr int kPolishPatience = 5;
constexpr double kPolishTolerance = 1e-4;

// ---- The print: its registration and its alignment -------------------------------------------------------------

/// Below this RMS texture gradient the model has no print to register (a plain object): not measured.
constexpr double kMinPrintContrast = 0.05;
/// The print is registered on the render's interior: this many pixels inside its full coverage (the silhouette's
/// gradients fit whenever the shape does), shifted up to kPrintShiftRadius pixels to find its chance level.
constexpr int kPrintInteriorMargin = 2;
constexpr int kPrintShiftRadius = 8;
/// Angles the alignment tries: every kPrintCoarseStep within the range, then every kPrintFineStep within one
/// coarse step of the best (radians; never beyond the range). 2.5 degrees move a 3 cm radius by 1.3 mm, under a
/// pixel at working resolution. A range below kPrintCoarseStep searches nothing.
constexpr double kPrintCoarseStep = 2.5 * M_PI / 180.0;
constexpr double kPrintFineStep = 0.5 * M_PI / 180.0;
/// Range about a tracked start (StartKind::kTracked): the track was aligned on an earlier frame, so only the spin
/// since then is sought. 10 degrees cover 100 deg/s at 10 refined frames/s, with 17 evaluations per axis instead
/// of 41 at the default 0.7 rad.
constexpr double kTrackedPrintSearch = 10.0 * M_PI / 180.0;
/// A turn is kept when the texture term is lower there by more than this fraction of its value at the result,
constexpr double kPrintMargin = 0.01;
/// the refiner's own loss (silhouette, depth, colour) is at most this fraction higher,
constexpr double kPrintLossTolerance = 0.02;
/// and the texture term's relative gain is at least this many times the loss's relative rise (a print that
/// barely registers better must not pay for it with the fit of everything else).
constexpr double kPrintTradeoff = 2.0;
/// The alignment and the Newton steps run at most this many times: once more when the steps went on well past
/// (kPrintLossTolerance) what the alignment compared its turns against.
constexpr int kAlignmentPasses = 2;

// ---- The Newton steps ------------------------------------------------------------------------------------------

/// A Newton step is taken when it raises the log-likelihood of the loss's noise model (pose_covariance(): N =
/// rendered pixels / kCorrelatedPixels Laplace residuals, N·ΔL / L) by more than this many nats: half the pose's
/// six degrees of freedom, what fitting them to noise alone gains on average. A move within the loss's noise
/// keeps the pose the descent left, the one nearer the start.
constexpr double kNewtonEvidence = 3.0;
/// Neighbouring pixels' residuals are not independent (antialiasing, texture filtering, image resampling): the
/// covariance counts one independent observation per this many pixels.
constexpr double kCorrelatedPixels = 4.0;
/// The probe's reach grows up to this fraction of the object's diameter (a valley that goes on), and the trust
/// radius is kNewtonTrustPerReach times the reach: a step within the probed region's quadratic model.
constexpr double kNewtonMaxReach = 0.25;
constexpr double kNewtonTrustPerReach = 2.0;
/// The shares of a Newton step tried (a line search of three, the full step last).
constexpr double kNewtonStepShares[] = {0.25, 0.5, 1.0};
/// Newton rounds at most on a frame of steady tracks: a track is a frame from the truth, and its steps take one
/// or two rounds; the cap bounds the frame's time.
constexpr int kTrackedNewtonRounds = 4;

// ---- The verdict -----------------------------------------------------------------------------------------------

/// Half-width of the depth inlier band in the noise's standard deviations: noise alone leaves 99.7 % inside
/// (Gaussian).
constexpr double kDepthNoiseBand = 3.0;
/// A result has converged when its run's loss changed by at most kConvergedChange (relative) over the last
/// 1 / kConvergedTailDivisor of its iterations (at least two): RefineResult::converged.
constexpr double kConvergedChange = 0.01;
constexpr int kConvergedTailDivisor = 10;

}  // namespace diffdope
