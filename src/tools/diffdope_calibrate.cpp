// diffdope_calibrate: calibrates a static camera to a robot from the robot's own meshes (URDF) and a few captures
// of it at known joint positions (include/diffdope/calibration.hpp), everything read from files.
//   diffdope_calibrate --urdf FILE --captures DIR --camera FILE --init FILE --out DIR [options]
//   diffdope_calibrate --generate DIR [--count N] [--seed S] [--init-error CM DEG] [--no-mask] [--no-rgb]
//                      [--no-table] [--eye-in-hand link5] [--depth-noise MM] [--noise-grain PX]
//                      [--holes F] [--flying-pixels F]
// Writes DIR/calibration.yaml (easy_handeye's layout), DIR/calibration.launch (a static_transform_publisher),
// DIR/result.json, DIR/residuals.txt and DIR/overlay_<capture>.png. Every unusable input is one line
// `diffdope_calibrate: <file>: <problem>` with exit code 1; command-line mistakes print the usage, exit code 2.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <nlohmann/json.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "diffdope/calibration.hpp"
#include "diffdope/input_files.hpp"
#include "diffdope/input_limits.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/procedural_robot.hpp"
#include "diffdope/synthetic.hpp"
#include "calibration_generate.hpp"
#include "tool_io.hpp"

