// The import of a model file with assimp, run in a child process by Mesh::load: triangles in metres with UVs and
// colours, and where their textures are (UV conventions: see mesh_load.cpp).
#include <algorithm>
#include <assimp/BaseImporter.h>
#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/mesh_io_internal.hpp"

namespace diffdope {
namespace mesh_io {

namespace fs = std::filesystem;

namespace {

// Collects the textures a model references, each distinct one once.
class TextureSources {
 public:
  TextureSources(const std::string& model, const aiScene* scene, std::vector<TextureSource>* out,
                 const MeshLoadOptions& options)
      : model_(model), scene_(scene), out_(out), options_(options) {
    dir_ = fs::path(model).parent_path();
    if (dir_.empty()) dir_ = ".";
  }

  int get(const std::string& ref) {
    if (ref.empty()) return -1;
    // Embedded texture ("*N" in glTF/GLB/FBX, or a file name matching an embedded texture's).
    const auto embedded = scene_->GetEmbeddedTextureAndIndex(ref.c_str());
    if (embedded.first != nullptr) {
      const std::string key = "*embedded*" + std::to_string(embedded.second);
      auto it = index_.find(key);
      if (it != index_.end()) return it->second;
      const aiTexture& t = *embedded.first;
      TextureSource src;
      src.ref = ref;
      if (t.pcData == nullptr || t.mWidth == 0) fail(model_, "embedded texture '" + ref + "' is empty");
      if (t.mHeight == 0) {  // compressed: mWidth bytes
        src.embedded.assign(reinterpret_cast<const char*>(t.pcData), t.mWidth);
      } else {  // raw aiTexel (b, g, r, a bytes)
        static_assert(sizeof(aiTexel) == 4, "aiTexel layout");
        if (uint64_t(t.mWidth) * t.mHeight > uint64_t(1) << 28) fail(model_, "embedded texture '" + ref + "' is too big");
        src.raw_width = int(t.mWidth), src.raw_height = int(t.mHeight);
        src.embedded.assign(reinterpret_cast<const char*>(t.pcData), size_t(4) * t.mWidth * t.mHeight);
      }
      return add(key, std::move(src));
    }
    const fs::path file = resolve(ref);
    if (file.empty()) fail(model_, "texture '" + ref + "' not found (looked relative to " + dir_.string() + ")");
    std::error_code ec;
    fs::path canon = fs::weakly_canonical(file, ec);
    const std::string key = ec ? file.string() : canon.string();
    auto it = index_.find(key);
    if (it != index_.end()) return it->second;
    TextureSource src;
    src.ref = ref;
    src.file = file.string();
    return add(key, std::move(src));
  }

 private:
  int add(const std::string& key, TextureSource src) {
    const int idx = static_cast<int>(out_->size());
    out_->push_back(std::move(src));
    index_[key] = idx;
    return idx;
  }

  static bool is_file(const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec);
  }

  fs::path resolve(const std::string& ref) const {
    std::string norm = ref;
    std::replace(norm.begin(), norm.end(), '\\', '/');  // models written on Windows
    std::vector<fs::path> candidates;
    for (const std::string& r : {ref, norm}) {
      const fs::path p(r);
      if (p.is_absolute()) {
        candidates.push_back(p);
      } else {
        candidates.push_back(dir_ / p);
      }
    }
    // Absolute or foreign paths baked in by the authoring tool: try the bare file name next to the model.
    candidates.push_back(dir_ / fs::path(norm).filename());
    // The first that exists in the folders a model may read; one that exists only elsewhere is refused.
    for (const auto& c : candidates)
      if (!c.empty() && is_file(c) && in_resource_dirs(model_, c.string(), options_)) return c;
    for (const auto& c : candidates) {
      std::error_code ec;
      if (!c.empty() && fs::exists(c, ec)) {
        if (!in_resource_dirs(model_, c.string(), options_)) fail(model_, outside_message(model_, "texture", ref, c.string()));
        fail(model_, "texture '" + ref + "' is not a regular file (" + c.string() + ")");
      }
    }
    return {};
  }

