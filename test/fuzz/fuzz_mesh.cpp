// Mesh::load on arbitrary bytes under one extension (FUZZ_MESH_EXT: .ply, .obj, .glb, .gltf), as the node calls
// it. For OBJ the input may carry an MTL file after a kSplit line (written as m.mtl; the OBJ may name it with
// "mtllib m.mtl"). Our checks, the texture decoding and finalize() run in this process; assimp runs in the import
// child (Mesh::load's isolation): its own crashes (heap corruption in its PLY reader, found here) and huge
// allocations (its glTF reader trusts accessor counts) are the error they are in the node. A finding here is a
// crash, leak, hang or runaway in our code. (Inputs our checks refuse never fork: those run fast.)
#include <stdexcept>

#include "diffdope/mesh.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string ext = FUZZ_MESH_EXT;
  const std::vector<std::string> p = fuzz::parts(data, size, ext == ".obj" ? 2 : 1);
  if (ext == ".obj") fuzz::write("m.mtl", p[1]);
  const std::string path = fuzz::write("m" + ext, p[0]);
  diffdope::MeshLoadOptions o;
  o.import_timeout_s = 5;  // (before libFuzzer's own -timeout counts a slow import as a finding)
  o.max_vertices = o.max_triangles = 200000;  // (libFuzzer's memory limit is 2 GB)
  o.max_texture_pixels = 1 << 20;
  try {
    diffdope::Mesh::load(path, o);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
