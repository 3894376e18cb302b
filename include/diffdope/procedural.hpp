#pragma once
// Procedural textures and scan-like meshes, for tests, benchmarks, the demo and the synthetic dataset generator
// (the simple solids are in primitives.hpp). Sizes in metres; meshes are centred on the origin, triangles wound
// counter-clockwise seen from outside.
#include <Eigen/Core>
#include <cstdint>

#include "diffdope/mesh.hpp"
#include "diffdope/primitives.hpp"

namespace diffdope {

/// A smooth, colourful texture (sums of sinusoids plus soft blobs) with enough detail for the colour term and
/// no hard texel edges. `seed` varies the pattern.
Texture make_pattern_texture(int size, uint32_t seed);
/// A "printed box" texture: smooth background with sharp-edged labels and stripes (realistic, less smooth).
Texture make_label_texture(int size, uint32_t seed);

/// Kinds of make_scan_like() object. The object's up axis is +z; the proportions listed are the natural ones
/// (x : y : z); other sizes stretch the shape along the axes.
enum class ScanShape {
  /// Mustard/detergent-like bottle (about 0.48 : 0.3 : 1): elliptical body slightly fuller on +y, a waist, a
  /// shoulder to a neck offset towards +x and a ribbed screw cap; printed front (+y) and back (-y) labels. No
  /// symmetry, neither in shape nor in print.
  Bottle,
  /// Mug (about 1.13 : 0.84 : 1): body of revolution with a real wall (outer wall, rounded rim, inner wall,
  /// inner bottom) and a handle towards +x; a printed band around the outer wall leaves the handle side free.
  /// The handle is its own closed shell whose ends sit inside the wall (the two shells interpenetrate, as in
  /// many modelled meshes; the surface is still closed and outward, so culling back faces stays exact).
  Mug,
  /// Printed cardboard box with slightly rounded edges (a superellipsoid, any proportions, e.g. a cereal box
  /// 0.16 : 0.06 : 0.21): brand front (+y), text and barcode back (-y), printed sides, top and bottom.
  Box,
};

/// A scan-like object (what users feed a refiner: photogrammetry / depth scans): a closed, irregular dense
/// triangulation (~`triangles` triangles, default 15000), vertices jittered off any regular grid, a UV atlas of
/// many charts with seams, and a big printed texture (`texture_size`², default 2048) with labels/print.
///
/// - Geometry: each closed part is sampled ring by ring along its smooth parametric surface, ring spacing and
///   vertices per ring following a target edge length that varies smoothly over the surface (triangle areas
///   vary about 1:4), with random ring phases and jittered vertices; rings are stitched greedily, so vertex
///   valences vary as in a remeshed scan. The triangle count is within a few percent of `triangles`.
///   Triangles are wound counter-clockwise seen from outside; closed_and_outward() holds.
/// - Bounding box: exactly `size` (metres, x y z), centred on the origin.
/// - UV atlas: the surface is split into ~25-50 charts grown over the triangles from farthest-point seeds
///   (normals within 60 degrees of the chart's mean normal, a bounded radius; tiny leftovers merged into a
///   neighbour; triangles that would fold in the chart's projection re-charted). Each chart is projected
///   onto its mean plane (UVs counter-clockwise like the triangles, charts disjoint) and packed into its own
///   rectangle of the atlas with a gutter; vertices on chart borders are duplicated with different UVs (seams).
/// - Texture: texel colours are computed from the 3-D surface point (labels, text, barcode, cap ribs...), so
///   the print is continuous across chart seams. A 1.5-texel ring around each chart continues its surface, so
///   filtering at a seam reads the same print on both sides; the other texels outside the charts take the
///   colour of the nearest chart texel (bleeding, as scan textures do), so coarse mip levels show no background.
/// - Deterministic for a given `seed` (shape, triangulation, charts and print).
///
/// Throws std::invalid_argument when a size is not positive, `triangles` < 200 or `texture_size` < 64.
Mesh make_scan_like(ScanShape shape, const Eigen::Vector3d& size, int triangles = 15000, int texture_size = 2048,
                    uint32_t seed = 1);

}  // namespace diffdope