  std::string model_;
  const aiScene* scene_;
  std::vector<TextureSource>* out_;
  const MeshLoadOptions& options_;
  fs::path dir_;
  std::map<std::string, int> index_;
};

std::string diffuse_texture_ref(const aiMaterial* mat) {
  if (mat == nullptr) return "";
  for (aiTextureType type : {aiTextureType_DIFFUSE, aiTextureType_BASE_COLOR}) {
    if (mat->GetTextureCount(type) > 0) {
      aiString p;
      if (mat->GetTexture(type, 0, &p) == AI_SUCCESS && p.length > 0) return std::string(p.C_Str());
    }
  }
  return "";
}

}  // namespace

// ---- the import (assimp), run in a child process by Mesh::load ----

ImportedModel import_with_assimp(const std::string& path, const MeshLoadOptions& options, const PlyHeader& ply,
                                 bool is_ply) {
  Assimp::Importer importer;
  // Only the readers of the format the extension names: else assimp sniffs the content of a file its own reader
  // refuses and hands it to any other (a corrupt .gltf read as 3DS allocated terabytes), which puts every one of
  // its ~40 readers in front of hostile input instead of the few our checks cover.
  const std::string ext = lower(fs::path(path).extension().string());
  std::vector<std::unique_ptr<Assimp::BaseImporter>> unregistered;  // (UnregisterLoader hands them back to us)
  for (size_t i = importer.GetImporterCount(); i-- > 0;) {
    const aiImporterDesc* info = importer.GetImporterInfo(i);
    std::istringstream exts(info && info->mFileExtensions ? info->mFileExtensions : "");
    bool reads = false;
    for (std::string e; exts >> e;) reads = reads || "." + lower(e) == ext;
    Assimp::BaseImporter* reader = importer.GetImporter(i);
    if (!reads && reader && importer.UnregisterLoader(reader) == AI_SUCCESS) unregistered.emplace_back(reader);
  }
  if (importer.GetImporterCount() == 0) fail(path, "no reader for '" + ext + "' files");
  // ValidateDataStructure: assimp checks its own output (indices, counts) before the other steps use it.
  const unsigned flags = aiProcess_ValidateDataStructure | aiProcess_Triangulate | aiProcess_PreTransformVertices |
                         aiProcess_JoinIdenticalVertices | aiProcess_SortByPType;
  const aiScene* scene = nullptr;
  try {
    scene = importer.ReadFile(path, flags);
  } catch (const std::exception& e) {
    fail(path, std::string("assimp failed: ") + e.what());
  } catch (...) {
    fail(path, "assimp failed with an unknown error");
  }
  if (scene == nullptr) {
    if (ply.valid && ply.num_faces <= 0) fail(path, "no triangles (the PLY has no faces)");
    fail(path, std::string("assimp failed: ") + importer.GetErrorString());
  }
  if ((scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0 || scene->mNumMeshes == 0) {
    fail(path, "no triangles (the file holds no mesh)");
  }

  // Which meshes contribute triangles, and does any of them have UVs?
  auto tri_count = [](const aiMesh* m) {
    unsigned n = 0;
    for (unsigned f = 0; f < m->mNumFaces; ++f) n += m->mFaces[f].mNumIndices == 3 ? 1u : 0u;
    return n;
  };
  bool any_uv = false;
  size_t total_v = 0, total_t = 0;
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    const aiMesh* m = scene->mMeshes[i];
    if (m == nullptr) continue;
    const unsigned nt = tri_count(m);
    if (nt == 0) continue;
    total_v += m->mNumVertices;
    total_t += nt;
    any_uv = any_uv || m->HasTextureCoords(0);
  }
  if (total_t == 0) fail(path, "no triangles (only points / lines)");
  if (total_v > size_t(options.max_vertices) || total_t > size_t(options.max_triangles))
    fail(path, std::to_string(total_v) + " vertices and " + std::to_string(total_t) +
                   " triangles: more than the limit (MeshLoadOptions: " + std::to_string(options.max_vertices) +
                   " vertices, " + std::to_string(options.max_triangles) + " triangles); simplify the mesh");

  ImportedModel out;
  out.positions.reserve(total_v);
  out.colors.reserve(total_v);
  if (any_uv) out.uvs.reserve(total_v);
  out.triangles.reserve(3 * total_t);
  out.tri_texture.reserve(total_t);

  TextureSources textures(path, scene, &out.textures, options);
  const float scale = static_cast<float>(options.scale);

  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    const aiMesh* m = scene->mMeshes[i];
    if (m == nullptr || tri_count(m) == 0) continue;
    const aiMaterial* mat = m->mMaterialIndex < scene->mNumMaterials ? scene->mMaterials[m->mMaterialIndex] : nullptr;
    const bool has_uv = m->HasTextureCoords(0);

    // Texture: the material's diffuse / base-colour map; for PLY, the header's TextureFile when assimp gave none.
    int tex_index = -1;
    if (has_uv) {
      std::string ref = diffuse_texture_ref(mat);
      if (ref.empty() && is_ply) ref = ply.texture_file;
      tex_index = textures.get(ref);
    }

    // Colour: vertex colours, else a material colour that the file really defines, else the default. Materials
    // that assimp generates itself (PLY without `element material` -> white, "DefaultMaterial" for OBJ without
    // MTL / STL / ...) do not count.
    Vec3f mat_color{options.default_color.x(), options.default_color.y(), options.default_color.z()};
    if (!m->HasVertexColors(0) && mat != nullptr) {
      const bool generated =
          (is_ply && !ply.has_material_element) || std::strcmp(mat->GetName().C_Str(), AI_DEFAULT_MATERIAL_NAME) == 0;
      aiColor4D c;
      if (!generated && (mat->Get(AI_MATKEY_COLOR_DIFFUSE, c) == AI_SUCCESS ||
                         mat->Get(AI_MATKEY_BASE_COLOR, c) == AI_SUCCESS)) {
        mat_color = {c.r, c.g, c.b};
      }
    }

    const int base = static_cast<int>(out.positions.size());
    for (unsigned v = 0; v < m->mNumVertices; ++v) {
      const aiVector3D& p = m->mVertices[v];
      out.positions.push_back({scale * p.x, scale * p.y, scale * p.z});
      if (any_uv) {
        if (has_uv) {
          const aiVector3D& t = m->mTextureCoords[0][v];
          out.uvs.push_back({t.x, t.y});
        } else {
          out.uvs.push_back({0.f, 0.f});
        }
      }
      if (m->HasVertexColors(0)) {
        const aiColor4D& c = m->mColors[0][v];
        out.colors.push_back({std::min(1.f, std::max(0.f, static_cast<float>(c.r))),
                              std::min(1.f, std::max(0.f, static_cast<float>(c.g))),
                              std::min(1.f, std::max(0.f, static_cast<float>(c.b)))});
      } else {
        out.colors.push_back(mat_color);
      }
    }
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points / lines are not rendered
      for (int k = 0; k < 3; ++k) {
        if (face.mIndices[k] >= m->mNumVertices) fail(path, "a face refers to a vertex that does not exist");
        out.triangles.push_back(base + static_cast<int>(face.mIndices[k]));
      }
      out.tri_texture.push_back(tex_index);
    }
  }
  return out;
}

}  // namespace mesh_io
}  // namespace diffdope
