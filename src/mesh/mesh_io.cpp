// Mesh::load: any format assimp reads (PLY incl. BOP's `comment TextureFile`, OBJ+MTL, glTF/GLB, ...) into one
// triangle Mesh in metres, with UVs + RGB float textures or per-vertex colours.
//
// Conventions (see kernels/texture.hpp): UV u right, v up, (0,0) = bottom-left of the image, as in PLY/OBJ and
// assimp's output (assimp already converts glTF's top-left origin, so no aiProcess_FlipUVs). Textures are stored
// with row 0 = top image row.
#include <algorithm>
#include <assimp/BaseImporter.h>
#include <assimp/Importer.hpp>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <cctype>
#include <climits>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "diffdope/mesh.hpp"
#include "mesh/isolated_call.hpp"

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

/// Size and signedness of a PLY scalar type; size 0 for an unknown one.
void ply_type(const std::string& t, int* size, bool* is_float, bool* is_signed) {
  *is_float = t == "float" || t == "float32" || t == "double" || t == "float64";
  *is_signed = *is_float || t == "char" || t == "int8" || t == "short" || t == "int16" || t == "int" || t == "int32";
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") *size = 1;
  else if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") *size = 2;
  else if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32") *size = 4;
  else if (t == "double" || t == "float64") *size = 8;
  else *size = 0;
}

bool is_vertex_index_list(const PlyElement& e, const PlyProperty& p) {
  return (e.name == "face" || e.name == "tristrips") && p.is_list &&
         (p.name == "vertex_indices" || p.name == "vertex_index");
}

/// Walks a binary body record by record (PlyHeader::body_error says what is wrong, if anything).
void check_binary_ply_body(std::istream& in, PlyHeader& h) {
  const bool swap = h.format == "binary_big_endian";
  auto read_int = [&](const unsigned char* p, int size, bool is_signed) -> long long {
    unsigned char b[8];
    for (int i = 0; i < size; ++i) b[i] = p[swap ? size - 1 - i : i];
    switch (size) {
      case 1: return is_signed ? (long long)(int8_t)b[0] : (long long)b[0];
      case 2: { uint16_t v; std::memcpy(&v, b, 2); return is_signed ? (long long)(int16_t)v : (long long)v; }
      case 4: { uint32_t v; std::memcpy(&v, b, 4); return is_signed ? (long long)(int32_t)v : (long long)v; }
      default: return -1;  // (a float count or index: refused below)
    }
  };
  std::vector<char> buf(1 << 16);
  std::streamsize have = 0, at = 0;
  auto take = [&](size_t n, unsigned char* out) {  // buffered reads: millions of small records
    while (n > 0) {
      if (at == have) {
        in.read(buf.data(), std::streamsize(buf.size()));
        have = in.gcount(), at = 0;
        if (have == 0) return false;
      }
      const size_t k = std::min<size_t>(n, size_t(have - at));
      if (out) std::memcpy(out, buf.data() + at, k), out += k;
      at += std::streamsize(k), n -= k;
    }
    return true;
  };
  unsigned char scratch[8];
  for (const PlyElement& e : h.elements) {
    if (e.properties.empty()) continue;  // nothing to read, however many it claims (fuzz_mesh_ply's find: a hang)
    for (long long r = 0; r < e.count; ++r) {
      for (const PlyProperty& p : e.properties) {
        if (!p.is_list) {
          if (!take(size_t(p.size), nullptr)) goto truncated;
          continue;
        }
        if (!take(size_t(p.count_size), scratch)) goto truncated;
        const long long n = read_int(scratch, p.count_size, p.count_signed);
        if (n < 0) {
          h.body_error = "corrupt PLY: " + e.name + " " + std::to_string(r) + " has a list of " + std::to_string(n) + " items";
          return;
        }
        for (long long k = 0; k < n; ++k) {
          if (!take(size_t(p.size), scratch)) goto truncated;
          if (is_vertex_index_list(e, p)) {
            const long long idx = p.is_float ? -1 : read_int(scratch, p.size, p.is_signed);
            if (idx < 0 || idx >= h.num_vertices) {
              h.body_error = "corrupt PLY: " + e.name + " " + std::to_string(r) + " refers to vertex " +
                             std::to_string(idx) + "; the file has " + std::to_string(h.num_vertices) + " vertices";
              return;
            }
          }
        }
        if (is_vertex_index_list(e, p) && e.name == "face" && n < 3) {
          h.body_error = "corrupt PLY: face " + std::to_string(r) + " has " + std::to_string(n) + " vertices";
          return;
        }
      }
    }
  }
  return;
truncated:
  h.body_error = "truncated PLY: the body ends before the " + std::to_string(h.num_vertices) + " vertices and " +
                 std::to_string(std::max(h.num_faces, 0LL)) + " faces its header declares";
}

