// Range checks of the render and loss options: every number must be finite and inside its documented range
// (include/diffdope/renderer.hpp), so a typo cannot turn into NaN losses or a hung thread pool.
#include <cmath>

#include "base/option_range.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

void RenderOptions::validate() const {
  const OptionRange check{"render options"};
  check.above("render.near_plane", near_plane, 0, 10, " metres");
  check("render.roi_margin", roi_margin, 0, kMaxRoiMargin, " pixels");
  check("render.lod_pixel_error", lod_pixel_error, 0, 100, " pixels (0: always the full mesh)");
  check("render.threads", threads, 0, kMaxThreads, " (0: all cores)");
}

bool operator==(const RenderOptions& a, const RenderOptions& b) {
  return a.cull_back_faces == b.cull_back_faces && a.auto_cull_closed == b.auto_cull_closed &&
         a.near_plane == b.near_plane && a.roi_margin == b.roi_margin && a.use_roi == b.use_roi &&
         a.lod_pixel_error == b.lod_pixel_error && a.threads == b.threads;
}

void LossOptions::validate() const {
  const OptionRange check{"loss options"};
  check("loss.weight_rgb", weight_rgb, 0, kMaxWeight);
  check("loss.weight_depth", weight_depth, 0, kMaxWeight);
  check("loss.weight_mask", weight_mask, 0, kMaxWeight);
  check("loss.weight_edges", weight_edges, 0, kMaxWeight);
  check("loss.weight_texture", weight_texture, 0, kMaxWeight);
  if (weight_rgb + weight_depth + weight_mask + weight_edges + weight_texture == 0)
    check.fail("every loss weight is 0: nothing to minimise");
  check("loss.texture_epsilon", texture_epsilon, 1e-3, 1);
  check("loss.edge_scale", edge_scale, 1e-3, 100);
  check("loss.rgb_miss", rgb_miss, 0, 10);
  check("loss.depth_truncation", depth_truncation, 1e-4, 10, " metres");
  check("loss.occlusion_margin", occlusion_margin, 0, 10, " metres (0: off)");
}

}  // namespace diffdope
