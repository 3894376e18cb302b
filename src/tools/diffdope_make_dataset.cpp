// diffdope_make_dataset: writes a small BOP-format dataset of generated scenes (the project's own test data).
//   diffdope_make_dataset --out ROOT [--scenes N] [--seed S] [--width W] [--height H] [--split NAME]
//                         [--colour-offset DX,DY]
// Objects: 1 printed box, 2 can (continuous symmetry, scored with ADD-S), 3 L-block (asymmetric). Each scene has
// a target and one or two distractors that partly occlude it, over a textured background, with colour noise,
// depth noise growing with z^2, and depth holes (blobs and silhouette borders). Files as BOP: millimetres,
// depth_scale 1.0 (mm per unit), rgb/depth/mask/mask_visib PNGs, scene_camera/scene_gt/scene_gt_info JSON.
// --colour-offset moves the colour image off the depth image and the masks by (DX, DY) pixels, as a real RGB-D
// camera's registration leaves it (SyntheticNoise::colour_offset_x_px).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <limits>
#include <random>

#include "diffdope/input_files.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

int usage(int rc) {
  std::cerr << "usage: diffdope_make_dataset --out ROOT [--scenes N] [--seed S] [--width W] [--height H] [--split NAME]\n"
               "                            [--colour-offset DX,DY]  (pixels: the colour image off depth and masks)\n";
  return rc;
}

std::string id6(int v) {
  char b[16];
  std::snprintf(b, sizeof b, "%06d", v);
  return b;
}

void write_png(const std::string& path, const cv::Mat& m) {
  if (!cv::imwrite(path, m)) throw std::runtime_error(path + ": cannot write");
}

json pose_json(const Pose& p, int obj_id) {
  const auto r = p.rotation_rowmajor();
  return {{"cam_R_m2c", std::vector<double>(r.begin(), r.end())},
          {"cam_t_m2c", {1e3 * p.t.x(), 1e3 * p.t.y(), 1e3 * p.t.z()}},
          {"obj_id", obj_id}};
}

}  // namespace

