// Mesh::load: any format assimp reads (PLY incl. BOP's `comment TextureFile`, OBJ+MTL, glTF/GLB, ...) into one
// triangle Mesh in metres, with UVs + RGB float textures or per-vertex colours.
//
// Conventions (see kernels/texture.hpp): UV u right, v up, (0,0) = bottom-left of the image, as in PLY/OBJ and
// assimp's output (assimp already converts glTF's top-left origin, so no aiProcess_FlipUVs). Textures are stored
// with row 0 = top image row.
#include <algorithm>
#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope/mesh.hpp"

namespace diffdope {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void fail(const std::string& model, const std::string& what) {
  throw std::runtime_error("Mesh::load('" + model + "'): " + what);
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  const size_t b = s.find_first_not_of(ws);
  if (b == std::string::npos) return "";
  const size_t e = s.find_last_not_of(ws);
  return s.substr(b, e - b + 1);
}

// What we need from a PLY header that assimp does not tell us: the `comment TextureFile` name (assimp 5.2 does map
// it to the material's diffuse texture; this is a fallback), whether the file has a real `element material` (if
// not, assimp's material is a generated white one that must not override MeshLoadOptions::default_color), and the
// face count (to report "no triangles" instead of assimp's obscure message for vertex-only files).
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
};

PlyHeader read_ply_header(const std::string& path) {
  PlyHeader h;
  std::ifstream in(path, std::ios::binary);
  if (!in) return h;
  std::string line;
  if (!std::getline(in, line) || lower(trim(line)) != "ply") return h;
  h.is_ply = true;
  // Text lines up to end_header (also for binary PLYs); bounded so that a corrupt file cannot make us read forever.
  for (int n = 0; n < 100000 && std::getline(in, line); ++n) {
    line = trim(line);
    std::istringstream ss(line);
    std::string kw;
    ss >> kw;
    if (kw == "end_header") {
      h.valid = true;
      break;
    }
    if (kw == "format") ss >> h.format;
    if (kw == "comment" || kw == "obj_info") {
      std::string tag;
      ss >> tag;
      if (lower(tag) == "texturefile" && h.texture_file.empty()) {
        std::string rest;
        std::getline(ss, rest);
        h.texture_file = trim(rest);
      }
    } else if (kw == "element") {
      std::string name;
      long long count = 0;
      ss >> name >> count;
      if (name == "material") h.has_material_element = true;
      if (name == "face" || name == "tristrips") h.num_faces = std::max(h.num_faces, 0LL) + count;
      if (name == "vertex") h.num_vertices = count;
    }
  }
  if (!h.valid) return h;
  // What follows the header, to catch truncated files before assimp (which can spin on them).
  const std::streampos body = in.tellg();
  in.seekg(0, std::ios::end);
  h.data_bytes = static_cast<long long>(in.tellg() - body);
  if (h.format == "ascii") {
    in.seekg(body);
    while (std::getline(in, line))
      if (!trim(line).empty()) ++h.data_lines;
  }
  return h;
}

// Converts an 8/16-bit or float BGR(A)/grey image to RGB floats in [0, 1], row 0 = top.
bool to_texture(const cv::Mat& in, Texture* tex) {
  if (in.empty() || in.cols <= 0 || in.rows <= 0) return false;
  cv::Mat img = in;
  if (img.channels() == 1) {
    cv::cvtColor(img, img, cv::COLOR_GRAY2BGR);
  } else if (img.channels() == 4) {
    cv::cvtColor(img, img, cv::COLOR_BGRA2BGR);
  } else if (img.channels() != 3) {
    return false;
  }
  double s = 1.0;
  switch (img.depth()) {
    case CV_8U: s = 1.0 / 255.0; break;
    case CV_16U: s = 1.0 / 65535.0; break;
    case CV_32F:
    case CV_64F: s = 1.0; break;
    default: return false;
  }
  cv::Mat f;
  img.convertTo(f, CV_32FC3, s);
  cv::cvtColor(f, f, cv::COLOR_BGR2RGB);
  tex->width = f.cols;
  tex->height = f.rows;
  tex->rgb.resize(static_cast<size_t>(3) * f.cols * f.rows);
  for (int y = 0; y < f.rows; ++y) {
    const float* row = f.ptr<float>(y);
    float* dst = tex->rgb.data() + static_cast<size_t>(3) * f.cols * y;
    for (int i = 0; i < 3 * f.cols; ++i) dst[i] = std::min(1.f, std::max(0.f, row[i]));  // HDR/float: clamp
  }
  return true;
}

constexpr int kImreadFlags = cv::IMREAD_ANYDEPTH | cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION;

