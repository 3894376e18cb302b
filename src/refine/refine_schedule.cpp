#include "refine/refine_schedule.hpp"

#include <algorithm>
#include <cmath>

namespace diffdope {

Camera scaled_camera(const Camera& camera, double scale) { return scale == 1.0 ? camera : camera.scaled(scale); }

double milliseconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

int coarse_iterations(const RefinerOptions& o) {
  if (!(o.coarse_scale < 1.0) || o.iterations < 2) return 0;
  return std::min(int(std::floor(o.coarse_fraction * o.iterations)), o.iterations - 1);
}

int scan_iteration(const RefinerOptions& o) {
  if (!o.shape_scan || !(o.shape_tolerance > 0)) return -1;
  const int switch_at = coarse_iterations(o);
  return switch_at > 0 ? switch_at : (o.iterations >= 2 ? o.iterations / 2 : -1);
}

int halvings_due(int k, int iters) {
  int due = 0;
  for (int quarter = 1; quarter <= 3; ++quarter) due += quarter * iters / 4 > 0 && k >= quarter * iters / 4;
  return due;
}

bool uses_texture(const RefinerOptions& o, Phase phase) {
  if (o.loss.weight_texture > 0) return true;
  const bool scan_compares_print = scan_iteration(o) >= 0 && o.scan_texture_weight > 0;
  return phase == Phase::kFine && o.shape_tolerance > 0 && (scan_compares_print || o.print_search > 0);
}

Observation scale_frame(const Camera& camera, const Observation& frame, const RefinerOptions& o, double scale,
                        Phase phase) {
  Observation f = frame.with_mask(cv::Mat());
  f.validate(camera);
  if (scale != 1.0) f = f.resized(scaled_camera(camera, scale));
  if (o.loss.weight_edges > 0 && f.has_rgb() && !f.has_edges()) f.edges = observed_edges(f.rgb);
  if (uses_texture(o, phase) && f.has_rgb()) f.texture = observed_texture(f.rgb, o.loss.texture_epsilon);
  return f;
}

}  // namespace diffdope
