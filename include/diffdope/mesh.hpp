#pragma once
#include <cstdint>
// Triangle mesh in metres (model frame), with what the renderer needs: UVs + textures or vertex colours, and an
// edge adjacency built on welded positions so that vertices duplicated at UV seams do not look like borders.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "diffdope/pose.hpp"
#include "diffdope/symmetry.hpp"
#include "diffdope/vec.hpp"

namespace diffdope {

/// One RGB image, float in [0, 1], row 0 = top image row.
struct TextureImage {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 * width * height
};

/// RGB texture (level 0 in width/height/rgb) and its mip pyramid, built by Mesh::finalize().
struct Texture {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 * width * height
  std::string source;      // file it came from, for messages
  std::vector<TextureImage> mips;  // levels 1.. (each half the previous size, down to 1x1)
};

struct MeshLoadOptions {
  /// Metres per model unit (0.001 for BOP's millimetre models).
  double scale = 1.0;
  /// Colour used when the model has neither texture nor vertex colours, RGB in [0, 1].
  Eigen::Vector3f default_color{0.7f, 0.7f, 0.7f};

  // Hostile files (a corrupt download, a truncated copy) must cost an error, never the process: the file is
  // checked before the importer sees it (PLY bodies walked, GLB chunks and OBJ material libraries checked) and
  // imported (assimp) in a child process with a time and memory limit, whose crash is only an error here.
  bool isolate_import = true;           // false: import in this process (fuzzing, debugging)
  double import_timeout_s = 60;         // the import child is stopped after this long
  size_t import_memory_bytes = size_t(4) << 30;  // address space of the import child (not under sanitizers)
  long long max_vertices = 20000000;    // larger meshes are refused (before anything is allocated for them)
  long long max_triangles = 20000000;
  long long max_texture_pixels = 8192LL * 8192;  // larger texture images are refused before decoding
  /// Textures larger than this on their longer side are downsampled on load (the renderer samples mip levels
  /// far below it; a whole 8k texture would only be memory). 0 = keep the file's size.
  int max_texture_size = 4096;
  /// All a model's textures together, in pixels after the max_texture_size downsampling (each costs 12 bytes per
  /// pixel in memory): a model beyond it is refused. 2^25 is two 4096^2 atlases.
  long long max_total_texture_pixels = 1LL << 25;
  /// Where a model may read its textures, material libraries and glTF buffers from: its own folder and those below
  /// it, and these folders (and those below them). A reference that leaves them (`../../x.png`, an absolute path
  /// elsewhere, a link that points out) is refused: opening a model must not read files the user did not point at.
  std::vector<std::string> resource_dirs;
};

/// Whether this build simplifies dense meshes (built with meshoptimizer); without it every mesh is drawn whole.
bool lods_built();

/// A simplified version of a mesh's surface over the mesh's textures: fewer triangles, and only the vertices they
/// use (corners equal in position, UV and colour merged). Mesh::finalize() builds a chain of them with
/// meshoptimizer (UV seams and borders kept) for dense meshes; the renderer draws the coarsest one whose error
/// projects below RenderOptions::lod_pixel_error, since triangles far smaller than a pixel cost time and show
/// nothing.
struct MeshLod {
  double error = 0;            // metres: meshoptimizer's estimate of the largest deviation from the full surface
  std::vector<Vec3f> positions, colors;
  std::vector<Vec2f> uvs;      // empty when the mesh has none
  std::vector<int> triangles;  // 3 vertex indices (into this level's vertices) per triangle
  std::vector<int> tri_texture;
  std::vector<int> neighbors, opposite;  // as Mesh::neighbors() / opposite_vertices(), for these triangles
  std::vector<unsigned char> seams;
  std::vector<float> tri_uv_area;
  bool closed_outward = false;
  int num_triangles() const { return static_cast<int>(triangles.size() / 3); }
  int num_vertices() const { return static_cast<int>(positions.size()); }
};

/// The most meshes a cache keyed by Mesh::content_id() holds (the renderer's uploads, the refiner's shape
/// analyses): a node that sees ever new meshes stays bounded, and a cache that is full starts again.
constexpr size_t kMaxCachedMeshes = 64;

class Mesh {
 public:
  std::vector<Vec3f> positions;  // metres, model frame
  std::vector<Vec2f> uvs;        // per vertex; empty when the model has none
  std::vector<Vec3f> colors;     // per vertex RGB in [0, 1]; always filled (material or default colour)
  std::vector<int> triangles;    // 3 vertex indices per triangle
  std::vector<int> tri_texture;  // per triangle: index into textures, or -1 for vertex colours
  std::vector<Texture> textures;
  std::string name;              // file name or generator name, for messages
  /// Declared by the caller (objects config, BOP models_info.json); load() leaves it empty. The refiner does not
  /// search along it and reports poses in a canonical form (symmetry.hpp).
  ObjectSymmetry symmetry;

  /// Loads PLY (incl. `comment TextureFile`), OBJ+MTL, glTF/GLB and whatever else assimp reads.
  /// Throws std::runtime_error naming the file and the problem (missing file, missing texture, no triangles).
  static Mesh load(const std::string& path, const MeshLoadOptions& options = {});

