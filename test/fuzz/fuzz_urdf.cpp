// A robot description (URDF) as the calibration reads it: urdfdom's parse, our checks, forward kinematics at zero
// and the merged mesh. Mesh files cannot exist here: inputs exercise primitives, joints and the error paths.
#include <stdexcept>

#include "diffdope/robot_model.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string xml(reinterpret_cast<const char*>(data), size);
  try {
    diffdope::MeshLoadOptions o;
    o.isolate_import = false;  // (no file to import anyway)
    const diffdope::RobotModel robot = diffdope::RobotModel::parse_urdf(
        xml, fuzz::folder(), "fuzz.urdf", [](const std::string& pkg) -> std::string { return "/nonexistent/" + pkg; }, o);
    std::map<std::string, double> q;
    for (const std::string& j : robot.joint_names()) q[j] = 0.3;
    diffdope::merge_meshes(robot.posed_visuals(q), "fuzz");
  } catch (const std::runtime_error&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
