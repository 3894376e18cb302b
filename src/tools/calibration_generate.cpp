// diffdope_calibrate --generate (calibration_generate.hpp).
#include "calibration_generate.hpp"

#include <cstdio>
#include <filesystem>
#include <random>
#include <set>
#include <vector>

#include "diffdope/robot_model.hpp"
#include "diffdope/procedural_robot.hpp"
#include "diffdope/synthetic.hpp"
#include "tool_io.hpp"

namespace diffdope::tools {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

/// Share of the image the robot (less the links fixed to the camera) must cover for an eye-in-hand capture to
/// show enough of it.
constexpr double kMinHandViewCoverage = 0.05;

void write_capture(const fs::path& dir, const SyntheticScene& s, const std::map<std::string, double>& q,
                   const GenerateOptions& o) {
  fs::create_directories(dir);
  cv::Mat depth_mm;
  s.depth.convertTo(depth_mm, CV_16U, 1000.0);
  write_image((dir / "depth.png").string(), depth_mm);
  if (o.rgb) write_image((dir / "rgb.png").string(), to_bgr8(s.rgb));
  if (o.masks) write_image((dir / "mask.png").string(), cv::Mat(s.visible_masks[0] >= 0.5f));
  json joints;
  for (const auto& [n, v] : q) joints[n] = v;
  write_text((dir / "joints.json").string(), joints.dump(2) + "\n");
}

}  // namespace

int generate_calibration_set(const GenerateOptions& o) {
  fs::create_directories(fs::path(o.dir) / "captures");
  const GeneratedRobot robot = write_generated_robot((fs::path(o.dir) / "robot").string());
  const RobotModel model = RobotModel::load_urdf(robot.urdf_path);
  const GeneratedView view = generated_view();
  const Camera& cam = view.camera;
  // The unknown: camera <- base on a stand, camera <- hand on the bracket; the guess is moved about the arm's
  // centre in the mount's frame.
  Pose truth = view.camera_from_base;
  Eigen::Vector3d centre = view.centre;
  if (o.eye_in_hand) {
    const auto reference = hand_reference_configuration();
    const Pose base_from_hand = model.link_poses(reference).at(kGeneratedHandLink);
    truth = generated_hand_camera(base_from_hand);
    centre = base_from_hand.inverse() * view.centre;
  }
  std::mt19937_64 rng(o.seed);
  const auto renderer = make_cpu_renderer();
  const std::set<std::string> hand_links =
      o.eye_in_hand ? model.links_fixed_to(kGeneratedHandLink) : std::set<std::string>{};
  for (int k = 0; k < o.count; ++k) {
    // The bracket's camera does not see its own hand: the scene leaves those links out, and so does the mask.
    std::map<std::string, double> q;
    Pose camera_from_base = truth;
    Mesh arm;
    if (o.eye_in_hand) {  // a configuration whose view shows enough of the arm (the hand's links say nothing)
      for (int tries = 0;; ++tries) {
        q = random_hand_configuration(robot, rng);
        camera_from_base = truth * model.link_poses(q).at(kGeneratedHandLink).inverse();
        arm = merge_meshes(model.posed_visuals(q, hand_links), "arm");
        const RenderImage img = renderer->render(cam, arm, {camera_from_base})[0];
        if (cv::countNonZero(img.coverage >= 0.5f) >= kMinHandViewCoverage * cam.width * cam.height) break;
        if (tries == 100) throw std::runtime_error("no configuration near the reference shows the arm");
      }
    } else {
      q = random_configuration(robot, rng);
      arm = merge_meshes(model.posed_visuals(q), "arm");
    }
    RobotSceneOptions scene;
    scene.table = o.table;
    scene.occluder = k % 3 == 1;  // every third capture has a box floating in front of the upper arm
    scene.noise = o.noise;
    const SyntheticScene s = synthesize_robot_scene(*renderer, cam, arm, camera_from_base, scene,
                                                    uint32_t(o.seed * 1000 + k));
    char name[16];
    std::snprintf(name, sizeof name, "%02d", k);
    write_capture(fs::path(o.dir) / "captures" / name, s, q, o);
  }
  write_text((fs::path(o.dir) / "camera.json").string(),
             json{{"fx", cam.fx}, {"fy", cam.fy}, {"cx", cam.cx}, {"cy", cam.cy}, {"width", cam.width},
                  {"height", cam.height}}.dump(2) + "\n");
  const Pose guess = perturb_pose(truth, centre, o.init_deg * M_PI / 180, 0.01 * o.init_cm, rng);
  write_text((fs::path(o.dir) / "init.json").string(), pose_file_json(guess.inverse()).dump(2) + "\n");
  write_text((fs::path(o.dir) / "truth.json").string(), pose_file_json(truth.inverse()).dump(2) + "\n");
  std::printf("wrote %s: robot/robot.urdf, %d captures, camera.json, init.json (%.1f cm, %.1f deg off), truth.json"
              "%s\n", o.dir.c_str(), o.count, o.init_cm, o.init_deg,
              o.eye_in_hand ? " (eye in hand: calibrate with --eye-in-hand link5)" : "");
  return 0;
}

}  // namespace diffdope::tools
