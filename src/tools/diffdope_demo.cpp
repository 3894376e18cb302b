// diffdope_demo: refines generated scenes offline and prints initial vs refined errors.
//   diffdope_demo [--level easy|medium|hard] [--scenes N] [--config FILE] [--out DIR] [--seed S]
// Each scene: a procedural textured object (printed box, can, L-block) rendered over a textured background
// with colour noise, depth noise and holes; the initial pose is the truth perturbed by the paper's rule.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "diffdope/input_files.hpp"
#include "diffdope/metrics.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;

namespace {

void usage() {
  std::cerr << "usage: diffdope_demo [--level easy|medium|hard|all] [--scenes N] [--config FILE] [--out DIR] [--seed S]\n";
}

void draw_outline(cv::Mat& bgr8, const cv::Mat& coverage, const cv::Scalar& colour) {
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(cv::Mat(coverage >= 0.5f), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  cv::drawContours(bgr8, contours, -1, colour, 1, cv::LINE_AA);
}

/// A whole number in [lo, hi] for `flag`; a usage error (exit 2) naming the flag otherwise.
long long integer_arg(const std::string& flag, const std::string& text, long long lo, long long hi) {
  try {
    return parse_integer_arg(flag, text, lo, hi);
  } catch (const std::invalid_argument& e) {
    std::cerr << "diffdope_demo: " << e.what() << "\n";
    std::exit(2);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string level = "all", config, out_dir;
  int scenes = 3;
  uint64_t seed = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::cerr << "diffdope_demo: " << a << " needs a value\n";
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--level") level = value();
    else if (a == "--scenes") scenes = int(integer_arg(a, value(), 1, 1000));
    else if (a == "--config") config = value();
    else if (a == "--out") out_dir = value();
    else if (a == "--seed") seed = uint64_t(integer_arg(a, value(), 0, std::numeric_limits<long long>::max()));
    else if (a == "-h" || a == "--help") return usage(), 0;
    else return usage(), 2;
  }
  std::vector<std::pair<std::string, std::pair<double, double>>> levels;
  if (level == "easy" || level == "all") levels.push_back({"easy", {1.0, 0.001}});
  if (level == "medium" || level == "all") levels.push_back({"medium", {10.0, 0.01}});
  if (level == "hard" || level == "all") levels.push_back({"hard", {40.0, 0.02}});
  if (levels.empty()) return usage(), 2;

  RefinerOptions options;
  try {
    if (!config.empty()) options = RefinerOptions::from_yaml_file(config);
  } catch (const std::exception& e) {
    std::cerr << "diffdope_demo: " << e.what() << "\n";
    return 1;
  }
  if (!out_dir.empty()) std::filesystem::create_directories(out_dir);

  const Camera cam(600, 600, 319.5, 239.5, 640, 480);
  struct Object {
    std::string name;
    Mesh mesh;
  };
  std::vector<Object> objects = {
      {"box", make_box(Eigen::Vector3d(0.16, 0.06, 0.21), make_label_texture(256, 3))},
      {"can", make_cylinder(0.035, 0.11, 48, make_label_texture(256, 4))},
      {"l_block", make_l_block(0.12, make_label_texture(256, 5))},
  };
  auto render = make_cpu_renderer();
  Refiner refiner(options);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);

  std::printf("%-7s %-8s %5s | %9s %9s %9s | %9s %9s %9s | %7s %5s %6s\n", "level", "object", "scene", "init mm",
              "init deg", "init ADD", "ref mm", "ref deg", "ref ADD", "ms", "iou", "plaus");
  std::vector<double> t_ms;
  for (const auto& [lname, lv] : levels) {
    std::vector<double> add_init, add_ref;
    for (const Object& obj : objects) {
      const auto pts = metric_points(obj.mesh);
      for (int s = 0; s < scenes; ++s) {
        Vector6d d;
        d << 0.1 * U(rng), 0.08 * U(rng), 0.0, M_PI * U(rng), M_PI * U(rng), M_PI * U(rng);
        const Pose truth(se3_exp(d).R, Eigen::Vector3d(0.08 * U(rng), 0.06 * U(rng), 0.6 + 0.15 * U(rng)));
        SyntheticNoise noise;
        noise.brightness = 0.85 + 0.15 * U(rng);
        const Observation obs = synthesize_observation(*render, cam, obj.mesh, truth, noise, uint32_t(rng()));
        const Pose init = perturb_pose(truth, obj.mesh.center(), lv.first * M_PI / 180, lv.second, rng);
        const RefineResult r = refiner.refine(cam, obs, obj.mesh, init);
        if (!r.error.empty()) {
          std::cerr << "diffdope_demo: " << r.error << "\n";
          return 1;
        }
        const double ai = add_error(pts, init, truth), ar = add_error(pts, r.pose, truth);
        add_init.push_back(ai);
        add_ref.push_back(ar);
        t_ms.push_back(r.time_ms);
        std::printf("%-7s %-8s %5d | %9.2f %9.2f %9.2f | %9.2f %9.2f %9.2f | %7.0f %5.2f %6s\n", lname.c_str(),
                    obj.name.c_str(), s, 1e3 * (init.t - truth.t).norm(), rotation_angle(init.R, truth.R) * 180 / M_PI,
                    1e3 * ai, 1e3 * (r.pose.t - truth.t).norm(), rotation_angle(r.pose.R, truth.R) * 180 / M_PI,
                    1e3 * ar, r.time_ms, r.mask_iou, r.plausible ? "yes" : "NO");
        if (!out_dir.empty()) {
          cv::Mat bgr;
          cv::cvtColor(obs.rgb, bgr, cv::COLOR_RGB2BGR);
          bgr.convertTo(bgr, CV_8UC3, 255.0);
          const auto imgs = render->render(cam, obj.mesh, {init, r.pose});
          draw_outline(bgr, imgs[0].coverage, cv::Scalar(0, 0, 255));
          draw_outline(bgr, imgs[1].coverage, cv::Scalar(0, 255, 0));
          cv::imwrite(out_dir + "/" + lname + "_" + obj.name + "_" + std::to_string(s) + ".png", bgr);
        }
      }
    }
    std::printf("%-7s ADD AUC (0-50 mm): initial %.2f -> refined %.2f\n", lname.c_str(), accuracy_auc(add_init, 0.05),
                accuracy_auc(add_ref, 0.05));
  }
  std::sort(t_ms.begin(), t_ms.end());
  std::printf("median time per object: %.0f ms (B=%d, %d iterations, image scale %.2f)\n", t_ms[t_ms.size() / 2],
              options.batch_size, options.iterations, options.image_scale);
  if (!out_dir.empty()) std::printf("overlays (red: initial, green: refined) in %s\n", out_dir.c_str());
  return 0;
}
