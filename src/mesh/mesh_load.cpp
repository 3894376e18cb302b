// Mesh::load: any format assimp reads (PLY incl. BOP's `comment TextureFile`, OBJ+MTL, glTF/GLB, ...) into one
// triangle Mesh in metres, with UVs + RGB float textures or per-vertex colours. The file is checked here, imported
// in a child process (its model sent back as bytes), and its textures decoded here.
//
// Conventions (see kernels/texture.hpp): UV u right, v up, (0,0) = bottom-left of the image, as in PLY/OBJ and
// assimp's output (assimp already converts glTF's top-left origin, so no aiProcess_FlipUVs). Textures are stored
// with row 0 = top image row.
#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "diffdope/mesh.hpp"
#include "mesh/isolated_call.hpp"
#include "mesh/mesh_io_internal.hpp"

#include "diffdope/input_files.hpp"

namespace diffdope {
namespace mesh_io {

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

namespace {

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

}  // namespace
}  // namespace mesh_io

Mesh Mesh::load(const std::string& path, const MeshLoadOptions& options) {
  using namespace mesh_io;
  namespace fs = std::filesystem;
  try {
    check_input_file(path);  // (a pipe or device is refused before it is opened)
  } catch (const InputFileError& e) {
    fail(path, e.what());
  }
  const std::string ext = lower(fs::path(path).extension().string());
  const bool is_ply = ext == ".ply";
  PlyHeader ply;
  if (is_ply) ply = check_ply(path, options);
  if (ext == ".glb") check_glb(path);
  if (ext == ".obj") check_obj(path, options);
  if (ext == ".gltf") check_gltf_uris(path, options);

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
  long long texture_pixels = 0;  // (decoded one at a time: at most one beyond the budget is ever held)
  for (const TextureSource& src : model.textures) {
    mesh.textures.push_back(decode_texture(path, src, options));
    texture_pixels += static_cast<long long>(mesh.textures.back().width) * mesh.textures.back().height;
    if (texture_pixels > options.max_total_texture_pixels)
      fail(path, "its " + std::to_string(model.textures.size()) + " textures hold more than " +
                     std::to_string(options.max_total_texture_pixels) +
                     " pixels together (MeshLoadOptions::max_total_texture_pixels): downsample them or use fewer");
  }
  mesh.finalize();
  return mesh;
}

}  // namespace diffdope