int main(int argc, char** argv) {
  std::string out, split = "test";
  int scenes = 6, width = 640, height = 480;
  uint64_t seed = 1;
  double colour_dx = 0, colour_dy = 0;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "-h" || a == "--help") return usage(0);
      if (i + 1 >= argc) return usage(2);
      const std::string v = argv[++i];
      if (a == "--out") out = v;
      else if (a == "--scenes") scenes = int(parse_integer_arg(a, v, 1, 100000));
      else if (a == "--seed") seed = uint64_t(parse_integer_arg(a, v, 0, std::numeric_limits<long long>::max()));
      else if (a == "--width") width = int(parse_integer_arg(a, v, 16, 16384));
      else if (a == "--height") height = int(parse_integer_arg(a, v, 16, 16384));
      else if (a == "--split") split = v;
      else if (a == "--colour-offset") {
        const size_t comma = v.find(',');
        if (comma == std::string::npos) throw std::invalid_argument("--colour-offset: expected DX,DY, got '" + v + "'");
        const double m = SyntheticNoise::kMaxColourOffset;
        colour_dx = parse_number_arg(a + " (DX)", v.substr(0, comma), -m, m);
        colour_dy = parse_number_arg(a + " (DY)", v.substr(comma + 1), -m, m);
      } else return usage(2);
    }
  } catch (const std::invalid_argument& e) {
    std::cerr << "diffdope_make_dataset: " << e.what() << "\n";
    return 2;
  }
  if (out.empty() || scenes < 1 || width < 16 || height < 16) return usage(2);
  try {
    struct Model {
      int id;
      Mesh mesh;
      bool symmetric;
    };
    std::vector<Model> models;
    models.push_back({1, make_box(Eigen::Vector3d(0.10, 0.05, 0.14), make_label_texture(512, 11)), false});
    models.push_back({2, make_cylinder(0.035, 0.11, 64, make_label_texture(512, 12)), true});
    models.push_back({3, make_l_block(0.12, make_label_texture(512, 13)), false});
    fs::create_directories(out + "/models");
    json info;
    for (const Model& m : models) {
      save_ply(m.mesh, out + "/models/obj_" + id6(m.id) + ".ply", 1000.0);
      const Eigen::Vector3d lo = 1e3 * m.mesh.bbox_min(), size = 1e3 * (m.mesh.bbox_max() - m.mesh.bbox_min());
      json e = {{"diameter", 1e3 * m.mesh.diameter()}, {"min_x", lo.x()}, {"min_y", lo.y()}, {"min_z", lo.z()},
                {"size_x", size.x()}, {"size_y", size.y()}, {"size_z", size.z()}};
      if (m.symmetric) e["symmetries_continuous"] = json::array({{{"axis", {0, 0, 1}}, {"offset", {0, 0, 0}}}});
      info[std::to_string(m.id)] = e;
    }
    std::ofstream(out + "/models/models_info.json") << info.dump(1) << "\n";

    const double f = 1.25 * width;  // ~44 degree horizontal field of view
    const Camera cam(f, f, width / 2.0 - 0.5, height / 2.0 - 0.5, width, height);
    auto renderer = make_cpu_renderer();
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    auto random_pose = [&](double x, double y, double z) {
      Vector6d d;
      d << 0, 0, 0, M_PI * U(rng), M_PI * U(rng), M_PI * U(rng);
      return Pose(se3_exp(d).R, Eigen::Vector3d(x, y, z));
    };
    for (int s = 1; s <= scenes; ++s) {
      const std::string dir = out + "/" + split + "/" + id6(s);
      for (const char* sub : {"rgb", "depth", "mask", "mask_visib"}) fs::create_directories(dir + "/" + sub);
      const int target = (s - 1) % int(models.size());
      std::vector<SceneObject> objs;
      std::vector<int> ids;
      SyntheticScene scene;
      for (int attempt = 0; attempt < 50; ++attempt) {  // redraw until the target stays mostly visible
        objs.clear();
        ids.clear();
        const double z = 0.55 + 0.1 * U(rng);
        objs.push_back({&models[target].mesh, random_pose(0.04 * U(rng), 0.03 * U(rng), z)});
        ids.push_back(models[target].id);
        const int n_distractors = 1 + int(rng() % 2);
        for (int k = 0; k < n_distractors; ++k) {
          const int m = (target + 1 + k) % int(models.size());
          const double side = (k == 0 ? 1.0 : -1.0);
          objs.push_back({&models[m].mesh, random_pose(side * (0.07 + 0.03 * U(rng)), 0.04 * U(rng), z - 0.12 + 0.05 * U(rng))});
          ids.push_back(models[m].id);
        }
        SyntheticNoise noise;
        noise.brightness = 0.85 + 0.15 * U(rng);
        noise.colour_offset_x_px = colour_dx, noise.colour_offset_y_px = colour_dy;
        scene = synthesize_scene(*renderer, cam, objs, noise, uint32_t(rng()));
        if (scene.visible_fraction[0] >= 0.6 && scene.visible_fraction[0] < 0.98) break;
      }
      cv::Mat bgr;
      cv::cvtColor(scene.rgb, bgr, cv::COLOR_RGB2BGR);
      bgr.convertTo(bgr, CV_8UC3, 255.0);
      write_png(dir + "/rgb/000000.png", bgr);
      cv::Mat depth_mm;
      scene.depth.convertTo(depth_mm, CV_16U, 1000.0);
      write_png(dir + "/depth/000000.png", depth_mm);
      json gt = json::array(), gt_info = json::array();
      for (size_t i = 0; i < objs.size(); ++i) {
        gt.push_back(pose_json(objs[i].pose, ids[i]));
        gt_info.push_back({{"visib_fract", scene.visible_fraction[i]}});
        cv::Mat m8;
        scene.visible_masks[i].convertTo(m8, CV_8U, 255.0);
        write_png(dir + "/mask_visib/000000_" + id6(int(i)) + ".png", m8);
        scene.full_masks[i].convertTo(m8, CV_8U, 255.0);
        write_png(dir + "/mask/000000_" + id6(int(i)) + ".png", m8);
      }
      std::ofstream(dir + "/scene_gt.json") << json{{"0", gt}}.dump(1) << "\n";
      std::ofstream(dir + "/scene_gt_info.json") << json{{"0", gt_info}}.dump(1) << "\n";
      const json K = {cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0};
      std::ofstream(dir + "/scene_camera.json") << json{{"0", {{"cam_K", K}, {"depth_scale", 1.0}}}}.dump(1) << "\n";
      std::fprintf(stderr, "scene %d: target obj %d, visible %.2f, %zu objects\n", s, ids[0], scene.visible_fraction[0],
                   objs.size());
    }
  } catch (const std::exception& e) {
    std::cerr << "diffdope_make_dataset: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
