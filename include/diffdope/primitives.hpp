#pragma once
// Simple textured solids: URDF primitives (box, cylinder, sphere) and test objects. Sizes in metres; meshes are
// centred on the origin, triangles wound counter-clockwise seen from outside.
#include <Eigen/Core>
#include <string>

#include "diffdope/mesh.hpp"

namespace diffdope {

/// One colour (a 1x1 texture): a part painted in a flat colour, e.g. a URDF primitive and its material.
Texture make_flat_texture(const Eigen::Vector3f& rgb, const std::string& source = "flat colour");

/// Box of the given size; each face has its own 4 vertices (UV seams on every edge), UVs in a 3x2 atlas.
Mesh make_box(const Eigen::Vector3d& size, Texture texture);
/// Closed cylinder along z (radius, height), `segments` around; side UVs wrap with a seam, caps in the atlas.
Mesh make_cylinder(double radius, double height, int segments, Texture texture);
/// UV sphere with `rings` x `segments` quads (2 triangles each, poles included): 2*rings*segments triangles.
Mesh make_uv_sphere(double radius, int rings, int segments, Texture texture);
/// An asymmetric object (an L-shaped block made of two boxes), for pose ambiguity-free tests.
Mesh make_l_block(double size, Texture texture);

}  // namespace diffdope
