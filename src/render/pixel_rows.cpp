// The rows of simd_rows.hpp in a build without Highway: each does none of its pixels, so the CPU executor hands
// every pixel to the one-pixel kernels, whose bits the SIMD rows reproduce. The same results, slower.
#include "render/simd_rows.hpp"

namespace diffdope {

int loss_row(const LossRow&, double*) { return 0; }
int shade_row(const ShadeRow&) { return 0; }
int blend_row(const BlendRow&) { return 0; }
int raster_batch(const RasterBatch& b, int*, int*, int*, int*, int*, int* rest) {
  *rest = b.first;  // every triangle is the caller's
  return 0;
}
const char* simd_row_target() { return "none (built without Highway)"; }
bool simd_rows_built() { return false; }

}  // namespace diffdope
