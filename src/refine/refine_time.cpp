#include "diffdope/refine_time.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace diffdope {

RefineTimeEstimator::RefineTimeEstimator(double prior_seconds_per_evaluation) : prior_(prior_seconds_per_evaluation) {
  if (!(std::isfinite(prior_) && prior_ > 0))
    throw std::invalid_argument("RefineTimeEstimator: the prior cost must be finite and > 0");
}

void RefineTimeEstimator::observe(double evaluations, double seconds) {
  if (!(std::isfinite(evaluations) && evaluations > 0 && std::isfinite(seconds) && seconds > 0)) return;
  recent_.emplace_back(evaluations, seconds);
  if (int(recent_.size()) > kWindow) recent_.pop_front();
  ++observed_;
}

double RefineTimeEstimator::seconds_per_evaluation() const {
  if (recent_.empty()) return prior_;
  double evaluations = 0, seconds = 0;
  for (const auto& [e, s] : recent_) evaluations += e, seconds += s;
  return seconds / evaluations;
}

double RefineTimeEstimator::estimate(const RefinerOptions& options, int objects) const {
  return double(planned_evaluations(options)) * std::max(objects, 0) * seconds_per_evaluation();
}

std::string check_request_time(const RefinerOptions& request, int objects, const RefineTimeEstimator& estimator,
                               double max_seconds) {
  const double estimate = estimator.estimate(request, objects);
  if (estimate <= max_seconds) return "";
  // The largest iteration count that fits (evaluations grow monotonically with iterations).
  RefinerOptions fit = request;
  int lo = 0, hi = request.iterations;
  while (lo < hi) {
    fit.iterations = (lo + hi + 1) / 2;
    if (estimator.estimate(fit, objects) <= max_seconds) lo = fit.iterations;
    else hi = fit.iterations - 1;
  }
  char text[512];
  std::snprintf(text, sizeof text,
                "refused: estimated %.1f s (%d object(s) x %ld evaluations of %d runs x %d iterations at %.2f ms "
                "each, %s) exceeds ~max_request_time = %.1f s; ",
                estimate, objects, planned_evaluations(request), request.batch_size, request.iterations,
                1e3 * estimator.seconds_per_evaluation(),
                estimator.observations() > 0 ? "as measured here" : "before any measurement", max_seconds);
  std::string why = text;
  if (lo >= 1)
    why += "at batch_size " + std::to_string(request.batch_size) + " at most " + std::to_string(lo) +
           " iterations fit";
  else
    why += "not even one iteration fits at batch_size " + std::to_string(request.batch_size) +
           ": ask for fewer runs or objects";
  return why;
}

}  // namespace diffdope
