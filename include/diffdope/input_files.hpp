#pragma once
// The small input files a user hands to the tools: camera intrinsics and an initial pose (JSON / YAML). Every
// problem is an InputFileError naming the file and saying what is wrong, e.g.
//   camera.json: 'cam_K' needs 9 values, found 6
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

#include "diffdope/camera.hpp"
#include "diffdope/pose.hpp"

namespace YAML {
class Node;
}

namespace diffdope {

/// An input that cannot be used; `file` is the file (or folder) to name in the message.
struct InputFileError : std::runtime_error {
  std::string file;
  InputFileError(std::string f, const std::string& what) : std::runtime_error(what), file(std::move(f)) {}
};

/// A command-line value that must be a whole integer in [lo, hi]; std::invalid_argument naming `flag` otherwise
/// ("--frames: expected an integer, got '3x'", "--frames: 0 is outside [1, 100000]").
long long parse_integer_arg(const std::string& flag, const std::string& text, long long lo, long long hi);

/// A command-line value that must be a finite number ("--rate: expected a number, got 'fast'"); ranges are the
/// caller's.
double parse_number_arg(const std::string& flag, const std::string& text);
/// The same in [lo, hi] ("--holes: 2 is outside [0, 1]").
double parse_number_arg(const std::string& flag, const std::string& text, double lo, double hi);

/// The whole file as text; std::runtime_error "<path>: cannot open <what>: ..." when it is missing, not a regular
/// file (a pipe or device could block forever) or unreadable, and when it exceeds input_limits::kMaxTextFileBytes.
std::string read_text_file(const std::string& path, const std::string& what);

/// Throws InputFileError naming `origin` when the YAML document `root` nests deeper than input_limits::kMaxNesting
/// or expands to more than input_limits::kMaxYamlNodes values, aliases counted at each use (a "billion laughs"
/// of a few hundred bytes): call it before walking a user's YAML.
void check_yaml_expansion(const YAML::Node& root, const std::string& origin);

/// Parses JSON `text` read from `path`; InputFileError naming the file when it is invalid or nested deeper than
/// input_limits::kMaxNesting.
nlohmann::json parse_json_checked(const std::string& text, const std::string& path);

/// Throws InputFileError unless `path` is a regular file that can be opened for reading; pipes (FIFOs, a shell's
/// <(...)), devices and sockets are refused before they are opened.
void check_input_file(const std::string& path);

/// Intrinsics from .json or .yaml/.yml: fx, fy, cx, cy[, width, height] (ROS: image_width, image_height), or a
/// 3x3 matrix as BOP's cam_K (9 values, row-major), K / k or camera_matrix ({data: [...]} as ROS's yaml); a BOP
/// scene_camera.json with a single image. The size is the image's; a size in the file must match it.
Camera read_camera_file(const std::string& path, int image_width, int image_height);

/// Model-to-camera pose (metres) from JSON: {"R": [9 row-major], "t": [3]}, {"quaternion": [x, y, z, w],
/// "t": [3]} or {"matrix": [16 row-major] or [[4] x 4]}. The rotation must be orthonormal to 1e-3 (then it is
/// re-orthonormalised) and not a reflection.
Pose read_pose_file(const std::string& path);

}  // namespace diffdope
