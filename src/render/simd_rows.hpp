#pragma once
// The CPU's pixel stages over a row of pixels at once (Highway vectors, chosen at run time for the CPU it runs on):
// the lane kernels (src/render/kernels/*_lanes.inc) on many pixels, the same bits per pixel as their
// one-pixel instantiation. Each runs the row's first pixels, as many as fill whole vectors, and returns how many;
// the caller does the rest one pixel at a time. Built without Highway (pixel_rows.cpp), each does none.
#include "render/kernels/pixel_loss.hpp"
#include "render/kernels/silhouette.hpp"

namespace diffdope {

struct LossRow {
  PixelLossParams P;
  const PixelAttr* post;  // n rendered pixels (after the blends)
  const float* S;         // n observed mask values; nullptr: S = 1
  const float* I;         // 3n observed rgb values; nullptr: 0
  const float* D;         // n observed depths (<= 0: no reading); nullptr: 0
  PixelAttr* g_post;      // n: receives dL/d(post); nullptr: no gradient
  int n;
};

/// The loss pass (pixel_loss_step) on the row's whole vectors. Adds each one's (rgb, depth, mask) terms to sum[0..2] as doubles, one pixel after the other in order: the same sums as adding
/// pixel_loss_step()'s values pixel by pixel. The caller does the rest of the row one pixel at a time.
int loss_row(const LossRow& row, double sum[3]);

/// A row of the shade stage: per pixel, the z-buffer's nearest triangle (-1: none) and its shading at the pixel
/// centre, as pipeline::ShadeStage::pixel() writes them one pixel at a time (shade_pixel(), no clamping).
struct ShadeRow {
  MeshView M;
  ProjectedView G;
  Intrinsics K;
  const unsigned long long* key;  // n z-buffer keys: (depth key << 32) | triangle, all ones = empty
  int* tri;                       // n: receive the triangle
  PixelAttr *pre, *post;          // n: receive the shading (coverage 1) or zeros
  detail::ShadeBary* bary;        // n: receive the barycentrics and texture derivatives (covered pixels only)
  int x;                          // image column of the row's first pixel (pixel centres at integers)
  float y;                        // image row of the row
  int n;
};

/// The shade stage on the whole row (the last vector partly filled); returns n (0 without Highway).
int shade_row(const ShadeRow& row);

/// A row of the blend detection: each pixel's pair with its right neighbour (slot 2 q) and with the pixel below
/// (slot 2 q + 1), as pipeline::BlendDetectStage::pixel() decides them one pixel at a time
/// (discontinuity_blend()). Indices are the region's (q: the pixel's index in the arrays and in its events).
struct BlendRow {
  MeshView M;
  ProjectedView G;
  Intrinsics K;
  const int* tri;           // the region's triangle per pixel (-1: none)
  const PixelAttr* pre;     // the region's shading before the blends (depth: d)
  BlendEvent* events;       // the region's event slots, two per pixel: receive the events found
  unsigned char* has_event;  // ... and whether each slot holds one
  int q;                    // index of the row's first pixel
  int stride;               // the pixel below pixel q is q + stride
  int right;                // the row's first `right` pixels have a right neighbour in the region
  bool below;               // whether the row below is in the region
  int x;                    // image column of the row's first pixel (pixel centres at integers)
  float y;                  // image row of the row
  int n;
};

/// The blend detection on the whole row (its pairs of different triangles packed into vectors, the longest walks
/// finished one pair at a time); returns n (0 without Highway).
int blend_row(const BlendRow& row);

/// Triangles of a hypothesis for the raster (pipeline::RasterStage), on SIMD vectors: of those drawn (area != 0)
/// whose bounding box of pixel centres (raster_bounds()) meets the region, the small ones (bounds of at most
/// kSmallTriangleCentres per side) are drawn into the z-buffer here (raster_small_setup_lanes()), the others
/// are left to the caller.
struct RasterBatch {
  const int* triangles;  // 3 vertex indices per triangle
  const Vec2f* pix;      // projected vertices
  const Vec3f* cam;      // camera-space vertices (depth: z)
  const float* area;     // signed pixel area per triangle (0: not drawn)
  int first, end;        // the triangles looked at: first .. end - 1
  int rx0, rx1, ry0, ry1;  // the region's pixels (inclusive)
  unsigned long long* key;  // the region's z-buffer, row by row (rx1 - rx0 + 1 per row)
};

/// Looks at the triangles first .. *rest - 1 (whole vectors; *rest: the first of the last partial vector, left to
/// the caller whole): draws the small ones and writes the others that meet the region, in order, into t and
/// their bounds into x0 .. y1 (room for end - first each); returns how many it left.
int raster_batch(const RasterBatch& b, int* t, int* x0, int* x1, int* y0, int* y1, int* rest);

/// The instruction set the rows run on here (e.g. "AVX3", "AVX2", "SSE4"; for the profile and docs/benchmarks.md),
/// or "none (built without Highway)".
const char* simd_row_target();
/// Whether the rows do pixels here (false in a build without Highway).
bool simd_rows_built();

}  // namespace diffdope
