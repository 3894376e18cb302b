// RefinerOptions from YAML text (the refiner config of the tools and the node).
#include <stdexcept>

#include "diffdope/refiner.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    diffdope::RefinerOptions::from_yaml_string(std::string(reinterpret_cast<const char*>(data), size), "fuzz.yaml")
        .validate();
  } catch (const std::runtime_error&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
