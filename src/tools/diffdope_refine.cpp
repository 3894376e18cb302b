// diffdope_refine: refines the pose of one object in one image, everything read from files.
//   diffdope_refine --rgb FILE --camera FILE --mesh FILE --init FILE --out DIR [--depth FILE] [--depth-scale M]
//                   [--mask FILE | --box X,Y,W,H] [--mesh-scale S] [--config FILE] [--quiet]
// Writes DIR/pose.json (refined pose and scores), DIR/overlay.png (initial pose red, refined green) and
// DIR/losses.png (loss per iteration of every run, the winner highlighted); prints the pose and the timing.
// Every unusable input is reported as one line `diffdope_refine: <file>: <problem>` with exit code 1; command-line
// mistakes print the usage with exit code 2.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "diffdope/input_files.hpp"
#include "diffdope/refiner.hpp"
#include "tool_io.hpp"

using namespace diffdope;
namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace diffdope::tools;

namespace {

const char* kUsage =
    "usage: diffdope_refine --rgb FILE --camera FILE --mesh FILE --init FILE --out DIR\n"
    "                       [--depth FILE] [--depth-scale M] [--mask FILE | --box X,Y,W,H] [--mesh-scale S]\n"
    "                       [--config FILE]\n"
    "                       [--device auto|cpu|cuda] [--quiet]\n"
    "       diffdope_refine --print-config [--config FILE] [--device D]\n"
    "\n"
    "  --rgb FILE        colour or grey image: PNG, JPEG, BMP, TIFF or PNM (8/16-bit or float in [0, 1])\n"
    "  --camera FILE     intrinsics of the (rectified) image, .json or .yaml/.yml: fx, fy, cx, cy[, width, height],\n"
    "                    or a 3x3 matrix as BOP's cam_K (9 values, row-major), K / k or camera_matrix: {data: [...]}\n"
    "  --mesh FILE       textured model (PLY incl. `comment TextureFile`, OBJ+MTL, glTF/GLB, ...)\n"
    "  --init FILE       initial pose (model to camera, metres), JSON: {\"R\": [9 row-major], \"t\": [3]},\n"
    "                    {\"quaternion\": [x, y, z, w], \"t\": [3]} or {\"matrix\": [16 row-major] or [[4] x 4]}\n"
    "  --out DIR         output folder (created): pose.json, overlay.png, losses.png\n"
    "  --depth FILE      depth image, one channel, 16-bit or float\n"
    "  --depth-scale M   metres per depth unit (default 0.001: millimetres)\n"
    "  --mask FILE       object mask, nonzero = object\n"
    "  --box X,Y,W,H     without a mask: a 2D detector's box around the object (pixels: left, top, width,\n"
    "                    height); it bounds where the object's pixels are sought, nothing more\n"
    "  --mesh-scale S    metres per model unit (default 1; 0.001 for millimetre models such as BOP's)\n"
    "  --config FILE     refiner options YAML (see config/default.yaml)\n"
    "  --device D        backend: cpu, cuda (error without a GPU) or auto (CUDA if present); overrides --config\n"
    "  --quiet           no progress bar and no summary on stdout\n"
    "  --print-config    print the options in effect (the defaults, with --config's and --device's changes) as\n"
    "                    YAML, every key with its range and meaning, and exit\n";

/// The initial pose must put the object in front of the camera and (at least partly) in the image.
void check_init_in_view(const std::string& path, const Pose& pose, const Mesh& mesh, const std::string& mesh_path,
                        const Camera& cam, double near_plane) {
  // The camera inside the model's box: nothing sensible to refine; usually a millimetre model read as metres.
  const Eigen::Vector3d eye = pose.inverse().t;  // camera centre in model coordinates
  if ((eye.array() > mesh.bbox_min().array()).all() && (eye.array() < mesh.bbox_max().array()).all()) {
    if (mesh.diameter() > 5.0)
      fail(mesh_path, "the model is " + fmt(mesh.diameter(), "%.1f") +
                          " m across and the camera is inside it at the initial pose (a millimetre model? use "
                          "--mesh-scale 0.001)");
    fail(path, "the initial pose puts the camera inside the object's bounding box");
  }
  const Eigen::Vector3d c = pose * mesh.center();
  const std::string hint = pose.t.norm() > 20 ? " (t is in metres: was it given in millimetres?)" : "";
  if (!(c.z() > 0))
    fail(path, "the initial pose puts the object behind the camera (centre z = " + std::to_string(c.z()) + " m)" +
                   hint);
  if (!(c.z() > near_plane))
    fail(path, "the initial pose puts the object's centre at z = " + fmt(c.z(), "%.3f") +
                   " m, not beyond render.near_plane (" + fmt(near_plane, "%.3f") + " m, from the options)" + hint);
  const Eigen::AlignedBox2d b = cam.project_bounds(mesh.bbox_corners(pose), 1e-6);
  if (b.isEmpty()) return;  // straddles the camera plane: let the refiner judge
  const double x0 = b.min().x(), y0 = b.min().y(), x1 = b.max().x(), y1 = b.max().y();
  if (x1 < -0.5 || y1 < -0.5 || x0 > cam.width - 0.5 || y0 > cam.height - 0.5)
    fail(path, "the initial pose puts the object outside the image (centre projects to (" +
                   std::to_string(cam.project(c).x()) + ", " + std::to_string(cam.project(c).y()) + "))" + hint);
}

cv::Mat make_overlay(const Observation& obs, Renderer& renderer, const Camera& cam, const Mesh& mesh,
                     const Pose& initial, const Pose& refined) {
  cv::Mat bgr = to_bgr8(obs.rgb);
  const auto imgs = renderer.render(cam, mesh, {initial, refined});
  const int thickness = std::max(1, int(std::lround(std::max(cam.width, cam.height) / 500.0)));
  draw_render(bgr, imgs[0], cv::Scalar(0, 0, 255), thickness);
  draw_render(bgr, imgs[1], cv::Scalar(0, 255, 0), thickness);
  const double s = std::clamp(cam.width / 900.0, 0.35, 1.2);
  const int line = int(std::lround(30 * s)) + 4;
  put_label(bgr, "initial", cv::Point(8, line), cv::Scalar(0, 0, 255), s);
  put_label(bgr, "refined", cv::Point(8, 2 * line), cv::Scalar(0, 255, 0), s);
  return bgr;
}

/// "Nice" tick step (1, 2 or 5 times a power of ten) for about `n` ticks over `range`.
double nice_step(double range, int n) {
  const double raw = range / std::max(1, n);
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}

std::string tick_label(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3g", v);
  return b;
}

cv::Mat make_loss_plot(const RefineResult& r) {
  const int W = 800, H = 500, L = 80, R = W - 25, T = 50, B = H - 55;
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  size_t n = 0;
  for (const auto& h : r.run_histories) {
    n = std::max(n, h.size());
    for (double v : h)
      if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
  for (double v : r.history)
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  n = std::max(n, r.history.size());
  const cv::Scalar black(0, 0, 0), grid(232, 232, 232), light(195, 195, 195), strong(200, 90, 0);
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  std::string title = "Loss per iteration: " + std::to_string(r.run_histories.size()) + " runs (grey), winner #" +
                      std::to_string(r.winner) + " (blue)";
  cv::putText(img, title, cv::Point(L, 30), font, 0.6, black, 1, cv::LINE_AA);
  if (!std::isfinite(lo)) {
    cv::putText(img, "no finite loss values", cv::Point(L + 20, (T + B) / 2), font, 0.6, black, 1, cv::LINE_AA);
    return img;
  }
  const bool log_scale = lo > 0 && hi > 10 * lo;
  if (!log_scale) {
    if (hi - lo < 1e-12 * std::max(1.0, std::abs(hi))) {  // flat: give it some room
      const double pad = std::max(1e-3, 0.1 * std::abs(hi));
      lo -= pad, hi += pad;
    } else {
      const double pad = 0.05 * (hi - lo);
      lo = lo >= 0 ? std::max(0.0, lo - pad) : lo - pad;
      hi += pad;
    }
  }
  auto f = [&](double v) { return log_scale ? std::log10(v) : v; };
  const double flo = log_scale ? std::log10(lo) - 0.05 : f(lo), fhi = log_scale ? std::log10(hi) + 0.05 : f(hi);
  const double xmax = std::max<double>(1, double(n) - 1);
  auto px = [&](double i) { return L + (R - L) * i / xmax; };
  auto py = [&](double v) { return B - (B - T) * (f(v) - flo) / (fhi - flo); };

  // Y ticks and grid.
  std::vector<double> yt;
  if (log_scale) {
    const int e0 = int(std::floor(flo)), e1 = int(std::ceil(fhi));
    const bool dense = e1 - e0 <= 3;
    for (int e = e0; e <= e1; ++e)
      for (double m : {1.0, 2.0, 5.0}) {
        if (!dense && m != 1.0) continue;
        const double v = m * std::pow(10.0, e);
        if (std::log10(v) >= flo && std::log10(v) <= fhi) yt.push_back(v);
      }
  } else {
    const double step = nice_step(hi - lo, 5);
    for (double v = std::ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) yt.push_back(v);
  }
  for (double v : yt) {
    const int y = int(std::lround(py(v)));
    cv::line(img, cv::Point(L, y), cv::Point(R, y), grid, 1);
    cv::line(img, cv::Point(L - 5, y), cv::Point(L, y), black, 1);
    const std::string s = tick_label(std::abs(v) < 1e-12 ? 0.0 : v);
    int base = 0;
    const cv::Size ts = cv::getTextSize(s, font, 0.45, 1, &base);
    cv::putText(img, s, cv::Point(L - 8 - ts.width, y + ts.height / 2), font, 0.45, black, 1, cv::LINE_AA);
  }
  // X ticks and grid.
  const double xs = std::max(1.0, nice_step(xmax, 8));
  for (double i = 0; i <= xmax + 1e-9; i += xs) {
    const int x = int(std::lround(px(i)));
    cv::line(img, cv::Point(x, T), cv::Point(x, B), grid, 1);
    cv::line(img, cv::Point(x, B), cv::Point(x, B + 5), black, 1);
    const std::string s = tick_label(i);
    int base = 0;
    const cv::Size ts = cv::getTextSize(s, font, 0.45, 1, &base);
    cv::putText(img, s, cv::Point(x - ts.width / 2, B + 20), font, 0.45, black, 1, cv::LINE_AA);
  }
  // Curves: every run in grey, then the winner on top.
  auto curve = [&](const std::vector<double>& h, const cv::Scalar& c, int thick) {
    for (size_t i = 1; i < h.size(); ++i) {
      if (!std::isfinite(h[i - 1]) || !std::isfinite(h[i])) continue;
      if (log_scale && (h[i - 1] <= 0 || h[i] <= 0)) continue;
      const cv::Point2d a(px(double(i - 1)), py(h[i - 1])), b(px(double(i)), py(h[i]));
      cv::line(img, cv::Point(int(std::lround(a.x * 16)), int(std::lround(a.y * 16))),
               cv::Point(int(std::lround(b.x * 16)), int(std::lround(b.y * 16))), c, thick, cv::LINE_AA, 4);
    }
  };
  for (size_t k = 0; k < r.run_histories.size(); ++k)
    if (int(k) != r.winner) curve(r.run_histories[k], light, 1);
  curve(r.history, strong, 2);
  // Axes and labels.
  cv::rectangle(img, cv::Point(L, T), cv::Point(R, B), black, 1);
  cv::putText(img, "iteration", cv::Point((L + R) / 2 - 35, H - 15), font, 0.5, black, 1, cv::LINE_AA);
  cv::putText(img, log_scale ? "loss (log)" : "loss", cv::Point(8, T - 8), font, 0.45, black, 1, cv::LINE_AA);
  const std::string summary = "initial " + tick_label(r.initial_loss) + " -> final " + tick_label(r.loss.total);
  int base = 0;
  const cv::Size ts = cv::getTextSize(summary, font, 0.5, 1, &base);
  cv::putText(img, summary, cv::Point(R - ts.width - 8, T + ts.height + 8), font, 0.5, strong, 1, cv::LINE_AA);
  return img;
}

nlohmann::ordered_json pose_json(const RefineResult& r) {
  const Pose& p = r.pose;
  std::vector<double> m16;
  const Eigen::Matrix4d M = p.matrix();
  for (int i = 0; i < 16; ++i) m16.push_back(M(i / 4, i % 4));
  const double lr = r.winner >= 0 && r.winner < int(r.learning_rates.size()) ? r.learning_rates[r.winner] : 0.0;
  return nlohmann::ordered_json{{"R", p.rotation_rowmajor()},
              {"t", {p.t.x(), p.t.y(), p.t.z()}},
              {"quaternion_xyzw", p.quaternion_xyzw()},
              {"matrix", m16},
              {"loss", r.loss.total},
              {"loss_terms", {{"rgb", r.loss.rgb}, {"depth", r.loss.depth}, {"mask", r.loss.mask}}},
              {"terms", used_terms(r.loss_used)},
              {"initial_loss", r.initial_loss},
              {"iterations", r.iterations},
              {"time_ms", r.time_ms},
              {"mask_iou", r.mask_iou},
              {"depth_inliers", r.depth_inliers},
              {"depth_noise_mm_at_1m", r.depth_noise < 0 ? -1.0 : 1e3 * r.depth_noise},
              {"converged", r.converged},
              {"plausible", r.plausible},
              {"judged", r.judged},
              {"retried", r.retried},
              {"given_mask_replaced", r.given_mask_replaced},
              {"given_mask_offset", r.given_mask_offset},
              {"given_mask_shift", r.given_mask_shift},
              {"given_mask_shifted_offset", r.given_mask_shifted_offset},
              {"confidence", r.confidence},
              {"print_significance", std::isfinite(r.print.significance()) ? nlohmann::json(r.print.significance())
                                                                           : nlohmann::json(nullptr)},
              {"rival_print_significance",
               std::isfinite(r.rival_print) ? nlohmann::json(r.rival_print) : nlohmann::json(nullptr)},
              {"winner", r.winner},
              {"learning_rate", lr}};
}

struct Args {
  std::string rgb, depth, mask, camera, mesh, init, out, config, device, box;
  double depth_scale = 0.001, mesh_scale = 1.0;
  bool quiet = false;
  bool print_config = false;
};

int usage_error(const std::string& what) {
  if (!what.empty()) std::cerr << "diffdope_refine: " << what << "\n";
  std::cerr << kUsage;
  return 2;
}

/// Parses argv into `a`; returns -1 to go on, else the exit code.
int parse_args(int argc, char** argv, Args& a) {
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    if (k == "-h" || k == "--help") {
      std::cout << kUsage;
      return 0;
    }
    if (k == "--quiet" || k == "-q") {
      a.quiet = true;
      continue;
    }
    if (k == "--print-config") {
      a.print_config = true;
      continue;
    }
    std::string* target = nullptr;
    double* num = nullptr;
    if (k == "--rgb") target = &a.rgb;
    else if (k == "--depth") target = &a.depth;
    else if (k == "--mask") target = &a.mask;
    else if (k == "--camera") target = &a.camera;
    else if (k == "--mesh") target = &a.mesh;
    else if (k == "--init") target = &a.init;
    else if (k == "--out") target = &a.out;
    else if (k == "--config") target = &a.config;
    else if (k == "--device") target = &a.device;
    else if (k == "--box") target = &a.box;
    else if (k == "--depth-scale") num = &a.depth_scale;
    else if (k == "--mesh-scale") num = &a.mesh_scale;
    else return usage_error("unknown option " + k);
    if (i + 1 >= argc) return usage_error(k + " needs a value");
    const std::string v = argv[++i];
    if (target) {
      if (v.empty()) return usage_error(k + " needs a non-empty value");
      *target = v;
    } else {
      size_t used = 0;
      double d = std::numeric_limits<double>::quiet_NaN();
      try {
        d = std::stod(v, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != v.size() || !std::isfinite(d) || d <= 0)
        return usage_error(k + " needs a positive number, got '" + v + "'");
      *num = d;
    }
  }
  if (a.print_config) return -1;
  std::string missing;
  for (const auto& [flag, val] : {std::pair<const char*, const std::string*>{"--rgb", &a.rgb},
                                  {"--camera", &a.camera}, {"--mesh", &a.mesh}, {"--init", &a.init},
                                  {"--out", &a.out}})
    if (val->empty()) missing += std::string(missing.empty() ? "" : ", ") + flag;
  if (!missing.empty()) return usage_error("missing " + missing);
  if (!a.box.empty() && !a.mask.empty()) return usage_error("--box is for refining without a mask: give --mask or --box");
  if (!a.box.empty()) {
    std::stringstream ss(a.box);
    std::vector<long long> v;
    for (std::string part; std::getline(ss, part, ',');) {
      try {
        v.push_back(parse_integer_arg("--box", part, -Camera::kMaxSize, Camera::kMaxSize));
      } catch (const std::invalid_argument& e) {
        return usage_error(e.what());
      }
    }
    if (v.size() != 4 || v[2] <= 0 || v[3] <= 0)
      return usage_error("--box needs X,Y,W,H (pixels; width and height positive), got '" + a.box + "'");
  }
  return -1;
}

int run(const Args& a) {
  // Options first: a typo in the config should not wait for the mesh to load.
  RefinerOptions options;
  if (!a.config.empty()) {
    check_file(a.config);
    options = about(a.config, [&] { return RefinerOptions::from_yaml_file(a.config); });
    about(a.config, [&] { options.validate(); });
  }
  if (!a.device.empty()) {
    options.device = a.device;
    about("--device", [&] { options.validate(); });
  }
  if (a.print_config) {
    std::cout << options.to_yaml();
    return 0;
  }

  Observation obs;
  const cv::Mat rgb = read_image(a.rgb, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "rgb");
  obs.rgb = about(a.rgb, [&] { return to_rgb_float(rgb, /*bgr=*/true, a.rgb); });
  const int W = obs.rgb.cols, H = obs.rgb.rows;
  const Camera cam = read_camera_file(a.camera, W, H);

  if (!a.depth.empty()) {
    const cv::Mat d = read_image(a.depth, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "depth");
    if (d.channels() != 1)
      fail(a.depth, "depth must have one channel, found " + std::to_string(d.channels()));
    if (d.cols != W || d.rows != H)
      fail(a.depth, "depth image is " + size_str(d.cols, d.rows) + " but the rgb image is " + size_str(W, H));
    obs.depth = about(a.depth, [&] { return to_depth_metres(d, a.depth_scale, a.depth); });
    if (cv::countNonZero(obs.depth > 0) == 0) fail(a.depth, "the depth image has no valid reading");
  }
  if (!a.mask.empty()) {
    const cv::Mat m = read_image(a.mask, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR, "mask");
    if (m.cols != W || m.rows != H)
      fail(a.mask, "mask is " + size_str(m.cols, m.rows) + " but the rgb image is " + size_str(W, H));
    obs.mask = about(a.mask, [&] { return to_mask_float(m, a.mask); });
    if (cv::countNonZero(obs.mask > 0) == 0) fail(a.mask, "the mask is empty (no nonzero pixel)");
  }
  if (!a.box.empty()) {
    int x = 0, y = 0, w = 0, h = 0;
    std::sscanf(a.box.c_str(), "%d,%d,%d,%d", &x, &y, &w, &h);  // (checked by parse_args)
    obs.box = cv::Rect(x, y, w, h);
    if ((obs.box & cv::Rect(0, 0, W, H)).empty())
      fail("--box", "the box " + a.box + " does not overlap the " + size_str(W, H) + " image");
  }

  check_file(a.mesh);
  MeshLoadOptions mopt;
  mopt.scale = a.mesh_scale;
  const Mesh mesh = about(a.mesh, [&] {
    QuietStderr quiet;
    return Mesh::load(a.mesh, mopt);
  });

  const Pose initial = read_pose_file(a.init);
  check_init_in_view(a.init, initial, mesh, a.mesh, cam, options.render.near_plane);

  std::error_code ec;
  fs::create_directories(a.out, ec);
  if (ec || !fs::is_directory(a.out)) fail(a.out, "cannot create the output folder" + (ec ? " (" + ec.message() + ")" : ""));

  Refiner refiner = about(a.config.empty() ? "options" : a.config, [&] { return Refiner(options); });
  const bool progress = !a.quiet && isatty(2);
  if (progress) {
    refiner.on_iteration = [](int k, int total, double best) {
      const int width = 30, filled = total > 0 ? width * k / total : width;
      std::fprintf(stderr, "\r[%s%s] %4d/%d  best loss %.5f ", std::string(filled, '#').c_str(),
                   std::string(width - filled, ' ').c_str(), k, total, best);
      std::fflush(stderr);
    };
  }
  const RefineResult r = refiner.refine(cam, obs, mesh, initial);
  if (!r.error.empty()) {
    if (progress) std::fprintf(stderr, "\n");
    const std::string& m = r.error;
    fail(m.find("initial pose") != std::string::npos ? a.init
         : m.find("mask") != std::string::npos       ? (a.mask.empty() ? a.rgb : a.mask)
                                                     : a.rgb,
         m);
  }
  if (progress) std::fprintf(stderr, "\n");

  const fs::path out(a.out);
  const std::string pose_path = (out / "pose.json").string();
  {
    std::ofstream f(pose_path);
    if (!f) fail(pose_path, "cannot write");
    f << pose_json(r).dump(2) << "\n";
    if (!f) fail(pose_path, "cannot write");
  }
  RenderOptions ropt = options.render;
  auto renderer = make_cpu_renderer(ropt);
  write_image((out / "overlay.png").string(), make_overlay(obs, *renderer, cam, mesh, initial, r.pose));
  write_image((out / "losses.png").string(), make_loss_plot(r));

  if (!a.quiet) {
    const Pose& p = r.pose;
    const auto q = p.quaternion_xyzw();
    std::printf("refined pose (model -> camera, metres):\n");
    for (int i = 0; i < 3; ++i)
      std::printf("  %s [%10.6f %10.6f %10.6f]\n", i == 0 ? "R =" : "   ", p.R(i, 0), p.R(i, 1), p.R(i, 2));
    std::printf("  t = [%10.6f %10.6f %10.6f] m\n", p.t.x(), p.t.y(), p.t.z());
    std::printf("  quaternion (x y z w) = [%.6f %.6f %.6f %.6f]\n", q[0], q[1], q[2], q[3]);
    std::printf("moved %.2f mm, %.2f deg from the initial pose\n", 1e3 * (p.t - initial.t).norm(),
                rotation_angle(p.R, initial.R) * 180 / M_PI);
    std::printf("loss %.5f -> %.5f (rgb %.4f, depth %.4f, mask %.4f)\n", r.initial_loss, r.loss.total, r.loss.rgb,
                r.loss.depth, r.loss.mask);
    const double z = r.print.significance();
    std::printf("mask IoU %s, depth inliers %s, print %s, converged %s, plausible %s (confidence %.2f)\n",
                r.mask_iou < 0 ? "n/a" : fmt(r.mask_iou, "%.3f").c_str(),
                r.depth_inliers < 0 ? "n/a" : fmt(r.depth_inliers, "%.3f").c_str(),
                std::isfinite(z) ? fmt(z, "%.1f sigma").c_str() : "n/a", r.converged ? "yes" : "no",
                r.plausible ? "yes" : r.judged ? "NO" : "NO (nothing could judge the pose)", r.confidence);
    if (std::isfinite(r.rival_print))
      std::printf("print at the best shape-equivalent turn (a rival face) %.1f sigma%s\n", r.rival_print,
                  r.rival_print >= z ? ": as well as at the pose, whose face is not determined" : "");
    std::printf("time %.0f ms (B=%d, %d iterations, image scale %.2f, winner #%d, lr %.5f)\n", r.time_ms,
                options.batch_size, r.iterations, options.image_scale, r.winner,
                r.winner >= 0 ? r.learning_rates[r.winner] : 0.0);
    std::printf("wrote %s, overlay.png, losses.png\n", pose_path.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args args;
  const int rc = parse_args(argc, argv, args);
  if (rc >= 0) return rc;
  // OpenCV's own warnings (e.g. from image decoders) would add lines to our one-line error reports.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  try {
    return run(args);
  } catch (const InputError& e) {
    std::cerr << "diffdope_refine: " << e.file << ": " << one_line(e.what()) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "diffdope_refine: " << one_line(e.what()) << "\n";
  } catch (...) {
    std::cerr << "diffdope_refine: unknown error\n";
  }
  return 1;
}
