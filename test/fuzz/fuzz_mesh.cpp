// Mesh::load on arbitrary bytes under one extension (FUZZ_MESH_EXT: .ply, .obj, .glb, .gltf). For OBJ the input
// may carry an MTL file after a kSplit line (written as m.mtl; the OBJ may name it with "mtllib m.mtl"). The
// import runs in this process, so that a crash in our checks or in assimp past them is found, not absorbed by the
// child-process isolation that Mesh::load uses by default.
#include <stdexcept>

#include "diffdope/mesh.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string ext = FUZZ_MESH_EXT;
  const std::vector<std::string> p = fuzz::parts(data, size, ext == ".obj" ? 2 : 1);
  if (ext == ".obj") fuzz::write("m.mtl", p[1]);
  const std::string path = fuzz::write("m" + ext, p[0]);
  diffdope::MeshLoadOptions o;
  o.isolate_import = false;
  o.max_vertices = o.max_triangles = 200000;  // (libFuzzer's memory limit is 2 GB)
  o.max_texture_pixels = 1 << 20;
  try {
    diffdope::Mesh::load(path, o);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
