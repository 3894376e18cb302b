// Mesh::load on arbitrary bytes under one extension (FUZZ_MESH_EXT: .ply, .obj, .glb, .gltf). For OBJ the input
// may carry an MTL file after a kSplit line (written as m.mtl; the OBJ may name it with "mtllib m.mtl").
// PLY and OBJ import in this process (~1,000 inputs/s; a fork of a sanitized process costs ~40 ms), so that a
// crash in our checks or in assimp past them is found. glTF / GLB import in Mesh::load's child process, as in the
// node: assimp's glTF reader trusts accessor counts and asks for gigabytes, which the child's limits turn into
// the error they are in the node; a finding there is a crash, leak or runaway in our own code.
#include <stdexcept>

#include "diffdope/mesh.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string ext = FUZZ_MESH_EXT;
  const std::vector<std::string> p = fuzz::parts(data, size, ext == ".obj" ? 2 : 1);
  if (ext == ".obj") fuzz::write("m.mtl", p[1]);
  const std::string path = fuzz::write("m" + ext, p[0]);
  diffdope::MeshLoadOptions o;
  o.isolate_import = ext == ".glb" || ext == ".gltf";
  o.import_timeout_s = 5;  // (before libFuzzer's own -timeout counts a slow import as a finding)
  o.max_vertices = o.max_triangles = 200000;  // (libFuzzer's memory limit is 2 GB)
  o.max_texture_pixels = 1 << 20;
  try {
    diffdope::Mesh::load(path, o);
  } catch (const std::runtime_error&) {
  }
  return 0;
}
