#include "diffdope/print_alignment.hpp"

#include <algorithm>
#include <cmath>

namespace diffdope {

namespace {
int coarse_steps(double range) { return std::max(0, int(std::floor(range / kPrintCoarseStep + 1e-9))); }
constexpr int kFineSteps = int(kPrintCoarseStep / kPrintFineStep + 0.5) - 1;  // each side of the coarse best

/// The refiner's loss from a value with the texture term at weight 1.
double refiner_loss(const LossValue& v, double texture_weight) { return v.total - (1.0 - texture_weight) * v.texture; }

/// Whether a turn to `to` may be kept over `at` (kPrintMargin, kPrintLossTolerance, kPrintTradeoff).
bool acceptable(const LossValue& at, const LossValue& to, double texture_weight) {
  const double f_at = refiner_loss(at, texture_weight), f_to = refiner_loss(to, texture_weight);
  if (!std::isfinite(f_to) || !std::isfinite(to.texture) || !(at.texture > 0)) return false;
  const double gain = 1.0 - to.texture / at.texture;
  // (a loss of 0 at the result: no rise allowed)
  const double rise = f_at > 0 ? f_to / f_at - 1.0 : (f_to > f_at ? HUGE_VAL : 0.0);
  return gain > kPrintMargin && rise <= kPrintLossTolerance && gain >= kPrintTradeoff * rise;
}
}  // namespace

int print_alignment_evaluations(double range) {
  const int n = coarse_steps(range);
  return n > 0 ? 2 * n + 1 + 2 * kFineSteps : 0;
}

PrintAlignment align_print(const Pose& pose, const ShapeRotation& axis, double range, double texture_weight,
                           const PrintEvaluator& evaluate) {
  PrintAlignment out;
  out.pose = pose;
  const int n = coarse_steps(range);
  if (n == 0) return out;
  std::vector<double> angles;
  for (int k = -n; k <= n; ++k) angles.push_back(k * kPrintCoarseStep);
  std::vector<Pose> poses;
  std::vector<LossValue> values, more;
  const auto turned = [&](double a) {
    ShapeRotation r = axis;
    r.angle = a;
    return pose * r.as_pose();
  };
  for (double a : angles) poses.push_back(turned(a));
  evaluate(poses, values);
  const LossValue at = values[size_t(n)];
  const double f_at = refiner_loss(at, texture_weight);
  out.print_before = out.print_after = at.texture;
  out.loss_before = out.loss_after = f_at;
  // The best turn among those that may be kept (none: the result itself, index n): the lowest sum of the texture
  // term and the loss, each relative to its value at the result (acceptable() keeps at.texture above 0; a loss
  // of 0 there allows no other).
  const auto score = [&](const LossValue& v) {
    return v.texture / at.texture + (f_at > 0 ? refiner_loss(v, texture_weight) / f_at : 1.0);
  };
  const auto best_of = [&](size_t first, size_t best) {
    for (size_t j = first; j < values.size(); ++j)
      if (acceptable(at, values[j], texture_weight) && (best == size_t(n) || score(values[j]) < score(values[best])))
        best = j;
    return best;
  };
  size_t best = best_of(0, size_t(n));
  const double centre = angles[best];
  poses.clear();
  const size_t coarse_count = angles.size();
  for (int m = -kFineSteps; m <= kFineSteps; ++m) {
    const double a = centre + m * kPrintFineStep;
    if (m != 0 && std::abs(a) <= range + 1e-12) angles.push_back(a), poses.push_back(turned(a));
  }
  if (!poses.empty()) evaluate(poses, more);
  values.insert(values.end(), more.begin(), more.end());
  best = best_of(coarse_count, best);
  out.evaluations = int(values.size());
  if (best != size_t(n)) {
    out.pose = turned(angles[best]);
    out.angle = angles[best];
    out.print_after = values[best].texture;
    out.loss_after = refiner_loss(values[best], texture_weight);
  }
  return out;
}

}  // namespace diffdope
