// Checks of our own before assimp sees a model file: the PLY header and body walked against each other and the
// limits, GLB chunk lengths, OBJ material libraries.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "mesh/mesh_io_internal.hpp"

#include <nlohmann/json.hpp>

#include "diffdope/input_files.hpp"

namespace diffdope {
namespace mesh_io {

namespace fs = std::filesystem;

namespace {

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
        if (is_vertex_index_list(e, p) && n > kMaxPolygonVertices) {
          h.body_error = "PLY " + e.name + " " + std::to_string(r) + " is a polygon of " + std::to_string(n) +
                         " vertices: at most " + std::to_string(kMaxPolygonVertices) + " (triangulate it first)";
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
        if (is_vertex_index_list(e, p) && n > kMaxPolygonVertices) {
          h.body_error = where() + " is a polygon of " + std::to_string(n) + " vertices: at most " +
                         std::to_string(kMaxPolygonVertices) + " (triangulate it first)";
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

/// The header of a PLY file, its body walked (see PlyHeader); is_ply false when the file does not start with "ply".
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

}  // namespace

PlyHeader check_ply(const std::string& path, const MeshLoadOptions& options) {
  PlyHeader ply = read_ply_header(path);
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
  return ply;
}

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

bool in_resource_dirs(const std::string& model, const std::string& file, const MeshLoadOptions& options) {
  std::error_code ec;
  const fs::path target = fs::weakly_canonical(file, ec);
  if (ec) return false;
  const auto below = [&](const fs::path& dir) {
    std::error_code e;
    const fs::path root = fs::weakly_canonical(dir.empty() ? fs::path(".") : dir, e);
    if (e) return false;
    const auto mismatch = std::mismatch(root.begin(), root.end(), target.begin(), target.end());
    return mismatch.first == root.end();
  };
  if (below(fs::path(model).parent_path())) return true;
  for (const std::string& d : options.resource_dirs)
    if (below(d)) return true;
  return false;
}

std::string outside_message(const std::string& model, const std::string& what, const std::string& ref,
                            const std::string& file) {
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(file, ec);
  std::string dir = fs::path(model).parent_path().string();
  if (dir.empty()) dir = ".";
  return what + " '" + ref + "' is " + (ec ? file : resolved.string()) + ", outside the model's folder (" + dir +
         "): refused, a model may only read files in its folder or below (MeshLoadOptions::resource_dirs adds "
         "folders)";
}

void check_obj(const std::string& path, const MeshLoadOptions& options) {
  std::ifstream in(path);
  std::string line;
  const fs::path dir = fs::path(path).parent_path();
  long long vertices = 0, triangles = 0;
  while (std::getline(in, line)) {
    // Counted before assimp reads the file: it would allocate for all of them first (a bad_alloc, not the limit).
    if (line.size() > 2 && line[0] == 'v' && (line[1] == ' ' || line[1] == '\t')) {
      ++vertices;
      continue;
    }
    if (line.size() > 2 && line[0] == 'f' && (line[1] == ' ' || line[1] == '\t')) {
      std::istringstream corners(line.substr(2));
      long long n = 0;
      for (std::string c; corners >> c;) ++n;
      if (n > kMaxPolygonVertices)
        fail(path, "a face of " + std::to_string(n) + " vertices: at most " + std::to_string(kMaxPolygonVertices) +
                       " (triangulate it first)");
      triangles += std::max(n - 2, 0LL);
      continue;
    }
    const std::string t = trim(line);
    if (t.rfind("mtllib", 0) != 0 || t.size() < 7 || !std::isspace(static_cast<unsigned char>(t[6]))) continue;
    const std::string lib = trim(t.substr(6));
    if (lib.empty()) continue;
    // (assimp opens the library relative to the OBJ's folder, whatever the path says)
    if (fs::path(lib).is_absolute())
      fail(path, "material library '" + lib + "' is an absolute path: it must be named relative to the OBJ's folder");
    std::error_code ec;
    const fs::path file = dir / lib;
    if (!fs::exists(file, ec))
      fail(path, "material library '" + lib + "' not found next to the OBJ (its colours and textures would be lost)");
    if (!in_resource_dirs(path, file.string(), options)) fail(path, outside_message(path, "material library", lib, file.string()));
    if (!fs::is_regular_file(file, ec)) fail(path, "material library '" + lib + "' is not a regular file");
  }
  if (vertices > options.max_vertices || triangles > options.max_triangles)
    fail(path, std::to_string(vertices) + " vertices and " + std::to_string(triangles) +
                   " triangles: more than the limit (MeshLoadOptions: " + std::to_string(options.max_vertices) +
                   " vertices, " + std::to_string(options.max_triangles) + " triangles); simplify the mesh");
}

void check_gltf_uris(const std::string& path, const MeshLoadOptions& options) {
  std::string text;
  try {
    text = read_text_file(path, "the glTF file");
  } catch (const std::exception& e) {
    fail(path, e.what());
  }
  nlohmann::json j;
  try {
    j = parse_json_checked(text, path);
  } catch (const std::exception& e) {
    fail(path, e.what());
  }
  if (!j.is_object()) return;  // (assimp says what is wrong)
  const fs::path dir = fs::path(path).parent_path();
  for (const char* kind : {"buffers", "images"}) {
    const auto list = j.find(kind);
    if (list == j.end() || !list->is_array()) continue;
    for (const auto& entry : *list) {
      if (!entry.is_object() || !entry.contains("uri") || !entry["uri"].is_string()) continue;
      const std::string uri = entry["uri"].get<std::string>();
      if (uri.rfind("data:", 0) == 0) continue;
      const std::string what = std::string(kind) == "buffers" ? "buffer" : "image";
      if (uri.find("://") != std::string::npos || fs::path(uri).is_absolute())
        fail(path, what + " '" + uri + "' is not a path relative to the glTF file");
      const fs::path file = dir / uri;
      std::error_code ec;
      if (!fs::exists(file, ec)) {
        if (what == "buffer") fail(path, "buffer '" + uri + "' not found next to the glTF file");
        continue;  // (a missing image: the texture reader says so)
      }
      if (!in_resource_dirs(path, file.string(), options)) fail(path, outside_message(path, what, uri, file.string()));
      if (!fs::is_regular_file(file, ec)) fail(path, what + " '" + uri + "' is not a regular file");
    }
  }
}

}  // namespace mesh_io
}  // namespace diffdope