// Loads the textures a model references, each distinct one once.
class TextureLoader {
 public:
  TextureLoader(const std::string& model, const aiScene* scene, std::vector<Texture>* out)
      : model_(model), scene_(scene), out_(out) {
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
      Texture tex;
      tex.source = model_ + " (embedded texture " + ref + ")";
      if (!decode_embedded(*embedded.first, &tex)) fail(model_, "cannot decode embedded texture '" + ref + "'");
      return add(key, std::move(tex));
    }
    const fs::path file = resolve(ref);
    if (file.empty()) fail(model_, "texture '" + ref + "' not found (looked relative to " + dir_.string() + ")");
    std::error_code ec;
    fs::path canon = fs::weakly_canonical(file, ec);
    const std::string key = ec ? file.string() : canon.string();
    auto it = index_.find(key);
    if (it != index_.end()) return it->second;
    Texture tex;
    tex.source = file.string();
    cv::Mat img;
    try {
      img = cv::imread(file.string(), kImreadFlags);
    } catch (const cv::Exception&) {
      img.release();
    }
    if (!to_texture(img, &tex)) fail(model_, "cannot read texture '" + ref + "' (" + file.string() + ")");
    return add(key, std::move(tex));
  }

 private:
  int add(const std::string& key, Texture tex) {
    const int idx = static_cast<int>(out_->size());
    out_->push_back(std::move(tex));
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
    for (const auto& c : candidates) {
      if (!c.empty() && is_file(c)) return c;
    }
    return {};
  }

  static bool decode_embedded(const aiTexture& t, Texture* tex) {
    if (t.pcData == nullptr || t.mWidth == 0) return false;
    if (t.mHeight == 0) {  // compressed (PNG, JPEG, ...): mWidth bytes
      cv::Mat buf(1, static_cast<int>(t.mWidth), CV_8UC1,
                  const_cast<void*>(static_cast<const void*>(t.pcData)));
      cv::Mat img;
      try {
        img = cv::imdecode(buf, kImreadFlags);
      } catch (const cv::Exception&) {
        return false;
      }
      return to_texture(img, tex);
    }
    // Uncompressed: aiTexel is b, g, r, a bytes.
    static_assert(sizeof(aiTexel) == 4, "aiTexel layout");
    cv::Mat bgra(static_cast<int>(t.mHeight), static_cast<int>(t.mWidth), CV_8UC4,
                 const_cast<void*>(static_cast<const void*>(t.pcData)));
    return to_texture(bgra, tex);
  }

  std::string model_;
  const aiScene* scene_;
  std::vector<Texture>* out_;
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

Mesh Mesh::load(const std::string& path, const MeshLoadOptions& options) {
  {
    std::error_code ec;
    if (!fs::exists(path, ec)) fail(path, "file does not exist");
    if (!fs::is_regular_file(path, ec)) fail(path, "not a regular file");
    std::ifstream probe(path, std::ios::binary);
    if (!probe) fail(path, "file is not readable");
  }
  const bool is_ply = lower(fs::path(path).extension().string()) == ".ply";
  PlyHeader ply;
  if (is_ply) {
    ply = read_ply_header(path);
    if (!ply.is_ply) fail(path, "not a PLY file (the first line is not 'ply')");
    if (!ply.valid) fail(path, "corrupt PLY header (no 'end_header' line)");
    if (ply.format != "ascii" && ply.format != "binary_little_endian" && ply.format != "binary_big_endian")
      fail(path, "corrupt PLY header (format '" + ply.format + "')");
    const long long faces = std::max(ply.num_faces, 0LL);
    if (ply.num_vertices < 0 || faces < 0) fail(path, "corrupt PLY header (negative element count)");
    if (ply.format == "ascii" ? ply.data_lines < ply.num_vertices + faces
                              : ply.data_bytes < 12 * ply.num_vertices + 4 * faces)
      fail(path, "truncated PLY: the header declares " + std::to_string(ply.num_vertices) + " vertices and " +
                     std::to_string(faces) + " faces, the file is shorter");
  }

  Assimp::Importer importer;
  const unsigned flags = aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_JoinIdenticalVertices |
                         aiProcess_SortByPType;
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

  Mesh mesh;
  mesh.name = path;
  mesh.positions.reserve(total_v);
  mesh.colors.reserve(total_v);
  if (any_uv) mesh.uvs.reserve(total_v);
  mesh.triangles.reserve(3 * total_t);
  mesh.tri_texture.reserve(total_t);

  TextureLoader textures(path, scene, &mesh.textures);
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

    const int base = static_cast<int>(mesh.positions.size());
    for (unsigned v = 0; v < m->mNumVertices; ++v) {
      const aiVector3D& p = m->mVertices[v];
      mesh.positions.push_back({scale * p.x, scale * p.y, scale * p.z});
      if (any_uv) {
        if (has_uv) {
          const aiVector3D& t = m->mTextureCoords[0][v];
          mesh.uvs.push_back({t.x, t.y});
        } else {
          mesh.uvs.push_back({0.f, 0.f});
        }
      }
      if (m->HasVertexColors(0)) {
        const aiColor4D& c = m->mColors[0][v];
        mesh.colors.push_back({std::min(1.f, std::max(0.f, static_cast<float>(c.r))),
                               std::min(1.f, std::max(0.f, static_cast<float>(c.g))),
                               std::min(1.f, std::max(0.f, static_cast<float>(c.b)))});
      } else {
        mesh.colors.push_back(mat_color);
      }
    }
    for (unsigned f = 0; f < m->mNumFaces; ++f) {
      const aiFace& face = m->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points / lines are not rendered
      for (int k = 0; k < 3; ++k) mesh.triangles.push_back(base + static_cast<int>(face.mIndices[k]));
      mesh.tri_texture.push_back(tex_index);
    }
  }

  mesh.finalize();
  return mesh;
}

}  // namespace diffdope
