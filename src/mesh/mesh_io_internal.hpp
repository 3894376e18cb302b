#pragma once
// What the parts of Mesh::load share: the checks of a file before assimp sees it (mesh_file_checks.cpp), the
// import with assimp (assimp_import.cpp), texture decoding (texture_io.cpp) and the model passed between them.
#include <string>
#include <vector>

#include "diffdope/mesh.hpp"

namespace diffdope {
namespace mesh_io {

/// Throws std::runtime_error "Mesh::load('model'): what".
[[noreturn]] void fail(const std::string& model, const std::string& what);

std::string lower(std::string s);
std::string trim(const std::string& s);

// ---- PLY ----

// What we need from a PLY file that assimp does not tell us: the `comment TextureFile` name (assimp 5.2 does map
// it to the material's diffuse texture; this is a fallback), whether the file has a real `element material` (if
// not, assimp's material is a generated white one that must not override MeshLoadOptions::default_color), the
// face count (to report "no triangles" instead of assimp's obscure message for vertex-only files), and whether
// the body is what the header declares: assimp reads face indices and list counts unchecked (out-of-range
// indices, truncated bodies and garbage lines crash it or read out of bounds), so the whole body is walked here
// first and every face index checked against the vertex count.
struct PlyProperty {
  std::string name;
  int size = 0;        // bytes of a scalar (the list's items when is_list)
  int count_size = 0;  // bytes of a list's count
  bool is_list = false, is_float = false, is_signed = false, count_signed = false;
};
struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};
struct PlyHeader {
  bool is_ply = false;  // first line is "ply"
  bool valid = false;   // end_header found
  std::string format;   // ascii / binary_little_endian / binary_big_endian
  long long num_vertices = 0;
  long long data_lines = 0;     // ascii: non-empty lines after the header
  long long data_bytes = 0;     // bytes after the header
  std::string texture_file;
  bool has_material_element = false;
  long long num_faces = -1;  // -1: no face element
  std::vector<PlyElement> elements;
  std::string body_error;    // what is wrong with the body ("" = it matches the header)
};

/// The PLY checks of Mesh::load: reads the header and body and throws (fail) when the file is not a complete,
/// consistent PLY within the options' vertex and triangle limits.
PlyHeader check_ply(const std::string& path, const MeshLoadOptions& options);

/// GLB: the chunk lengths must fit in the file (assimp allocates what the header says before reading).
void check_glb(const std::string& path);

/// Whether `file` (resolved: `..` and links followed) lies in the model's folder or below, or in one of
/// MeshLoadOptions::resource_dirs.
bool in_resource_dirs(const std::string& model, const std::string& file, const MeshLoadOptions& options);
/// The message of a reference `ref` (the model names it `what`, e.g. "texture") that resolves to `file`, outside
/// the folders a model may read.
std::string outside_message(const std::string& model, const std::string& what, const std::string& ref,
                            const std::string& file);

/// A polygon's vertices at most (PLY, OBJ): assimp's triangulation of an n-gon costs n^2, and a scan's faces are
/// triangles or small polygons.
constexpr long long kMaxPolygonVertices = 1024;

/// OBJ: vertex and triangle counts within the options' limits, no polygon beyond kMaxPolygonVertices; a material
/// library it names must exist (else assimp loads the mesh grey without a word), be a regular file and lie in the
/// resource folders.
void check_obj(const std::string& path, const MeshLoadOptions& options);

/// glTF: every buffer and image it names by URI (not data: URIs) must be a regular file in the resource folders
/// (assimp opens them itself, a pipe would hang it).
void check_gltf_uris(const std::string& path, const MeshLoadOptions& options);

// ---- the imported model ----

/// A texture as the model file names it: a file found next to the model, or bytes embedded in it.
struct TextureSource {
  std::string ref;       // as the model names it
  std::string file;      // resolved path; empty when embedded
  std::string embedded;  // compressed image bytes (PNG, JPEG, ...), or raw BGRA texels when raw_width > 0
  int raw_width = 0, raw_height = 0;
};

/// What assimp gives us of a model: triangles with UVs and colours, and where their textures are. Built in the
/// import child process (see Mesh::load), sent to the parent as bytes.
struct ImportedModel {
  std::vector<Vec3f> positions, colors;
  std::vector<Vec2f> uvs;
  std::vector<int> triangles, tri_texture;  // tri_texture: index into `textures`, -1 = none
  std::vector<TextureSource> textures;
};

/// The import (assimp), run in a child process by Mesh::load. `ply` is the file's checked header when is_ply.
ImportedModel import_with_assimp(const std::string& path, const MeshLoadOptions& options, const PlyHeader& ply,
                                 bool is_ply);

/// A texture decoded in the caller's process, its size checked first (MeshLoadOptions::max_texture_pixels) and
/// downsampled to MeshLoadOptions::max_texture_size. `model` names the model file in messages.
Texture decode_texture(const std::string& model, const TextureSource& src, const MeshLoadOptions& options);

}  // namespace mesh_io
}  // namespace diffdope
