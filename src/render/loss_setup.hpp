#pragma once
// Loss normalisers and per-call constants shared by the CPU and CUDA backends (internal header): each term is a
// mean over the pixels it is defined on (whole image, not the region of interest, so the value does not depend
// on the region).
#include <algorithm>
#include <vector>

#include <opencv2/core.hpp>

#include "render/kernels/pixel_loss.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

struct LossSetup {
  PixelLossParams P{};
  float k_edges = 0.f, edge_scale = 0.f;
  float k_texture = 0.f, texture_epsilon = 0.f;
  double n_rgb = 0, n_depth = 0;
  bool has_rgb = false, has_mask = false;
};

/// The median depth reading over the observed mask (all readings without one); 0 without any.
inline float median_observed_depth(const Observation& obs) {
  std::vector<float> z;
  for (int y = 0; y < obs.depth.rows; ++y) {
    const float* d = obs.depth.ptr<float>(y);
    const float* m = obs.has_mask() ? obs.mask.ptr<float>(y) : nullptr;
    for (int x = 0; x < obs.depth.cols; ++x)
      if (d[x] > 0.f && (!m || m[x] > 0.f)) z.push_back(d[x]);
  }
  if (z.empty()) return 0.f;
  std::nth_element(z.begin(), z.begin() + long(z.size() / 2), z.end());
  return z[z.size() / 2];
}

inline LossSetup make_loss_setup(const Camera& camera, const Observation& obs, const LossOptions& loss) {
  LossSetup s;
  if (obs.has_mask()) {
    s.n_rgb = cv::sum(obs.mask)[0];
    if (obs.has_depth()) {
      cv::Mat valid;
      cv::compare(obs.depth, 0.0, valid, cv::CMP_GT);
      valid.convertTo(valid, CV_32F, 1.0 / 255.0);
      s.n_depth = cv::sum(valid.mul(obs.mask))[0];
    }
  } else {
    s.n_rgb = static_cast<double>(camera.width) * camera.height;
    if (obs.has_depth()) s.n_depth = cv::countNonZero(obs.depth > 0);
  }
  s.has_rgb = obs.has_rgb();
  s.has_mask = obs.has_mask();
  PixelLossParams& P = s.P;
  P.k_rgb = (obs.has_rgb() && s.n_rgb > 0) ? static_cast<float>(loss.weight_rgb / s.n_rgb) : 0.f;
  P.k_depth = (obs.has_depth() && s.n_depth > 0) ? static_cast<float>(loss.weight_depth / s.n_depth) : 0.f;
  P.k_mask = (obs.has_mask() && s.n_rgb > 0) ? static_cast<float>(loss.weight_mask / s.n_rgb) : 0.f;
  P.rgb_miss = static_cast<float>(loss.rgb_miss);
  P.depth_trunc = static_cast<float>(loss.depth_truncation);
  P.depth_noise_power = 0;
  P.depth_noise_scale = 0.f;
  if (loss.depth_noise_power > 0 && obs.has_depth()) {
    const float z_ref = median_observed_depth(obs);
    if (z_ref > 0.f) P.depth_noise_power = loss.depth_noise_power, P.depth_noise_scale = 1.f / z_ref;
  }
  P.occlusion_margin = static_cast<float>(loss.occlusion_margin);
  s.k_edges = (obs.has_edges() && s.n_rgb > 0) ? static_cast<float>(loss.weight_edges / s.n_rgb) : 0.f;
  s.edge_scale = static_cast<float>(loss.edge_scale);
  s.k_texture = (obs.has_texture() && s.n_rgb > 0) ? static_cast<float>(loss.weight_texture / s.n_rgb) : 0.f;
  s.texture_epsilon = static_cast<float>(loss.texture_epsilon);
  return s;
}

/// Per-term means and the weighted total from the per-pixel sums.
inline void finish_loss(const LossSetup& s, double sum_rgb, double sum_depth, double sum_mask, double sum_edges,
                        double sum_texture, LossValue* res) {
  res->edges = s.n_rgb > 0 && s.k_edges != 0.f ? sum_edges / s.n_rgb : 0.0;
  res->texture = s.n_rgb > 0 && s.k_texture != 0.f ? sum_texture / s.n_rgb : 0.0;
  res->rgb = s.n_rgb > 0 && s.has_rgb ? sum_rgb / s.n_rgb : 0.0;
  res->depth = s.n_depth > 0 ? sum_depth / s.n_depth : 0.0;
  res->mask = s.n_rgb > 0 && s.has_mask ? sum_mask / s.n_rgb : 0.0;
  res->total = s.P.k_rgb * sum_rgb + s.P.k_depth * sum_depth + s.P.k_mask * sum_mask + s.k_edges * sum_edges +
               s.k_texture * sum_texture;
}

}  // namespace diffdope
