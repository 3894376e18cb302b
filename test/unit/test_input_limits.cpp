// Hostile but legal-looking inputs: every option finite and inside its range, YAML errors that name
// the key, intrinsics and poses that leave nothing to refine, meshes that draw nothing. Each must be refused with
// a message that says what is wrong, never run with NaN losses or for an unbounded time.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "diffdope/input_files.hpp"
#include "diffdope/object_track.hpp"
#include "diffdope/procedural.hpp"
#include "diffdope/refiner.hpp"
#include "diffdope/synthetic.hpp"

using namespace diffdope;

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

/// The message of the std::invalid_argument that f throws ("" when it does not throw one).
std::string invalid_argument_message(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

struct NumericField {
  const char* name;  // as the message names it
  std::function<void(RefinerOptions&, double)> set;
  double out_of_range;  // a finite value outside the field's range
};

std::vector<NumericField> numeric_fields() {
  return {
      {"batch_size", [](RefinerOptions& o, double v) { o.batch_size = int(v); }, 1e6},
      {"iterations", [](RefinerOptions& o, double v) { o.iterations = int(v); }, 1e9},
      {"lr_low", [](RefinerOptions& o, double v) { o.lr_low = v; }, -1},
      {"lr_high", [](RefinerOptions& o, double v) { o.lr_high = v; }, 1e6},
      {"lr_decay", [](RefinerOptions& o, double v) { o.lr_decay = v; }, 2},
      {"image_scale", [](RefinerOptions& o, double v) { o.image_scale = v; }, 1e-9},
      {"coarse_scale", [](RefinerOptions& o, double v) { o.coarse_scale = v; }, 1e-9},
      {"early_stop_patience", [](RefinerOptions& o, double v) { o.early_stop_patience = int(v); }, -3},
      {"early_stop_tolerance", [](RefinerOptions& o, double v) { o.early_stop_tolerance = v; }, 5},
      {"no_mask_window", [](RefinerOptions& o, double v) { o.no_mask_window = v; }, 1e9},
      {"inlier_threshold", [](RefinerOptions& o, double v) { o.inlier_threshold = v; }, 0},
      {"min_mask_iou", [](RefinerOptions& o, double v) { o.min_mask_iou = v; }, 1.5},
      {"min_depth_inliers", [](RefinerOptions& o, double v) { o.min_depth_inliers = v; }, -0.1},
      {"loss.weight_rgb", [](RefinerOptions& o, double v) { o.loss.weight_rgb = v; }, -1},
      {"loss.weight_depth", [](RefinerOptions& o, double v) { o.loss.weight_depth = v; }, 1e9},
      {"loss.weight_mask", [](RefinerOptions& o, double v) { o.loss.weight_mask = v; }, -1},
      {"loss.weight_edges", [](RefinerOptions& o, double v) { o.loss.weight_edges = v; }, 1e9},
      {"loss.edge_scale", [](RefinerOptions& o, double v) { o.loss.edge_scale = v; }, 1e-300},
      {"loss.rgb_miss", [](RefinerOptions& o, double v) { o.loss.rgb_miss = v; }, -1},
      {"loss.depth_truncation", [](RefinerOptions& o, double v) { o.loss.depth_truncation = v; }, 0},
      {"loss.occlusion_margin", [](RefinerOptions& o, double v) { o.loss.occlusion_margin = v; }, -0.1},
      {"loss.depth_noise_power", [](RefinerOptions& o, double v) { o.loss.depth_noise_power = int(v); }, 3},
      {"render.near_plane", [](RefinerOptions& o, double v) { o.render.near_plane = v; }, 0},
      {"render.roi_margin", [](RefinerOptions& o, double v) { o.render.roi_margin = int(v); }, 1e6},
      {"render.lod_pixel_error", [](RefinerOptions& o, double v) { o.render.lod_pixel_error = v; }, 1e3},
      {"render.threads", [](RefinerOptions& o, double v) { o.render.threads = int(v); }, 100000},
  };
}

}  // namespace