/// Walks an ASCII body: one record per non-empty line, each with exactly the values its element declares.
void check_ascii_ply_body(std::istream& in, PlyHeader& h) {
  std::string line;
  long long line_no = 0;
  for (const PlyElement& e : h.elements) {
    for (long long r = 0; r < e.count; ++r) {
      do {
        if (!std::getline(in, line)) {
          h.body_error = "truncated PLY: the body ends at " + e.name + " " + std::to_string(r) + " of " +
                         std::to_string(e.count);
          return;
        }
        ++line_no;
      } while (trim(line).empty());
      const char* c = line.c_str();
      const auto number = [&](double* v) {
        char* end = nullptr;
        *v = std::strtod(c, &end);
        if (end == c) return false;
        c = end;
        return true;
      };
      const auto where = [&] { return "PLY body line " + std::to_string(line_no) + " (" + e.name + " " + std::to_string(r) + ")"; };
      for (const PlyProperty& p : e.properties) {
        double v = 0;
        if (!number(&v)) {
          h.body_error = "corrupt " + where() + ": expected a number for '" + p.name + "'";
          return;
        }
        if (!p.is_list) continue;
        if (!(v >= 0 && v <= 1e6) || v != std::floor(v)) {
          h.body_error = "corrupt " + where() + ": list count " + std::to_string(v);
          return;
        }
        const long long n = (long long)v;
        if (is_vertex_index_list(e, p) && e.name == "face" && n < 3) {
          h.body_error = "corrupt " + where() + ": a face of " + std::to_string(n) + " vertices";
          return;
        }
        for (long long k = 0; k < n; ++k) {
          if (!number(&v)) {
            h.body_error = "corrupt " + where() + ": the list has fewer than " + std::to_string(n) + " values";
            return;
          }
          if (is_vertex_index_list(e, p) && (!(v >= 0 && v < double(h.num_vertices)) || v != std::floor(v))) {
            // (casting a huge value to an integer would be undefined: fuzz_mesh_ply's find)
            const std::string shown =
                std::fabs(v) < 1e15 && v == std::floor(v) ? std::to_string((long long)v) : std::to_string(v);
            h.body_error = "corrupt " + where() + ": refers to vertex " + shown +
                           "; the file has " + std::to_string(h.num_vertices) + " vertices";
            return;
          }
        }
      }
      if (!trim(c).empty()) {
        h.body_error = "corrupt " + where() + ": more values than the header declares ('" + trim(c).substr(0, 40) + "')";
        return;
      }
    }
  }
}

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
      PlyElement e;
      ss >> e.name >> e.count;
      // (a count beyond any file's size would also overflow the sums below: fuzz_mesh_ply's find)
      if (!ss || e.count < 0 || e.count > (1LL << 40)) {
        h.body_error = "corrupt PLY header: '" + line.substr(0, 60) + "'";
        e.count = 0;
      }
      if (e.name == "material") h.has_material_element = true;
      if (e.name == "face" || e.name == "tristrips") h.num_faces = std::max(h.num_faces, 0LL) + e.count;
      if (e.name == "vertex") h.num_vertices = e.count;
      h.elements.push_back(e);
    } else if (kw != "format" && kw != "property" && !kw.empty()) {
      h.body_error = "corrupt PLY header: unknown line '" + line.substr(0, 60) + "'";
    } else if (kw == "property") {
      PlyProperty p;
      std::string type;
      ss >> type;
      if (type == "list") {
        std::string count_type;
        ss >> count_type >> type;
        bool count_float = false;
        ply_type(count_type, &p.count_size, &count_float, &p.count_signed);
        if (count_float) p.count_size = 0;
        p.is_list = true;
      }
      ss >> p.name;
      ply_type(type, &p.size, &p.is_float, &p.is_signed);
      if (h.elements.empty() || !ss || p.size == 0 || (p.is_list && p.count_size == 0))
        h.body_error = "corrupt PLY header: '" + line + "'";
      else
        h.elements.back().properties.push_back(p);
    }
  }
  if (!h.valid) return h;
  // What follows the header, to catch truncated files before assimp (which can spin on them).
  const std::streampos body = in.tellg();
  in.seekg(0, std::ios::end);
  h.data_bytes = static_cast<long long>(in.tellg() - body);
  in.seekg(body);
  if (h.format == "ascii") {
    while (std::getline(in, line))
      if (!trim(line).empty()) ++h.data_lines;
    in.clear();
    in.seekg(body);
    if (h.body_error.empty()) check_ascii_ply_body(in, h);
  } else if (h.body_error.empty() && (h.format == "binary_little_endian" || h.format == "binary_big_endian")) {
    check_binary_ply_body(in, h);
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

// Collects the textures a model references, each distinct one once.
class TextureSources {
 public:
  TextureSources(const std::string& model, const aiScene* scene, std::vector<TextureSource>* out)
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
    for (const auto& c : candidates) {
      if (!c.empty() && is_file(c)) return c;
    }
    return {};
  }

  std::string model_;
  const aiScene* scene_;
  std::vector<TextureSource>* out_;
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

  TextureSources textures(path, scene, &out.textures);
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

// ---- ImportedModel as bytes (child -> parent) ----

class ByteWriter {
 public:
  template <typename T>
  void pod(const T& v) {
    static_assert(std::is_trivially_copyable<T>::value, "plain data");
    out_.append(reinterpret_cast<const char*>(&v), sizeof v);
  }
  template <typename T>
  void vec(const std::vector<T>& v) {
    pod(uint64_t(v.size()));
    if (!v.empty()) out_.append(reinterpret_cast<const char*>(v.data()), sizeof(T) * v.size());
  }
  void str(const std::string& v) {
    pod(uint64_t(v.size()));
    out_ += v;
  }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

/// Reads what ByteWriter wrote; every count is checked against the bytes left (a child that died while writing
/// leaves a short message, never an over-read).
class ByteReader {
 public:
  explicit ByteReader(const std::string& in) : in_(in) {}
  template <typename T>
  T pod() {
    T v;
    need(sizeof v);
    std::memcpy(&v, in_.data() + pos_, sizeof v);
    pos_ += sizeof v;
    return v;
  }
  template <typename T>
  std::vector<T> vec() {
    const uint64_t n = pod<uint64_t>();
    if (n > (in_.size() - pos_) / sizeof(T)) throw std::runtime_error("truncated answer from the import process");
    std::vector<T> v(n);
    if (n) std::memcpy(static_cast<void*>(v.data()), in_.data() + pos_, sizeof(T) * n);
    pos_ += sizeof(T) * n;
    return v;
  }
  std::string str() {
    const uint64_t n = pod<uint64_t>();
    need(n);
    std::string v = in_.substr(pos_, n);
    pos_ += n;
    return v;
  }
  bool done() const { return pos_ == in_.size(); }

 private:
  void need(uint64_t n) const {
    if (n > in_.size() - pos_) throw std::runtime_error("truncated answer from the import process");
  }
  const std::string& in_;
  size_t pos_ = 0;
};

std::string to_bytes(const ImportedModel& m) {
  ByteWriter w;
  w.vec(m.positions), w.vec(m.colors), w.vec(m.uvs), w.vec(m.triangles), w.vec(m.tri_texture);
  w.pod(uint64_t(m.textures.size()));
  for (const TextureSource& t : m.textures) {
    w.str(t.ref), w.str(t.file), w.str(t.embedded);
    w.pod(int32_t(t.raw_width)), w.pod(int32_t(t.raw_height));
  }
  return w.take();
}

ImportedModel from_bytes(const std::string& bytes) {
  ByteReader r(bytes);
  ImportedModel m;
  m.positions = r.vec<Vec3f>(), m.colors = r.vec<Vec3f>(), m.uvs = r.vec<Vec2f>();
  m.triangles = r.vec<int>(), m.tri_texture = r.vec<int>();
  const uint64_t n = r.pod<uint64_t>();
  if (n > bytes.size()) throw std::runtime_error("corrupt answer from the import process");
  for (uint64_t i = 0; i < n; ++i) {
    TextureSource t;
    t.ref = r.str(), t.file = r.str(), t.embedded = r.str();
    t.raw_width = r.pod<int32_t>(), t.raw_height = r.pod<int32_t>();
    m.textures.push_back(std::move(t));
  }
  if (!r.done()) throw std::runtime_error("corrupt answer from the import process");
  return m;
}

// ---- textures: decoded here, in the caller's process, with their size checked first ----

uint32_t be32(const unsigned char* p) { return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3]; }

/// Width and height from a PNG, JPEG or BMP header, without decoding; false for other formats.
bool image_header_size(const std::string& bytes, long long* w, long long* h) {
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t n = bytes.size();
  if (n >= 24 && std::memcmp(b, "\x89PNG\r\n\x1a\n", 8) == 0 && std::memcmp(b + 12, "IHDR", 4) == 0) {
    *w = be32(b + 16), *h = be32(b + 20);
    return true;
  }
  if (n >= 26 && b[0] == 'B' && b[1] == 'M') {
    int32_t bw, bh;
    std::memcpy(&bw, b + 18, 4), std::memcpy(&bh, b + 22, 4);
    *w = std::llabs(bw), *h = std::llabs(bh);
    return true;
  }
  if (n >= 4 && b[0] == 0xFF && b[1] == 0xD8) {  // JPEG: walk the segments to a start-of-frame
    size_t i = 2;
    while (i + 4 <= n) {
      if (b[i] != 0xFF) return false;
      const unsigned char marker = b[i + 1];
      if (marker == 0xFF) {  // fill byte
        ++i;
        continue;
      }
      if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // no length
        i += 2;
        continue;
      }
      const size_t len = size_t(b[i + 2]) << 8 | b[i + 3];
      if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
        if (i + 9 > n) return false;
        *h = (static_cast<long long>(b[i + 5]) << 8) | b[i + 6];
        *w = (static_cast<long long>(b[i + 7]) << 8) | b[i + 8];
        return true;
      }
      if (len < 2) return false;
      i += 2 + len;
    }
  }
  return false;
}