  /// Checks consistency, drops nothing silently, computes bounds and adjacency. Call after filling by hand.
  /// Throws std::runtime_error when the mesh is empty, indices are out of range or a vertex lies beyond
  /// kMaxVertexCoordinate.
  void finalize();
  /// Metres from the model's origin a vertex may lie (100 km: any object or robot, in any unit a user may mix up).
  static constexpr float kMaxVertexCoordinate = 1e5f;

  int num_vertices() const { return static_cast<int>(positions.size()); }
  int num_triangles() const { return static_cast<int>(triangles.size() / 3); }
  bool has_texture() const { return !textures.empty(); }
  /// No print: the whole surface is one colour (no texture, or only uniform ones, and one vertex colour, within
  /// kPlainColourSpread): a CAD model, a painted part. Valid after finalize().
  bool plain() const { return plain_; }
  static constexpr float kPlainColourSpread = 2.0f / 255.0f;

  // Geometry summaries (valid after finalize()).
  Eigen::Vector3d bbox_min() const { return bbox_min_; }
  Eigen::Vector3d bbox_max() const { return bbox_max_; }
  Eigen::Vector3d center() const { return 0.5 * (bbox_min_ + bbox_max_); }  // bounding-box centre
  double diameter() const { return diameter_; }  // largest distance between two vertices, metres
  /// The 8 corners of the bounding box, optionally moved by `pose` (model -> camera).
  std::vector<Eigen::Vector3d> bbox_corners() const;
  std::vector<Eigen::Vector3d> bbox_corners(const Pose& pose) const;

  /// Per triangle edge k (v_k -> v_k+1): the triangle across it, or -1 at a border / non-manifold edge.
  const std::vector<int>& neighbors() const { return neighbors_; }
  /// Per triangle edge k: the vertex of the neighbour opposite that edge (valid where neighbors() >= 0).
  const std::vector<int>& opposite_vertices() const { return opposite_; }
  /// Per triangle edge k: 1 where the colour jumps across it (a colour seam: texture, UVs or vertex colours
  /// differ and so does the colour they give, e.g. a box crease; not a UV atlas's chart border).
  const std::vector<unsigned char>& seams() const { return seams_; }

  /// True when the surface is closed and consistently wound with outward normals (back faces then never show
  /// from outside, so the renderer may cull them).
  bool closed_and_outward() const { return closed_outward_; }

  /// Identifies the content as of the last finalize(): unique per finalize() call in this process, kept by
  /// copies (same content). Renderers key their uploads on it. 0 = never finalized.
  uint64_t content_id() const { return content_id_; }

  /// Per triangle: its area in UV units (0 when untextured), for the texture's mip level.
  const std::vector<float>& tri_uv_area() const { return tri_uv_area_; }

  /// Simplified surfaces, each about 1 / kLodStep of the triangles of the one before (a finer choice than halving:
  /// an object seen small then gets a level near the error it can afford) and with a larger error (empty for
  /// meshes of at most kLodMinTriangles triangles). A triangle soup's first level is the whole surface over
  /// merged vertices (error 0). Built by finalize().
  const std::vector<MeshLod>& lods() const { return lods_; }
  static constexpr int kLodMinTriangles = 1024;
  static constexpr double kLodStep = 1.41421356;
  /// Closed and outward (see closed_and_outward()) for level `lod` (0 = the full mesh).
  bool closed_and_outward(int lod) const { return lod == 0 ? closed_outward_ : lods_[lod - 1].closed_outward; }

 private:
  void build_adjacency();
  void build_lods();
  void build_mipmaps();
  Eigen::Vector3d bbox_min_ = Eigen::Vector3d::Zero(), bbox_max_ = Eigen::Vector3d::Zero();
  double diameter_ = 0;
  std::vector<int> neighbors_, opposite_;
  std::vector<unsigned char> seams_;
  std::vector<float> tri_uv_area_;
  bool closed_outward_ = false;
  bool plain_ = false;
  uint64_t content_id_ = 0;
  std::vector<MeshLod> lods_;
};

/// Writes an ASCII PLY (BOP layout: positions times `units_per_metre`, e.g. 1000 for millimetres; texture_u/v and
/// `comment TextureFile <stem>.png` written next to it when textured, else vertex colours). Only the first texture
/// is written. Throws std::runtime_error naming the file.
void save_ply(const Mesh& mesh, const std::string& path, double units_per_metre);

/// A mesh placed in a common frame: `pose` maps its model frame into that frame; `scale` multiplies its
/// coordinates first (per axis, as a URDF mesh's scale).
struct MeshPart {
  const Mesh* mesh = nullptr;
  Pose pose;
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
};
/// One finalized mesh of all parts (vertices moved, textures and colours kept): e.g. a robot's link meshes at one
/// joint configuration, in its base frame. A negative scale's mirror keeps the triangles' outward winding.
/// Throws std::runtime_error when there is no part or a part has no mesh.
Mesh merge_meshes(const std::vector<MeshPart>& parts, const std::string& name);

}  // namespace diffdope