TEST(InputLimits, EveryNumericOptionMustBeFiniteAndInRange) {
  EXPECT_NO_THROW(RefinerOptions().validate());
  for (const NumericField& f : numeric_fields()) {
    std::vector<double> bad = {f.out_of_range};
    // (integer fields cannot hold NaN or infinity; the YAML reader refuses them, tested below)
    if (std::string(f.name) != "batch_size" && std::string(f.name) != "iterations" &&
        std::string(f.name) != "early_stop_patience" && std::string(f.name) != "render.roi_margin" &&
        std::string(f.name) != "render.threads" && std::string(f.name) != "loss.depth_noise_power")
      bad.insert(bad.end(), {kNaN, kInf, -kInf});
    for (double v : bad) {
      RefinerOptions o;
      f.set(o, v);
      const std::string m = invalid_argument_message([&] { o.validate(); });
      EXPECT_NE(m.find(f.name), std::string::npos) << f.name << " = " << v << " was accepted or misnamed: " << m;
    }
  }
  RefinerOptions zero;
  zero.loss.weight_rgb = zero.loss.weight_depth = zero.loss.weight_mask = zero.loss.weight_edges = 0;
  EXPECT_NE(invalid_argument_message([&] { zero.validate(); }).find("every loss weight is 0"), std::string::npos);
  RefinerOptions swapped;
  swapped.lr_low = 0.1, swapped.lr_high = 0.01;
  EXPECT_NE(invalid_argument_message([&] { swapped.validate(); }).find("lr_high"), std::string::npos);
}

TEST(InputLimits, YamlErrorsNameTheFileTheKeyAndTheValue) {
  const auto message = [](const std::string& yaml) {
    try {
      RefinerOptions::from_yaml_string(yaml, "my.yaml");
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  for (const std::string& yaml : {"lr_high: .nan\n", "iterations: 1000000000\n", "batch_size: 1000000\n",
                                  "loss: {edge_scale: 1e-300}\n", "image_scale: 1e-9\n", "render: {near_plane: .nan}\n",
                                  "render: {threads: 100000}\n", "loss: {depth_truncation: .inf}\n"}) {
    const std::string m = message(yaml);
    const std::string key = yaml.substr(yaml.find('{') == std::string::npos ? 0 : yaml.find('{') + 1);
    EXPECT_NE(m.find("my.yaml"), std::string::npos) << yaml << m;
    EXPECT_NE(m.find(key.substr(0, key.find(':'))), std::string::npos) << yaml << " -> " << m;
  }
  const std::string m = message("batch_size: abc\n");
  EXPECT_NE(m.find("batch_size: expected an integer, got 'abc'"), std::string::npos) << m;
  EXPECT_NE(message("loss: {weight_rgb: [1, 2]}\n").find("weight_rgb: expected a number"), std::string::npos);
}

TEST(InputLimits, ARendererWithTooManyThreadsIsRefusedNotHung) {
  RenderOptions o;
  o.threads = 100000;
  EXPECT_NE(invalid_argument_message([&] { make_cpu_renderer(o); }).find("render.threads"), std::string::npos);
  o.threads = -1;
  EXPECT_NE(invalid_argument_message([&] { make_cpu_renderer(o); }).find("render.threads"), std::string::npos);
}

TEST(InputLimits, CamerasThatCannotImageAnythingAreRefused) {
  EXPECT_NO_THROW(Camera(500, 500, 319.5, 239.5, 640, 480).validate());
  const std::vector<Camera> bad = {Camera(1e-30, 1e-30, 319.5, 239.5, 640, 480),
                                   Camera(1e30, 500, 319.5, 239.5, 640, 480),
                                   Camera(500, 500, 1e9, 239.5, 640, 480),
                                   Camera(500, 500, 319.5, kNaN, 640, 480),
                                   Camera(500, 500, 319.5, 239.5, 100000, 480),
                                   Camera(0.1, 1e7, 319.5, 239.5, 640, 480)};  // each in range, not a camera
  for (const Camera& c : bad)
    EXPECT_NE(invalid_argument_message([&] { c.validate(); }).find("camera: unusable intrinsics"), std::string::npos)
        << c.fx << " " << c.cx << " " << c.cy << " " << c.width;
}

TEST(InputLimits, PosesWithNothingToRefineAgainstAreRefused) {
  const Camera cam(420, 420, 159.5, 119.5, 320, 240);
  const Mesh mesh = make_box(Eigen::Vector3d(0.1, 0.08, 0.06), make_label_texture(64, 3));
  const Pose truth(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 0.5));
  auto renderer = make_cpu_renderer();
  const Observation obs = synthesize_observation(*renderer, cam, mesh, truth, SyntheticNoise(), 1);
  RefinerOptions o;
  o.batch_size = 4;
  o.iterations = 2;
  Refiner refiner(o);
  Pose far = truth;
  far.t = Eigen::Vector3d(0, 0, 1e9);
  EXPECT_NE(refiner.refine(cam, obs, mesh, far).error.find("pixels across"), std::string::npos);
  Pose aside = truth;
  aside.t = Eigen::Vector3d(1e3, 0, 0.5);
  EXPECT_NE(refiner.refine(cam, obs, mesh, aside).error.find("outside the image"), std::string::npos);
  RefinerOptions deep_near = o;  // in front of the camera but not beyond the near plane: the option is named
  deep_near.render.near_plane = 1.0;
  Refiner near_refiner(deep_near);
  EXPECT_NE(near_refiner.refine(cam, obs, mesh, truth).error.find("render.near_plane"), std::string::npos);
  Pose half_out = truth;  // partly outside the image is a legal start
  half_out.t.x() = 0.2;
  EXPECT_EQ(refiner.refine(cam, obs, mesh, half_out).error, "");
}

TEST(InputLimits, AMeshThatDrawsNothingIsRefusedWhenFinalized) {
  Mesh m;
  m.name = "flat";
  m.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 0, 0}};
  m.triangles = {0, 1, 2, 0, 3, 1};  // collinear, and one with a repeated position
  try {
    m.finalize();
    FAIL() << "a mesh of degenerate triangles was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("degenerate"), std::string::npos) << e.what();
  }
  // One vertex far beyond any object: named, rather than "degenerate" after its squares overflow.
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1e38f, 1, 0}};
  m.triangles = {0, 1, 2};
  try {
    m.finalize();
    FAIL() << "a vertex at 1e38 m was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 2 is at (1e+38, 1, 0) m"), std::string::npos) << e.what();
  }
}

