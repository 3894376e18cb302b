// diffdope_make_calibration_bag: writes the data of the calibration node's rostest and demo: the generated arm
// (URDF and meshes), a bag in which it holds still in a few configurations and moves between them, the true
// camera pose and a guess 5 cm / 10 degrees off. The arm stands on a table with a box and a can beside it.
//
//   diffdope_make_calibration_bag --out DIR [--configurations N (4)] [--rate HZ (3)] [--seed S (1)] [--eye-in-hand]
//                                 [--depth-noise MM (2)] [--noise-grain PX (0)] [--flying-pixels F (0)]
//
// The depth camera's noise as diffdope_calibrate --generate's: MM at 1 m growing with z^2, correlated over PX
// pixels, and a share F of the silhouettes' border pixels reading a mixed depth.
//
// DIR/robot/robot.urdf (+ meshes), DIR/calibration.bag, DIR/truth.yaml (truth: [x, y, z, qx, qy, qz, qw], the
// camera in base_link; --eye-in-hand: the camera on the hand's bracket, its pose in link5) and DIR/guess.yaml
// (initial_guess: [...], the same 5 cm / 10 deg off, for rosparam load).
// Topics, the arm still for 2 s in each configuration and moving for 1 s between them (stamps from 1000 s):
//   /camera/depth/image_rect  sensor_msgs/Image 16UC1 millimetres (0 = no reading), camera_color_optical_frame
//   /camera/depth/camera_info sensor_msgs/CameraInfo
//   /camera/rgb/image_rect_color sensor_msgs/Image rgb8      /camera/mask sensor_msgs/Image mono8 (255 = robot)
//   /joint_states             sensor_msgs/JointState at 50 Hz (positions and velocities)
#include <cv_bridge/cv_bridge.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/JointState.h>
#include <sensor_msgs/image_encodings.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <set>

#include "diffdope/input_files.hpp"
#include "diffdope_ros/conversions.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/procedural_robot.hpp"
#include "diffdope/robot_model.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;
namespace fs = std::filesystem;

namespace {

std::string pose_list(const Pose& p) {
  const auto q = p.quaternion_xyzw();
  char b[256];
  std::snprintf(b, sizeof b, "[%.9f, %.9f, %.9f, %.9f, %.9f, %.9f, %.9f]", p.t.x(), p.t.y(), p.t.z(), q[0], q[1],
                q[2], q[3]);
  return b;
}

}  // namespace

