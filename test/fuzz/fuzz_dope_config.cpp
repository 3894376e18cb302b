// DOPE's config_pose.yaml as the node reads it (its maps of weights, meshes, scales, ids, dimensions and model
// transforms), and each object's mesh against its cuboid.
#include <stdexcept>

#include "diffdope/object_config.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write("config_pose.yaml", std::string(reinterpret_cast<const char*>(data), size));
  try {
    const diffdope::ObjectsConfig cfg =
        diffdope::load_objects_config(path, [](const std::string& pkg) { return "/nonexistent/" + pkg; });
    for (const diffdope::ObjectConfig& o : cfg.objects)  // a centimetre mesh read as metres, and a fitting one
      for (const double scale : {1.0, 0.01}) (void)diffdope::cuboid_mismatch(o.cuboid_extent / scale, o);
  } catch (const std::runtime_error&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