TEST(InputLimits, TrackingOptionsOutsideTheirRangeAreRefused) {
  EXPECT_NO_THROW(ObjectTrack(TrackOptions()));
  const std::vector<std::pair<const char*, std::function<void(TrackOptions&)>>> bad = {
      {"max_detection_age", [](TrackOptions& o) { o.max_detection_age = kNaN; }},
      {"track_timeout", [](TrackOptions& o) { o.track_timeout = -1; }},
      {"max_track_failures", [](TrackOptions& o) { o.max_failures = 0; }},
      {"max_extrapolation", [](TrackOptions& o) { o.max_extrapolation = kInf; }},
      {"track_batch_size", [](TrackOptions& o) { o.batch_size = -1; }},
      {"track_iterations", [](TrackOptions& o) { o.iterations = RefinerOptions::kMaxIterations + 1; }}};
  for (const auto& [name, set] : bad) {
    TrackOptions o;
    set(o);
    EXPECT_NE(invalid_argument_message([&] { ObjectTrack t(o); }).find(name), std::string::npos) << name;
  }
}

// Found by fuzz_camera_pose: a YAML camera file holding bytes that are not UTF-8 made the error message itself
// throw (nlohmann::json::dump), which terminated diffdope_refine.
TEST(InputLimits, CameraFilesWithBytesThatAreNotUtf8GetAnErrorNotACrash) {
  const std::string path = (std::filesystem::temp_directory_path() / "diffdope_camera_not_utf8.yaml").string();
  std::ofstream(path) << "fx: \"\xff\xfe\x01\"\nfy: 500\ncx: 320\ncy: 240\n";
  try {
    read_camera_file(path, 640, 480);
    FAIL() << "accepted";
  } catch (const InputFileError& e) {
    EXPECT_NE(std::string(e.what()).find("'fx' must be a number or an array of numbers, found"), std::string::npos) << e.what();
  }
  std::ofstream(path) << "K: [600, 0, 320, 0, 600, 240, 0, 0, \"\xc3\x28\"]\n";
  EXPECT_THROW(read_camera_file(path, 640, 480), InputFileError);
  std::filesystem::remove(path);
}