int main(int argc, char** argv) {
  std::string out;
  int configurations = 4;
  double rate = 3;
  long long seed = 1;
  bool eye_in_hand = false;
  RobotSceneOptions scene;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string k = argv[i];
      if (k == "--eye-in-hand") {
        eye_in_hand = true;
        continue;
      }
      if (k == "-h" || k == "--help" || i + 1 >= argc) {
        std::cerr << "usage: diffdope_make_calibration_bag --out DIR [--configurations N] [--rate HZ] [--seed S]"
                     " [--eye-in-hand] [--depth-noise MM] [--noise-grain PX] [--flying-pixels F]\n";
        return k == "-h" || k == "--help" ? 0 : 2;
      }
      const std::string v = argv[++i];
      if (k == "--out") out = v;
      else if (k == "--configurations") configurations = int(parse_integer_arg(k, v, 1, 20));
      else if (k == "--rate") rate = double(parse_integer_arg(k, v, 1, 30));
      else if (k == "--seed") seed = parse_integer_arg(k, v, 0, 1LL << 40);
      else if (k == "--depth-noise") scene.noise.depth_sigma_at_1m = 0.001 * parse_number_arg(k, v, 0, 50);
      else if (k == "--noise-grain") scene.noise.depth_noise_grain_px = parse_number_arg(k, v, 0, 10);
      else if (k == "--flying-pixels") scene.noise.flying_pixel_fraction = parse_number_arg(k, v, 0, 1);
      else throw std::invalid_argument("unknown option '" + k + "'");
    }
    if (out.empty()) throw std::invalid_argument("--out DIR is required");
  } catch (const std::invalid_argument& e) {
    std::cerr << "diffdope_make_calibration_bag: " << e.what() << "\n";
    return 2;
  }
  try {
    fs::create_directories(out);
    const GeneratedRobot robot = write_generated_robot((fs::path(out) / "robot").string());
    const RobotModel model = RobotModel::load_urdf(robot.urdf_path);
    const GeneratedView view = generated_view();
    const Camera& cam = view.camera;
    // The unknown: camera <- base on a stand, camera <- link5 on the hand's bracket (procedural_robot.hpp).
    Pose truth = view.camera_from_base;
    Eigen::Vector3d centre = view.centre;
    std::set<std::string> hand_links;  // not drawn: the bracket's camera does not see its own hand
    if (eye_in_hand) {
      const Pose base_from_hand = model.link_poses(hand_reference_configuration()).at(kGeneratedHandLink);
      truth = generated_hand_camera(base_from_hand);
      centre = base_from_hand.inverse() * view.centre;
      hand_links = model.links_fixed_to(kGeneratedHandLink);
    }
    std::mt19937_64 rng{static_cast<uint64_t>(seed)};
    std::vector<std::map<std::string, double>> qs;
    for (int k = 0; k < configurations; ++k)
      qs.push_back(eye_in_hand ? random_hand_configuration(robot, rng) : random_configuration(robot, rng));
    const Pose guess = perturb_pose(truth, centre, 10 * M_PI / 180, 0.05, rng);
    std::ofstream(fs::path(out) / "truth.yaml") << "truth: " << pose_list(truth.inverse()) << "\n";
    std::ofstream(fs::path(out) / "guess.yaml") << "initial_guess: " << pose_list(guess.inverse()) << "\n";

    const double still = 2.0, move = 1.0, period = still + move;
    const double duration = configurations * period - move;
    // The joints at time tau: still, then a smooth (cosine) move to the next configuration.
    auto joints_at = [&](double tau, std::map<std::string, double>* velocity) {
      const int k = std::min(int(tau / period), configurations - 1);
      const double in = tau - k * period;
      std::map<std::string, double> q = qs[size_t(k)];
      for (auto& [n, v] : q) (*velocity)[n] = 0;
      if (in > still && k + 1 < configurations) {
        const double s = (in - still) / move, w = 0.5 - 0.5 * std::cos(M_PI * s);
        const double dw = 0.5 * M_PI * std::sin(M_PI * s) / move;
        for (auto& [n, v] : q) {
          const double a = qs[size_t(k)].at(n), b = qs[size_t(k + 1)].at(n);
          v = a + w * (b - a);
          (*velocity)[n] = dw * (b - a);
        }
      }
      return q;
    };
    rosbag::Bag bag;
    bag.open((fs::path(out) / "calibration.bag").string(), rosbag::bagmode::Write);
    bag.setCompression(rosbag::compression::LZ4);
    const ros::Time t0(1000.0);
    for (int j = 0; j * 0.02 <= duration + 0.5; ++j) {
      const double tau = j * 0.02;
      std::map<std::string, double> v;
      const auto q = joints_at(std::min(tau, duration), &v);
      sensor_msgs::JointState js;
      js.header.stamp = t0 + ros::Duration(tau);
      for (const auto& [n, x] : q) js.name.push_back(n), js.position.push_back(x), js.velocity.push_back(v.at(n));
      bag.write("/joint_states", js.header.stamp, js);
    }
    const auto renderer = make_cpu_renderer();
    for (int f = 0; f / rate <= duration; ++f) {
      const double tau = f / rate;
      std::map<std::string, double> v;
      const auto q = joints_at(tau, &v);
      const Mesh posed = merge_meshes(model.posed_visuals(q, hand_links), "arm");
      const Pose camera_from_base =
          eye_in_hand ? truth * model.link_poses(q).at(kGeneratedHandLink).inverse() : truth;
      const SyntheticScene s =
          synthesize_robot_scene(*renderer, cam, posed, camera_from_base, scene, uint32_t(seed * 1000 + f));
      std_msgs::Header h;
      h.stamp = t0 + ros::Duration(tau);
      h.frame_id = "camera_color_optical_frame";
      h.seq = uint32_t(f);
      cv::Mat depth_mm, rgb8, mask;
      s.depth.convertTo(depth_mm, CV_16U, 1000.0);
      s.rgb.convertTo(rgb8, CV_8UC3, 255.0);
      mask = s.visible_masks[0] >= 0.5f;
      bag.write("/camera/depth/image_rect", h.stamp,
                cv_bridge::CvImage(h, sensor_msgs::image_encodings::TYPE_16UC1, depth_mm).toImageMsg());
      bag.write("/camera/rgb/image_rect_color", h.stamp,
                cv_bridge::CvImage(h, sensor_msgs::image_encodings::RGB8, rgb8).toImageMsg());
      bag.write("/camera/mask", h.stamp, cv_bridge::CvImage(h, sensor_msgs::image_encodings::MONO8, mask).toImageMsg());
      bag.write("/camera/depth/camera_info", h.stamp, diffdope_ros::camera_info_from_camera(cam, h));
    }
    bag.close();
    std::fprintf(stderr, "diffdope_make_calibration_bag: %s: %d configurations, %.1f s\n", out.c_str(), configurations,
                 duration);
  } catch (const std::exception& e) {
    std::cerr << "diffdope_make_calibration_bag: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
