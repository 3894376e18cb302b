// The render and loss options' rows of the option table, and their checks: every number must be finite and inside
// its range, so a typo cannot turn into NaN losses or a hung thread pool.
#include <cmath>

#include "base/option_range.hpp"
#include "diffdope/option_table.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

const std::vector<OptionSpec<RenderOptions>>& render_option_table() {
  using R = RenderOptions;
  static const std::vector<OptionSpec<R>> rows = {
      option_row("cull_back_faces", &R::cull_back_faces, 0, 0, "", "true: always cull back faces (only for closed meshes)"),
      option_row("auto_cull_closed", &R::auto_cull_closed, 0, 0, "",
                 "cull when the mesh is closed and wound outward (exact from outside the object)"),
      option_row("near_plane", &R::near_plane, 0, 10, " metres", "triangles with a vertex nearer than this are not drawn",
                 true),
      option_row("roi_margin", &R::roi_margin, 0, R::kMaxRoiMargin, " pixels",
                 "pixels added around the region of interest (projected model box and observed mask)"),
      option_row("lod_pixel_error", &R::lod_pixel_error, 0, 100, " pixels (0: always the full mesh)",
                 "draw the coarsest simplified mesh whose error projects below this"),
      option_row("threads", &R::threads, 0, R::kMaxThreads, " (0: all cores)", "worker threads of the CPU executor"),
  };
  return rows;
}

const std::vector<OptionSpec<LossOptions>>& loss_option_table() {
  using L = LossOptions;
  static const std::vector<OptionSpec<L>> rows = {
      option_row("weight_rgb", &L::weight_rgb, 0, L::kMaxWeight, "", "colour term"),
      option_row("weight_depth", &L::weight_depth, 0, L::kMaxWeight, "", "depth term"),
      option_row("weight_mask", &L::weight_mask, 0, L::kMaxWeight, "", "mask term"),
      option_row("rgb_miss", &L::rgb_miss, 0, 10, "", "cost of an observed object pixel the render does not cover"),
      option_row("depth_truncation", &L::depth_truncation, 1e-4, 10, " metres", "depth errors saturate here"),
      option_row("occlusion_margin", &L::occlusion_margin, 0, 10, " metres (0: off)",
                 "the mask term skips pixels where the observed depth shows an occluder this much in front"),
      option_row("weight_edges", &L::weight_edges, 0, L::kMaxWeight, "",
                 "the paper's edge term (Canny of the image against Sobel of the render; off: docs/benchmarks.md)"),
      option_row("edge_scale", &L::edge_scale, 1e-3, 100, "", "Sobel magnitude at which a rendered edge counts half"),
      option_row("weight_texture", &L::weight_texture, 0, L::kMaxWeight, "",
                 "Sobel of the log grey level, a lighting-robust print term (off: docs/benchmarks.md)"),
      option_row("texture_epsilon", &L::texture_epsilon, 1e-3, 1, "", "grey offset inside the texture term's log"),
      option_row("depth_noise_power", &L::depth_noise_power, 0, 2, " (0: every reading alike; 2: stereo, RealSense)",
                 "the depth noise grows as z^power: each reading weighs as its noise allows"),
  };
  return rows;
}

void RenderOptions::validate() const { check_option_ranges(render_option_table(), *this, {"render options"}, "render."); }

bool operator==(const RenderOptions& a, const RenderOptions& b) {
  return a.cull_back_faces == b.cull_back_faces && a.auto_cull_closed == b.auto_cull_closed &&
         a.near_plane == b.near_plane && a.roi_margin == b.roi_margin && a.use_roi == b.use_roi &&
         a.lod_pixel_error == b.lod_pixel_error && a.threads == b.threads;
}

bool operator==(const LossOptions& a, const LossOptions& b) {
  return a.weight_rgb == b.weight_rgb && a.weight_depth == b.weight_depth && a.weight_mask == b.weight_mask &&
         a.weight_edges == b.weight_edges && a.edge_scale == b.edge_scale && a.weight_texture == b.weight_texture &&
         a.texture_epsilon == b.texture_epsilon && a.rgb_miss == b.rgb_miss &&
         a.depth_truncation == b.depth_truncation && a.occlusion_margin == b.occlusion_margin &&
         a.depth_noise_power == b.depth_noise_power;
}

void LossOptions::validate() const {
  const OptionRange check{"loss options"};
  check_option_ranges(loss_option_table(), *this, check, "loss.");
  if (weight_rgb + weight_depth + weight_mask + weight_edges + weight_texture == 0)
    check.fail("every loss weight is 0: nothing to minimise");
}

}  // namespace diffdope
