#pragma once
// How long a refinement will take, before it runs: a node serving requests on the same worker as its streaming
// refinements must refuse one that would stop streaming for longer than its budget (~max_request_time).
// The unit of work is one hypothesis evaluation; what one costs is learned from the refinements this process has
// timed (the evaluations they made, RefineResult::evaluations), as objects, images and machines differ by orders
// of magnitude. An estimate counts what the options plan at most (planned_evaluations() in refiner.hpp): early
// stops make a refinement shorter, never longer.
#include <deque>
#include <string>

#include "diffdope/refiner.hpp"

namespace diffdope {

class RefineTimeEstimator {
 public:
  /// Cost of one object's evaluation before anything was timed, seconds: a scan-like object at the default
  /// image scale on one core of a 2-core x86-64 VM (docs/benchmarks.md): deliberately on the slow side.
  static constexpr double kPriorSecondsPerEvaluation = 1e-3;
  /// How many recent refinements the estimate looks at (it follows a bigger object or a busier machine within
  /// a few refinements and forgets them after this many).
  static constexpr int kWindow = 16;

  explicit RefineTimeEstimator(double prior_seconds_per_evaluation = kPriorSecondsPerEvaluation);

  /// A refinement that made `evaluations` (RefineResult::evaluations over its objects) took `seconds` of wall time.
  /// Ignored unless both are finite and positive.
  void observe(double evaluations, double seconds);
  /// Seconds per evaluation over the last kWindow observations (their total time over their total evaluations,
  /// so that a small call, whose fixed costs dominate, weighs little); the prior before any.
  double seconds_per_evaluation() const;
  /// Estimated wall time of refining `objects` objects with `options`, seconds.
  double estimate(const RefinerOptions& options, int objects) const;
  int observations() const { return observed_; }

 private:
  double prior_;
  std::deque<std::pair<double, double>> recent_;  // (evaluations, seconds), newest last
  int observed_ = 0;
};

/// The service's time budget: an empty string when refining `objects` objects with `request` is expected to take
/// at most `max_seconds`, else why not, with the estimate and the largest iteration count that would fit at the
/// request's batch size (a caller can retry with it).
std::string check_request_time(const RefinerOptions& request, int objects, const RefineTimeEstimator& estimator,
                               double max_seconds);

}  // namespace diffdope
