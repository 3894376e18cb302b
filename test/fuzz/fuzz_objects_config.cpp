// The objects config (YAML: objects, meshes, masks, refiner section) as the node reads it.
#include <stdexcept>

#include "diffdope/object_config.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write("objects.yaml", std::string(reinterpret_cast<const char*>(data), size));
  try {
    diffdope::load_objects_config(path, [](const std::string& pkg) { return "/nonexistent/" + pkg; });
  } catch (const std::runtime_error&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
