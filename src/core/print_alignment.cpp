#include "diffdope/print_alignment.hpp"

#include <algorithm>
#include <cmath>

namespace diffdope {

namespace {
int coarse_steps(double range) { return std::max(0, int(std::floor(range / kPrintCoarseStep + 1e-9))); }
constexpr int kFineSteps = int(kPrintCoarseStep / kPrintFineStep + 0.5) - 1;  // each side of the coarse best
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
  size_t best = size_t(n);
  for (size_t j = 0; j < values.size(); ++j)
    if (values[j].texture < values[best].texture) best = j;
  const double centre = angles[best];
  poses.clear();
  const size_t coarse_count = angles.size();
  for (int m = -kFineSteps; m <= kFineSteps; ++m)
    if (m != 0) angles.push_back(centre + m * kPrintFineStep), poses.push_back(turned(angles.back()));
  evaluate(poses, more);
  values.insert(values.end(), more.begin(), more.end());
  for (size_t j = coarse_count; j < values.size(); ++j)
    if (values[j].texture < values[best].texture) best = j;
  out.evaluations = int(values.size());
  const auto loss = [&](const LossValue& v) { return v.total - (1.0 - texture_weight) * v.texture; };
  const LossValue& at = values[size_t(n)];
  out.print_before = out.print_after = at.texture;
  out.loss_before = out.loss_after = loss(at);
  const LossValue& b = values[best];
  const double gain = at.texture > 0 ? 1.0 - b.texture / at.texture : 0.0;
  const double rise = loss(at) > 0 ? loss(b) / loss(at) - 1.0 : 0.0;
  if (best != size_t(n) && std::isfinite(b.total) && gain > kPrintMargin && rise <= kPrintLossTolerance &&
      gain >= kPrintTradeoff * rise) {
    out.pose = turned(angles[best]);
    out.angle = angles[best];
    out.print_after = b.texture;
    out.loss_after = loss(b);
  }
  return out;
}

}  // namespace diffdope