using namespace diffdope;
using namespace diffdope::tools;
namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace {

const char* kUsage =
    "usage: diffdope_calibrate --urdf FILE --captures DIR --camera FILE --init FILE --out DIR\n"
    "                          [--package-path NAME=DIR]... [--depth-scale M] [--config FILE] [--passes N]\n"
    "                          [--mask-margin M] [--eye-in-hand LINK] [--robot-base-frame NAME]\n"
    "                          [--camera-frame NAME] [--truth FILE] [--quiet]\n"
    "       diffdope_calibrate --generate DIR [--count N] [--seed S] [--init-error CM DEG] [--no-mask] [--no-rgb]\n"
    "                                                 [--no-table] [--eye-in-hand link5] [--depth-noise MM]\n"
    "                                                 [--noise-grain PX] [--holes F] [--flying-pixels F]\n"
    "\n"
    "  --urdf FILE            the robot (meshes: STL, DAE, OBJ, PLY...; package:// paths, see --package-path)\n"
    "  --captures DIR         one folder per capture (in name order), each with depth.png (16-bit, millimetres;\n"
    "                         or a float image in metres with --depth-scale 1), joints.json ({\"joint\": radians}\n"
    "                         or a JointState-like {\"name\": [...], \"position\": [...]}), optional rgb.png and\n"
    "                         mask.png (nonzero = robot; all captures or none)\n"
    "  --camera FILE          intrinsics (.json / .yaml, as diffdope_refine), the depth images' size\n"
    "  --init FILE            initial guess of the camera's pose in the robot base frame (base -> camera optical\n"
    "                         frame, metres; eye in hand: in LINK's frame), JSON: {\"R\": [9], \"t\": [3]},\n"
    "                         {\"quaternion\": [x,y,z,w], \"t\": [3]} or {\"matrix\": [16]}; 5 cm / 10 deg off is\n"
    "                         fine, see docs/calibration.md for more\n"
    "  --out DIR              output folder (created)\n"
    "  --package-path N=DIR   resolve package://N/... to DIR/... (repeatable; else ROS_PACKAGE_PATH is searched)\n"
    "  --depth-scale M        metres per depth unit (default 0.001)\n"
    "  --config FILE          refiner options YAML over the calibration's defaults (see config/default.yaml)\n"
    "  --passes N             descents in a row (default 2)\n"
    "  --mask-margin M        without masks: metres around the robot at the guess that count as robot (0.08)\n"
    "  --eye-in-hand LINK     the camera rides on LINK (e.g. the end effector): calibrates LINK -> camera; the\n"
    "                         links fixed to LINK are left out (default: eye to hand, a static camera)\n"
    "  --robot-base-frame F   frame name for the outputs (default: the URDF's root link)\n"
    "  --camera-frame F       frame name for the outputs (default camera_color_optical_frame)\n"
    "  --truth FILE           the true camera pose (same format as --init): prints and stores the errors\n"
    "  --quiet                no progress on the terminal\n"
    "  --generate DIR         writes a generated arm, N captures of it (default 3), camera.json, init.json (the\n"
    "                         truth moved by --init-error, default 5 cm 10 deg) and truth.json, then exits;\n"
    "                         the arm stands on a table with a box and a can beside it (--no-table: alone)\n"
    "  --depth-noise MM       the generated depth's noise at 1 m, growing with z^2 (default 2; a RealSense\n"
    "                         D435 is about 3-8)\n"
    "  --noise-grain PX       the depth noise correlated over PX pixels, as a stereo camera's (default 0:\n"
    "                         independent per pixel)\n"
    "  --holes F              the share of depth pixels in dropout holes (default 0.05)\n"
    "  --flying-pixels F      the share of silhouette-border pixels with a mixed depth (default 0: none)\n";

int usage_error(const std::string& what) {
  std::cerr << "diffdope_calibrate: " << what << "\n" << kUsage;
  return 2;
}

// ---- Reading captures ----

std::map<std::string, double> read_joints(const std::string& path) {
  check_file(path);
  std::string text;
  try {
    text = read_text_file(path, "a joints file");
  } catch (const std::exception& e) {
    fail(path, strip_file_prefix(one_line(e.what()), path));
  }
  const nlohmann::json j = parse_json_checked(text, path);  // (nesting bounded; errors name the file)
  std::map<std::string, double> q;
  const auto number = [&](const std::string& name, const nlohmann::json& v) {
    if (!v.is_number()) fail(path, "joint '" + name + "': expected a number");
    const double x = v.get<double>();
    if (!std::isfinite(x)) fail(path, "joint '" + name + "': not finite");
    q[name] = x;
  };
  if (j.is_object() && j.contains("name") && j.contains("position")) {  // JointState-like
    if (!j["name"].is_array() || !j["position"].is_array() || j["name"].size() != j["position"].size())
      fail(path, "'name' and 'position' must be arrays of the same length");
    for (size_t i = 0; i < j["name"].size(); ++i) {
      if (!j["name"][i].is_string()) fail(path, "'name' must hold strings");
      number(j["name"][i].get<std::string>(), j["position"][i]);
    }
  } else if (j.is_object()) {
    for (const auto& [name, v] : j.items()) number(name, v);
  } else {
    fail(path, "expected {\"joint\": position, ...} or {\"name\": [...], \"position\": [...]}");
  }
  if (q.empty()) fail(path, "no joint positions");
  return q;
}

struct Args {
  std::string urdf, captures, camera, init, out, config, truth, base_frame, camera_frame = "camera_color_optical_frame";
  std::string hand_link;  // eye in hand: the link the camera rides on
  bool hand_set = false;
  std::map<std::string, std::string> packages;
  double depth_scale = 0.001, mask_margin = -1;
  int passes = 0;
  bool quiet = false;
};

std::vector<CalibrationCapture> read_captures(const Args& a) {
  if (!fs::is_directory(a.captures)) fail(a.captures, "not a folder");
  std::vector<fs::path> dirs;
  for (const auto& e : fs::directory_iterator(a.captures))
    if (e.is_directory()) dirs.push_back(e.path());
  std::sort(dirs.begin(), dirs.end());
  if (dirs.empty()) fail(a.captures, "no capture folder in it (one folder per capture: depth.png, joints.json)");
  if (dirs.size() > size_t(input_limits::kMaxCaptures))  // (before any is read: each costs its images' memory)
    fail(a.captures, std::to_string(dirs.size()) + " capture folders; at most " +
                         std::to_string(input_limits::kMaxCaptures) + " (three to ten constrain every direction)");
  std::vector<CalibrationCapture> out;
  Camera cam;
  for (const fs::path& d : dirs) {
    CalibrationCapture c;
    c.name = d.filename().string();
    const std::string depth_path = (d / "depth.png").string();
    const cv::Mat depth = read_image(depth_path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "depth");
    if (depth.channels() != 1) fail(depth_path, "depth must have one channel, found " + std::to_string(depth.channels()));
    if (out.empty()) cam = read_camera_file(a.camera, depth.cols, depth.rows);
    if (depth.cols != cam.width || depth.rows != cam.height)
      fail(depth_path, "depth image is " + size_str(depth.cols, depth.rows) + " but the camera is " +
                           size_str(cam.width, cam.height));
    c.camera = cam;
    c.observed.depth = about(depth_path, [&] { return to_depth_metres(depth, a.depth_scale, depth_path); });
    if (cv::countNonZero(c.observed.depth > 0) == 0) fail(depth_path, "the depth image has no valid reading");
    const std::string rgb_path = (d / "rgb.png").string(), mask_path = (d / "mask.png").string();
    if (fs::exists(rgb_path)) {
      const cv::Mat rgb = read_image(rgb_path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "rgb");
      if (rgb.cols != cam.width || rgb.rows != cam.height)
        fail(rgb_path, "rgb image is " + size_str(rgb.cols, rgb.rows) + " but depth is " + size_str(cam.width, cam.height));
      c.observed.rgb = about(rgb_path, [&] { return to_rgb_float(rgb, true, rgb_path); });
    }
    if (fs::exists(mask_path)) {
      const cv::Mat m = read_image(mask_path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "mask");
      if (m.cols != cam.width || m.rows != cam.height)
        fail(mask_path, "mask is " + size_str(m.cols, m.rows) + " but depth is " + size_str(cam.width, cam.height));
      c.observed.mask = about(mask_path, [&] { return to_mask_float(m, mask_path); });
      if (cv::countNonZero(c.observed.mask > 0) == 0) fail(mask_path, "the mask is empty (the robot is not in it)");
    }
    if (!out.empty() && c.observed.has_mask() != out.front().observed.has_mask())
      fail(d.string(), "has " + std::string(c.observed.has_mask() ? "a" : "no") + " mask.png but capture '" +
                           out.front().name + "' has " + (out.front().observed.has_mask() ? "one" : "none") +
                           ": give every capture a mask, or none");
    c.joint_positions = read_joints((d / "joints.json").string());
    out.push_back(std::move(c));
  }
  return out;
}

// ---- Outputs ----

int run(const Args& a) {
  CalibrationOptions options;
  if (!a.config.empty()) {
    check_file(a.config);
    options.refiner = about(a.config, [&] { return RefinerOptions::from_yaml_file(a.config, options.refiner); });
  }
  if (a.passes > 0) options.passes = a.passes;
  if (a.mask_margin >= 0) options.mask_margin = a.mask_margin;
  about("options", [&] { options.validate(); });

  check_file(a.urdf);
  const PackageResolver resolve = [&](const std::string& pkg) -> std::string {
    const auto it = a.packages.find(pkg);
    if (it != a.packages.end()) return it->second;
    if (const char* rpp = std::getenv("ROS_PACKAGE_PATH")) {  // offline, without roslib
      std::stringstream ss(rpp);
      std::string root;
      while (std::getline(ss, root, ':'))
        if (!root.empty() && fs::exists(fs::path(root) / pkg / "package.xml")) return (fs::path(root) / pkg).string();
    }
    throw std::runtime_error("package '" + pkg + "' not found (give --package-path " + pkg + "=DIR)");
  };
  const RobotModel robot = about(a.urdf, [&] {
    QuietStderr quiet;  // urdfdom and assimp print their own complaints
    return RobotModel::load_urdf(a.urdf, resolve);
  });
  const CameraMount mount{a.hand_link};
  about(a.urdf, [&] { mount.check(robot); });  // (--eye-in-hand: a link of this robot that moves)
  std::vector<CalibrationCapture> captures = read_captures(a);
  for (const CalibrationCapture& c : captures)  // every joint the robot needs, named in the capture's file
    about((fs::path(a.captures) / c.name / "joints.json").string(), [&] { robot.link_poses(c.joint_positions); });
  const Pose base_from_camera0 = read_pose_file(a.init);  // (mount <- camera: the base, or the hand's link)
  const std::optional<Pose> truth = a.truth.empty() ? std::nullopt : std::optional<Pose>(read_pose_file(a.truth));
  const Pose initial = base_from_camera0.inverse();

  std::error_code ec;
  fs::create_directories(a.out, ec);
  if (ec) fail(a.out, "cannot create the output folder: " + ec.message());

  Calibrator calibrator(options);
  const bool progress = !a.quiet && isatty(2);
  if (progress)
    calibrator.on_iteration = [&](int p, int k, int total, double loss) {
      std::fprintf(stderr, "\rpass %d/%d  iteration %3d/%d  loss %.5f ", p + 1, options.passes, k, total, loss);
    };
  CalibrationResult r;
  try {
    r = calibrator.calibrate(robot, captures, initial, mount);
  } catch (const std::invalid_argument& e) {
    if (progress) std::fprintf(stderr, "\n");
    fail(a.captures, one_line(e.what()));
  }
  if (progress) std::fprintf(stderr, "\n");
  const Pose base_from_camera = r.camera_from_mount.inverse();
  const std::string base = mount.eye_in_hand() ? mount.link : a.base_frame.empty() ? robot.root_link() : a.base_frame;

  // Overlays: the robot at the guess (red) and calibrated (green) over each capture.
  const auto renderer = make_cpu_renderer();
  for (const CalibrationCapture& c : captures) {
    const Mesh posed = merge_meshes(mount.posed_robot(robot, c.joint_positions), c.name);
    cv::Mat bgr;
    if (c.observed.has_rgb()) {
      bgr = to_bgr8(c.observed.rgb);
    } else {  // depth as grey
      cv::Mat d;
      c.observed.depth.convertTo(d, CV_8U, 255.0 / 3.0);
      cv::cvtColor(d, bgr, cv::COLOR_GRAY2BGR);
    }
    const auto imgs = renderer->render(c.camera, posed, {initial, r.camera_from_mount});
    draw_render(bgr, imgs[0], cv::Scalar(0, 0, 255), 1);
    draw_render(bgr, imgs[1], cv::Scalar(0, 255, 0), 2);
    put_label(bgr, "guess", cv::Point(8, 24), cv::Scalar(0, 0, 255), 0.6);
    put_label(bgr, "calibrated", cv::Point(8, 48), cv::Scalar(0, 255, 0), 0.6);
    write_image((fs::path(a.out) / ("overlay_" + c.name + ".png")).string(), bgr);
  }

  std::ostringstream table;
  table << "capture          loss     mask IoU  depth inliers  median |depth error|  depth noise at 1 m  mask\n";
  for (const CaptureResidual& c : r.captures) {
    char line[200];
    std::snprintf(line, sizeof line, "%-14s  %7.4f  %8.3f  %13.3f  %15.2f mm  %15.2f mm  %s\n", c.name.c_str(),
                  c.loss, c.mask_iou, c.depth_inliers, c.depth_median_mm, c.depth_noise_mm,
                  c.derived_mask ? "derived" : "given");
    table << line;
  }
  const double moved_mm = 1e3 * (base_from_camera.t - base_from_camera0.t).norm();
  const double moved_deg = Eigen::AngleAxisd(base_from_camera.R * base_from_camera0.R.transpose()).angle() * 180 / M_PI;
  json result{{"base_from_camera", pose_file_json(base_from_camera)},
              {"camera_from_base", pose_file_json(r.camera_from_mount)},
              {"initial_base_from_camera", pose_file_json(base_from_camera0)},
              {"moved_from_guess", {{"mm", moved_mm}, {"deg", moved_deg}}},
              {"plausible", r.plausible},
              {"confidence", r.confidence},
              {"diverged", r.diverged},
              {"position_std_mm", r.position_std < 0 ? -1.0 : 1e3 * r.position_std},
              {"rotation_std_deg", r.rotation_std < 0 ? -1.0 : r.rotation_std * 180 / M_PI},
              {"passes", r.passes},
              {"time_s", r.time_ms / 1e3},
              {"robot_base_frame", base},
              {"camera_frame", a.camera_frame}};
  json rows = json::array();
  for (const CaptureResidual& c : r.captures)
    rows.push_back({{"name", c.name}, {"loss", c.loss}, {"mask_iou", c.mask_iou}, {"depth_inliers", c.depth_inliers},
                    {"depth_median_mm", c.depth_median_mm}, {"depth_noise_mm", c.depth_noise_mm},
                    {"derived_mask", c.derived_mask}});
  result["captures"] = rows;
  std::string truth_line;
  if (truth) {
    const double mm = 1e3 * (base_from_camera.t - truth->t).norm();
    const double deg = Eigen::AngleAxisd(base_from_camera.R * truth->R.transpose()).angle() * 180 / M_PI;
    result["error_vs_truth"] = {{"camera_position_mm", mm}, {"rotation_deg", deg}};
    truth_line = "error against " + a.truth + ": camera position " + fmt(mm, "%.2f") + " mm, rotation " +
                 fmt(deg, "%.3f") + " deg\n";
  }
  write_text((fs::path(a.out) / "calibration.yaml").string(), easy_handeye_yaml(base_from_camera, base, a.camera_frame,
                                                                                       mount.eye_in_hand()));
  write_text((fs::path(a.out) / "calibration.launch").string(), static_transform_launch(base_from_camera, base, a.camera_frame));
  write_text((fs::path(a.out) / "residuals.txt").string(), table.str());
  write_text((fs::path(a.out) / "result.json").string(), result.dump(2) + "\n");
  if (!a.quiet) {
    const std::string firmness = r.position_std < 0 ? std::string("(undetermined)")
                                                    : fmt(1e3 * r.position_std, "%.2f") + " mm / " +
                                                          fmt(r.rotation_std * 180 / M_PI, "%.3f") + " deg (1 sigma)";
    std::printf("%s", table.str().c_str());
    std::printf("camera in %s: t = [%.4f %.4f %.4f] m, quaternion [%.5f %.5f %.5f %.5f] (moved %.1f mm, %.2f deg "
                "from the guess)\n%s, confidence %.2f; pinned down to %s; %d capture(s), %.1f s\n%s",
                base.c_str(), base_from_camera.t.x(), base_from_camera.t.y(), base_from_camera.t.z(),
                base_from_camera.quaternion_xyzw()[0], base_from_camera.quaternion_xyzw()[1],
                base_from_camera.quaternion_xyzw()[2], base_from_camera.quaternion_xyzw()[3], moved_mm, moved_deg,
                r.plausible ? "plausible"
                : r.diverged ? "NOT plausible: a pass drove the robot out of view (diverged)"
                             : "NOT plausible (check the overlays and the residuals)",
                r.confidence,
                firmness.c_str(), int(captures.size()), r.time_ms / 1e3, truth_line.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  Args a;
  GenerateOptions gen;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string k = argv[i];
      if (k == "-h" || k == "--help") {
        std::cout << kUsage;
        return 0;
      }
      if (k == "--quiet") { a.quiet = true; continue; }
      if (k == "--no-mask") { gen.masks = false; continue; }
      if (k == "--no-rgb") { gen.rgb = false; continue; }
      if (k == "--no-table") { gen.table = false; continue; }
      if (i + 1 >= argc) return usage_error(k + ": missing value");
      const std::string v = argv[++i];
      if (k == "--urdf") a.urdf = v;
      else if (k == "--captures") a.captures = v;
      else if (k == "--camera") a.camera = v;
      else if (k == "--init") a.init = v;
      else if (k == "--out") a.out = v;
      else if (k == "--config") a.config = v;
      else if (k == "--truth") a.truth = v;
      else if (k == "--robot-base-frame") a.base_frame = v;
      else if (k == "--eye-in-hand") a.hand_link = v, a.hand_set = true;
      else if (k == "--camera-frame") a.camera_frame = v;
      else if (k == "--depth-scale") a.depth_scale = parse_number_arg(k, v);
      else if (k == "--mask-margin") a.mask_margin = parse_number_arg(k, v);
      else if (k == "--passes") a.passes = int(parse_integer_arg(k, v, 1, 10));
      else if (k == "--package-path") {
        const size_t eq = v.find('=');
        if (eq == std::string::npos || eq == 0 || eq + 1 == v.size())
          return usage_error("--package-path: expected NAME=DIR, got '" + v + "'");
        a.packages[v.substr(0, eq)] = v.substr(eq + 1);
      } else if (k == "--generate") gen.dir = v;
      else if (k == "--count") gen.count = int(parse_integer_arg(k, v, 1, 100));
      else if (k == "--seed") gen.seed = uint64_t(parse_integer_arg(k, v, 0, 1LL << 62));
      else if (k == "--init-error") {
        if (i + 1 >= argc) return usage_error("--init-error: expected CM DEG");
        gen.init_cm = parse_number_arg(k, v);
        gen.init_deg = parse_number_arg(k, argv[++i]);
        if (gen.init_cm < 0 || gen.init_deg < 0 || gen.init_cm > 100 || gen.init_deg > 90)
          return usage_error("--init-error: CM in [0, 100], DEG in [0, 90]");
      } else if (k == "--depth-noise") gen.noise.depth_sigma_at_1m = 0.001 * parse_number_arg(k, v, 0, 50);
      else if (k == "--noise-grain") gen.noise.depth_noise_grain_px = parse_number_arg(k, v, 0, 10);
      else if (k == "--holes") gen.noise.hole_fraction = parse_number_arg(k, v, 0, 1);
      else if (k == "--flying-pixels") gen.noise.flying_pixel_fraction = parse_number_arg(k, v, 0, 1);
      else return usage_error("unknown option '" + k + "'");
    }
    if (!(a.depth_scale > 0)) return usage_error("--depth-scale must be positive");
    if (a.camera_frame.empty()) return usage_error("--camera-frame: empty frame name");
    if (a.hand_set && a.hand_link.empty()) return usage_error("--eye-in-hand: empty link name");
    if (!a.hand_link.empty() && !a.base_frame.empty())
      return usage_error("--robot-base-frame: eye in hand the result is in the --eye-in-hand link's frame");
  } catch (const std::invalid_argument& e) {
    return usage_error(e.what());
  }
  try {
    if (!gen.dir.empty()) {
      if (!a.hand_link.empty() && a.hand_link != kGeneratedHandLink)
        return usage_error(std::string("--generate --eye-in-hand: the generated arm's camera rides on ") +
                           kGeneratedHandLink);
      gen.eye_in_hand = !a.hand_link.empty();
      return generate_calibration_set(gen);
    }
    for (const auto& [flag, value] : {std::pair<const char*, std::string>{"--urdf", a.urdf}, {"--captures", a.captures},
                                      {"--camera", a.camera}, {"--init", a.init}, {"--out", a.out}})
      if (value.empty()) return usage_error(std::string(flag) + " is required");
    return run(a);
  } catch (const InputError& e) {
    std::cerr << "diffdope_calibrate: " << e.file << ": " << one_line(e.what()) << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "diffdope_calibrate: " << one_line(e.what()) << "\n";
    return 1;
  }
}