Texture decode_texture(const std::string& model, const TextureSource& src, const MeshLoadOptions& options) {
  const std::string name = src.file.empty() ? "embedded texture '" + src.ref + "'" : "texture '" + src.ref + "'";
  Texture tex;
  tex.source = src.file.empty() ? model + " (embedded texture " + src.ref + ")" : src.file;
  std::string bytes;
  long long w = src.raw_width, h = src.raw_height;
  if (src.raw_width <= 0) {
    if (!src.file.empty()) {
      std::error_code ec;
      const auto size = fs::file_size(src.file, ec);
      if (ec) fail(model, "cannot read " + name + " (" + src.file + ")");
      if (size > (uint64_t(1) << 30)) fail(model, name + " is a file of more than 1 GB");
      std::ifstream in(src.file, std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
      if (!in.good() && !in.eof()) fail(model, "cannot read " + name + " (" + src.file + ")");
    }
    const std::string& data = src.file.empty() ? src.embedded : bytes;
    if (!image_header_size(data, &w, &h)) w = h = 0;  // (other formats: checked after decoding)
  }
  const auto too_big = [&](long long pw, long long ph) {
    return pw * ph > options.max_texture_pixels;
  };
  if (too_big(w, h))
    fail(model, name + " is " + std::to_string(w) + " x " + std::to_string(h) + " pixels: more than the limit of " +
                    std::to_string(options.max_texture_pixels) + " (MeshLoadOptions::max_texture_pixels); downsample it");
  cv::Mat img;
  try {
    if (src.raw_width > 0) {
      img = cv::Mat(src.raw_height, src.raw_width, CV_8UC4, const_cast<char*>(src.embedded.data())).clone();
    } else {
      const std::string& data = src.file.empty() ? src.embedded : bytes;
      const cv::Mat buf(1, int(std::min<size_t>(data.size(), INT_MAX)), CV_8UC1, const_cast<char*>(data.data()));
      if (!data.empty()) img = cv::imdecode(buf, kImreadFlags);
    }
  } catch (const cv::Exception&) {
    img.release();
  }
  if (img.empty()) fail(model, "cannot " + std::string(src.file.empty() ? "decode " : "read ") + name +
                                   (src.file.empty() ? "" : " (" + src.file + ")"));
  if (too_big(img.cols, img.rows))
    fail(model, name + " is " + std::to_string(img.cols) + " x " + std::to_string(img.rows) +
                    " pixels: more than the limit (MeshLoadOptions::max_texture_pixels); downsample it");
  // The renderer samples mip levels; a texture beyond max_texture_size is only memory.
  const int longest = std::max(img.cols, img.rows);
  if (options.max_texture_size > 0 && longest > options.max_texture_size) {
    const double f = double(options.max_texture_size) / longest;
    cv::resize(img, img, cv::Size(std::max(1, int(std::lround(img.cols * f))), std::max(1, int(std::lround(img.rows * f)))),
               0, 0, cv::INTER_AREA);
  }
  if (!to_texture(img, &tex)) fail(model, "cannot read " + name + ": unsupported pixel format");
  return tex;
}

// ---- checks of our own before assimp sees the file ----

/// GLB: the chunk lengths must fit in the file (assimp allocates what the header says before reading).
void check_glb(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  unsigned char h[20];
  if (!in.read(reinterpret_cast<char*>(h), sizeof h)) fail(path, "truncated GLB (shorter than its 20-byte header)");
  const auto le32 = [](const unsigned char* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
  };
  if (std::memcmp(h, "glTF", 4) != 0) fail(path, "not a GLB file (no 'glTF' magic)");
  std::error_code ec;
  const uint64_t size = fs::file_size(path, ec);
  if (le32(h + 4) != 2) fail(path, "GLB version " + std::to_string(le32(h + 4)) + " (only glTF 2.0 is read)");
  if (le32(h + 8) > size) fail(path, "corrupt GLB: the header declares " + std::to_string(le32(h + 8)) +
                                         " bytes, the file has " + std::to_string(size));
  // Every chunk: length + type, then the data, inside the declared length.
  uint64_t pos = 12;
  const uint64_t end = std::min<uint64_t>(le32(h + 8), size);
  while (pos + 8 <= end) {
    unsigned char c[8];
    in.seekg(std::streamoff(pos));
    if (!in.read(reinterpret_cast<char*>(c), 8)) break;
    const uint64_t len = le32(c);
    if (pos + 8 + len > end)
      fail(path, "corrupt GLB: a chunk of " + std::to_string(len) + " bytes at offset " + std::to_string(pos) +
                     " runs past the end of the file");
    pos += 8 + len;
  }
}

/// OBJ: a material library it names must exist (else assimp loads the mesh grey without a word).
void check_obj_materials(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  const fs::path dir = fs::path(path).parent_path();
  for (int n = 0; n < 10000000 && std::getline(in, line); ++n) {
    const std::string t = trim(line);
    if (t.rfind("mtllib", 0) != 0 || t.size() < 7 || !std::isspace(static_cast<unsigned char>(t[6]))) continue;
    const std::string lib = trim(t.substr(6));
    std::error_code ec;
    if (!lib.empty() && !fs::is_regular_file(dir / lib, ec) && !fs::is_regular_file(dir / fs::path(lib).filename(), ec))
      fail(path, "material library '" + lib + "' not found next to the OBJ (its colours and textures would be lost)");
  }
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
  const std::string ext = lower(fs::path(path).extension().string());
  const bool is_ply = ext == ".ply";
  PlyHeader ply;
  if (is_ply) {
    ply = read_ply_header(path);
    if (!ply.is_ply) fail(path, "not a PLY file (the first line is not 'ply')");
    if (!ply.valid) fail(path, "corrupt PLY header (no 'end_header' line)");
    if (ply.format != "ascii" && ply.format != "binary_little_endian" && ply.format != "binary_big_endian")
      fail(path, "corrupt PLY header (format '" + ply.format + "')");
    const long long faces = std::max(ply.num_faces, 0LL);
    if (ply.num_vertices < 0 || faces < 0) fail(path, "corrupt PLY header (negative element count)");
    if (ply.num_vertices > options.max_vertices || faces > options.max_triangles)
      fail(path, "the PLY declares " + std::to_string(ply.num_vertices) + " vertices and " + std::to_string(faces) +
                     " faces: more than the limit (MeshLoadOptions: " + std::to_string(options.max_vertices) +
                     " vertices, " + std::to_string(options.max_triangles) + " triangles)");
    if (ply.format == "ascii" ? ply.data_lines < ply.num_vertices + faces
                              : ply.data_bytes < 12 * ply.num_vertices + 4 * faces)
      fail(path, "truncated PLY: the header declares " + std::to_string(ply.num_vertices) + " vertices and " +
                     std::to_string(faces) + " faces, the file is shorter");
    if (!ply.body_error.empty()) fail(path, ply.body_error);
  }
  if (ext == ".glb") check_glb(path);
  if (ext == ".obj") check_obj_materials(path);

  ImportedModel model;
  if (options.isolate_import) {
    IsolationLimits limits;
    limits.timeout_s = options.import_timeout_s;
    limits.address_space_bytes = options.import_memory_bytes;
    const std::string bytes =
        run_isolated([&] { return to_bytes(import_with_assimp(path, options, ply, is_ply)); }, limits,
                     "Mesh::load('" + path + "'): importing");
    try {
      model = from_bytes(bytes);
    } catch (const std::exception& e) {
      fail(path, e.what());
    }
  } else {
    model = import_with_assimp(path, options, ply, is_ply);
  }

  Mesh mesh;
  mesh.name = path;
  mesh.positions = std::move(model.positions);
  mesh.colors = std::move(model.colors);
  mesh.uvs = std::move(model.uvs);
  mesh.triangles = std::move(model.triangles);
  mesh.tri_texture = std::move(model.tri_texture);
  for (const TextureSource& src : model.textures) mesh.textures.push_back(decode_texture(path, src, options));
  mesh.finalize();
  return mesh;
}

}  // namespace diffdope
