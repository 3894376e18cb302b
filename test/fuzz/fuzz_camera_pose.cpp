// Camera (JSON and YAML) and initial-pose files of diffdope_refine: part 1 as camera.json, part 2 as camera.yaml,
// part 3 as init.json.
#include "diffdope/input_files.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::vector<std::string> p = fuzz::parts(data, size, 3);
  for (const char* name : {"camera.json", "camera.yaml"}) {
    try {
      diffdope::read_camera_file(fuzz::write(name, name[7] == 'j' ? p[0] : p[1]), 640, 480);
    } catch (const std::runtime_error&) {
    }
  }
  try {
    diffdope::read_pose_file(fuzz::write("init.json", p[2]));
  } catch (const std::runtime_error&) {
  }
  return 0;
}
