// Camera and initial-pose files (include/diffdope/input_files.hpp).
#include "diffdope/input_files.hpp"

#include "diffdope/input_limits.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

namespace diffdope {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

using input_limits::kMaxNesting;

[[noreturn]] void fail(const std::string& file, const std::string& what) { throw InputFileError(file, what); }

void check_file(const std::string& path) {
  check_input_file(path);
  std::error_code ec;
  if (fs::file_size(path, ec) > input_limits::kMaxTextFileBytes) fail(path, "more than 64 MB: not a camera or pose file");
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

/// A value for a message: bytes that are not UTF-8 (a YAML file may hold any) replaced, long ones cut.
std::string shown(const json& v) {
  std::string s = v.dump(-1, ' ', false, json::error_handler_t::replace);
  if (s.size() > 80) s = s.substr(0, 77) + "...";
  return s;
}

std::string size_str(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

}  // namespace

nlohmann::json parse_json_checked(const std::string& text, const std::string& path) {
  // The depth is checked while parsing: a deeper document is refused before it is built (and before a message
  // would print it recursively).
  const json::parser_callback_t limit_depth = [&](int depth, json::parse_event_t, json&) {
    if (depth > kMaxNesting) fail(path, "nested deeper than " + std::to_string(kMaxNesting) + " levels");
    return true;
  };
  try {
    return json::parse(text, limit_depth);
  } catch (const json::exception& e) {
    std::string m = e.what();
    const size_t b = m.find("] ");
    if (m.rfind("[json.exception", 0) == 0 && b != std::string::npos) m = m.substr(b + 2);
    fail(path, "invalid JSON: " + m);
  }
}

namespace {

json read_json_file(const std::string& path) {
  check_file(path);
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return parse_json_checked(text.str(), path);
}

void count_yaml_nodes(const YAML::Node& n, const std::string& origin, long long& nodes, int depth) {
  if (depth > kMaxNesting) fail(origin, "nested deeper than " + std::to_string(kMaxNesting) + " levels");
  if (--nodes < 0)
    fail(origin, "expands to more than " + std::to_string(input_limits::kMaxYamlNodes) +
                     " values (aliases counted each time they are used)");
  if (n.IsMap()) {
    for (const auto& kv : n) {
      count_yaml_nodes(kv.first, origin, nodes, depth + 1);
      count_yaml_nodes(kv.second, origin, nodes, depth + 1);
    }
  } else if (n.IsSequence()) {
    for (const auto& e : n) count_yaml_nodes(e, origin, nodes, depth + 1);
  }
}

/// (Call check_yaml_expansion() first: it bounds the depth and the size of what this builds.)
json yaml_to_json(const YAML::Node& n, const std::string& path) {
  switch (n.Type()) {
    case YAML::NodeType::Map: {
      json j = json::object();
      for (const auto& kv : n) j[kv.first.as<std::string>()] = yaml_to_json(kv.second, path);
      return j;
    }
    case YAML::NodeType::Sequence: {
      json j = json::array();
      for (const auto& e : n) j.push_back(yaml_to_json(e, path));
      return j;
    }
    case YAML::NodeType::Scalar: {
      try {
        return n.as<double>();
      } catch (const YAML::Exception&) {
        return n.as<std::string>();
      }
    }
    default:
      return nullptr;
  }
}

json read_yaml_file(const std::string& path) {
  check_file(path);
  try {
    const YAML::Node root = YAML::LoadFile(path);
    check_yaml_expansion(root, path);
    return yaml_to_json(root, path);
  } catch (const YAML::Exception& e) {
    fail(path, std::string("invalid YAML: ") + e.what());
  }
}

/// Numbers of `key`: a flat array, an array of arrays (rows), or an object with a `data` array (ROS yaml).
std::vector<double> numbers(const json& j, const std::string& key, const std::string& file) {
  std::vector<double> out;
  const json& v = (j.is_object() && j.contains("data")) ? j.at("data") : j;
  auto add = [&](const json& x) {
    if (!x.is_number()) fail(file, "'" + key + "' must hold numbers, found " + shown(x));
    const double d = x.get<double>();
    if (!std::isfinite(d)) fail(file, "'" + key + "' holds a value that is not finite (" + shown(x) + ")");
    out.push_back(d);
  };
  if (v.is_number()) {
    add(v);
  } else if (v.is_array()) {
    for (const json& e : v) {
      if (e.is_array()) {
        for (const json& x : e) add(x);
      } else {
        add(e);
      }
    }
  } else {
    fail(file, "'" + key + "' must be a number or an array of numbers, found " + shown(v));
  }
  return out;
}

std::vector<double> numbers_n(const json& j, const std::string& key, size_t n, const std::string& file) {
  if (!j.contains(key)) fail(file, "missing key '" + key + "'");
  std::vector<double> v = numbers(j.at(key), key, file);
  if (v.size() != n)
    fail(file, "'" + key + "' needs " + std::to_string(n) + " values, found " + std::to_string(v.size()));
  return v;
}

double number(const json& j, const std::string& key, const std::string& file) {
  return numbers_n(j, key, 1, file)[0];
}

}  // namespace

long long parse_integer_arg(const std::string& flag, const std::string& text, long long lo, long long hi) {
  size_t used = 0;
  long long x = 0;
  try {
    x = std::stoll(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size())
    throw std::invalid_argument(flag + ": expected an integer, got '" + text + "'");
  if (x < lo || x > hi)
    throw std::invalid_argument(flag + ": " + text + " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return x;
}

double parse_number_arg(const std::string& flag, const std::string& text) {
  size_t used = 0;
  double x = 0;
  try {
    x = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(x))
    throw std::invalid_argument(flag + ": expected a number, got '" + text + "'");
  return x;
}

double parse_number_arg(const std::string& flag, const std::string& text, double lo, double hi) {
  const double x = parse_number_arg(flag, text);
  if (x < lo || x > hi) {
    std::ostringstream m;
    m << flag << ": " << text << " is outside [" << lo << ", " << hi << "]";
    throw std::invalid_argument(m.str());
  }
  return x;
}

void check_yaml_expansion(const YAML::Node& root, const std::string& origin) {
  long long nodes = input_limits::kMaxYamlNodes;
  count_yaml_nodes(root, origin, nodes, 0);
}

std::string read_text_file(const std::string& path, const std::string& what) {
  try {
    check_input_file(path);
  } catch (const InputFileError& e) {
    throw std::runtime_error(path + ": cannot open " + what + ": " + e.what());
  }
  std::error_code ec;
  if (fs::file_size(path, ec) > input_limits::kMaxTextFileBytes)
    throw std::runtime_error(path + ": more than " + std::to_string(input_limits::kMaxTextFileBytes >> 20) +
                             " MB: not " + what);
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open " + what);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void check_input_file(const std::string& path) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);  // (follows links: /dev/fd/N of a shell's <(...) is a pipe)
  if (!fs::exists(st)) fail(path, "file does not exist");
  if (fs::is_directory(st)) fail(path, "is a directory, expected a file");
  if (!fs::is_regular_file(st)) {
    const char* kind = fs::is_fifo(st)                                          ? "a pipe (FIFO)"
                       : fs::is_character_file(st) || fs::is_block_file(st) ? "a device"
                       : fs::is_socket(st)                                      ? "a socket"
                                                                                : "not a file";
    fail(path, std::string("is ") + kind + ", not a regular file: refused, since reading it may never end "
                                           "(write it to a file first)");
  }
  std::ifstream probe(path, std::ios::binary);
  if (!probe) fail(path, "cannot open the file for reading");
}

Camera read_camera_file(const std::string& path, int image_width, int image_height) {
  const std::string ext = lower(fs::path(path).extension().string());
  json j;
  if (ext == ".json") j = read_json_file(path);
  else if (ext == ".yaml" || ext == ".yml") j = read_yaml_file(path);
  else {
    check_file(path);
    fail(path, "unknown camera file type '" + ext + "' (expected .json, .yaml or .yml)");
  }
  if (!j.is_object()) fail(path, "expected a mapping of camera parameters");
  const std::vector<std::string> matrix_keys = {"cam_K", "K", "k", "camera_matrix"};
  auto has_intrinsics = [&](const json& o) {
    if (o.contains("fx")) return true;
    for (const auto& k : matrix_keys)
      if (o.contains(k)) return true;
    return false;
  };
  // A BOP scene_camera.json with a single image: {"0": {"cam_K": [...], ...}}.
  if (!has_intrinsics(j) && j.size() == 1 && j.begin().value().is_object() && has_intrinsics(j.begin().value())) {
    const json inner = j.begin().value();
    j = inner;
  } else if (!has_intrinsics(j) && j.size() > 1 && j.begin().value().is_object() &&
             has_intrinsics(j.begin().value())) {
    fail(path, "holds " + std::to_string(j.size()) +
                   " cameras (a BOP scene_camera.json?); give a file with the one camera of this image");
  }
  Camera cam;
  if (j.contains("fx")) {
    cam.fx = number(j, "fx", path);
    cam.fy = number(j, "fy", path);
    cam.cx = number(j, "cx", path);
    cam.cy = number(j, "cy", path);
  } else {
    std::string key;
    for (const auto& k : matrix_keys)
      if (j.contains(k)) {
        key = k;
        break;
      }
    if (key.empty())
      fail(path, "missing key 'fx' (expected fx, fy, cx, cy[, width, height] or BOP's cam_K: 9 values)");
    const std::vector<double> K = numbers_n(j, key, 9, path);
    if (std::abs(K[6]) > 1e-9 || std::abs(K[7]) > 1e-9 || std::abs(K[8] - 1.0) > 1e-9)
      fail(path, "'" + key + "' is not an intrinsic matrix (its last row must be 0 0 1)");
    if (std::abs(K[3]) > 1e-9) fail(path, "'" + key + "' is not an intrinsic matrix (K[1][0] must be 0)");
    if (std::abs(K[1]) > 1e-3 * std::abs(K[0]))
      fail(path, "'" + key + "' has a skew term (K[0][1] = " + std::to_string(K[1]) + "), which is not supported");
    cam.fx = K[0];
    cam.fy = K[4];
    cam.cx = K[2];
    cam.cy = K[5];
  }
  if (!(cam.fx > 0) || !(cam.fy > 0)) fail(path, "focal lengths must be positive");
  // Size: width/height (ROS: image_width/image_height) when given, else the image's.
  auto size_key = [&](const char* a, const char* b) -> std::string {
    return j.contains(a) ? a : (j.contains(b) ? b : "");
  };
  const std::string wk = size_key("width", "image_width"), hk = size_key("height", "image_height");
  if (wk.empty() != hk.empty()) fail(path, "give both width and height, or neither");
  cam.width = image_width;
  cam.height = image_height;
  if (!wk.empty()) {
    const double w = number(j, wk, path), h = number(j, hk, path);
    if (w != std::floor(w) || h != std::floor(h) || w < 0 || h < 0 || w > 1e6 || h > 1e6)
      fail(path, "width and height must be positive integers");
    // ROS camera_info leaves both 0 when unknown: then the image decides.
    if (!(w == 0 && h == 0) && (int(w) != image_width || int(h) != image_height))
      fail(path, "camera size " + size_str(int(w), int(h)) + " does not match the rgb image (" +
                     size_str(image_width, image_height) + ")");
  }
  try {
    cam.validate();
  } catch (const std::invalid_argument& e) {
    fail(path, e.what());
  }
  return cam;
}

Pose read_pose_file(const std::string& path) {
  const json j = read_json_file(path);
  if (!j.is_object()) fail(path, "expected a JSON object with R + t, quaternion + t, or matrix");
  const int forms = int(j.contains("R")) + int(j.contains("quaternion")) + int(j.contains("matrix"));
  if (forms == 0) fail(path, "expected one of {\"R\": [9], \"t\": [3]}, {\"quaternion\": [x,y,z,w], \"t\": [3]}, "
                             "{\"matrix\": [16]}");
  if (forms > 1) fail(path, "give only one of R, quaternion or matrix");
  Pose pose;
  const char* rot_key = "R";
  if (j.contains("matrix")) {
    rot_key = "matrix";
    const std::vector<double> m = numbers_n(j, "matrix", 16, path);
    Eigen::Matrix4d T;
    for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = m[i];
    if ((T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6)
      fail(path, "'matrix' is not a rigid transform (its last row must be 0 0 0 1)");
    pose = Pose::from_matrix(T);
  } else {
    const std::vector<double> t = numbers_n(j, "t", 3, path);
    const Eigen::Vector3d tv(t[0], t[1], t[2]);
    if (j.contains("R")) {
      const std::vector<double> r = numbers_n(j, "R", 9, path);
      std::array<double, 9> a;
      std::copy(r.begin(), r.end(), a.begin());
      pose = Pose::from_rotation_rowmajor(a, tv);
    } else {
      rot_key = "quaternion";
      const std::vector<double> q = numbers_n(j, "quaternion", 4, path);
      const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      if (std::abs(norm - 1.0) > 1e-2)
        fail(path, "'quaternion' has norm " + std::to_string(norm) + ", expected a unit quaternion [x, y, z, w]");
      pose = Pose::from_quaternion(q[0], q[1], q[2], q[3], tv);
    }
  }
  if (!pose.R.allFinite() || !pose.t.allFinite()) fail(path, "the pose holds values that are not finite");
  const double ortho = (pose.R.transpose() * pose.R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (ortho > 1e-3)
    fail(path, std::string("the rotation in '") + rot_key + "' is not orthonormal (|R^T R - I| = " +
                   std::to_string(ortho) + ")");
  if (pose.R.determinant() < 0) fail(path, std::string("the rotation in '") + rot_key + "' is a reflection (det -1)");
  pose.orthonormalize();
  return pose;
}

}  // namespace diffdope
