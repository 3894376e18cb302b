#pragma once
// Procedural textured meshes and textures, for tests, benchmarks, the demo and the synthetic dataset generator.
// All sizes in metres; meshes are centred on the origin, triangles wound counter-clockwise seen from outside.
#include <Eigen/Core>
#include <cstdint>

#include "diffdope/mesh.hpp"

namespace diffdope {

/// A smooth, colourful texture (sums of sinusoids plus soft blobs) with enough detail for the colour term and
/// no hard texel edges. `seed` varies the pattern.
Texture make_pattern_texture(int size, uint32_t seed);
/// A "printed box" texture: smooth background with sharp-edged labels and stripes (realistic, less smooth).
Texture make_label_texture(int size, uint32_t seed);

/// Box of the given size; each face has its own 4 vertices (UV seams on every edge), UVs in a 3x2 atlas.
Mesh make_box(const Eigen::Vector3d& size, Texture texture);
/// Closed cylinder along z (radius, height), `segments` around; side UVs wrap with a seam, caps in the atlas.
Mesh make_cylinder(double radius, double height, int segments, Texture texture);
/// UV sphere with `rings` x `segments` quads (2 triangles each, poles included): 2*rings*segments triangles.
Mesh make_uv_sphere(double radius, int rings, int segments, Texture texture);
/// An asymmetric object (an L-shaped block made of two boxes), for pose ambiguity-free tests.
Mesh make_l_block(double size, Texture texture);

}  // namespace diffdope
