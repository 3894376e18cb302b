// diffdope_refine run as a user would: inputs written to files (a millimetre PLY box with a PNG texture, a
// synthetic scene saved as 8-bit rgb / 16-bit mm depth / 8-bit mask PNGs, camera and initial pose in the formats
// the tool reads), the tool started with std::system, its outputs and error reports checked.
#include <gtest/gtest.h>

#include "diffdope/device.hpp"
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "diffdope/procedural.hpp"
#include "diffdope/renderer.hpp"
#include "diffdope/synthetic.hpp"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace diffdope;

namespace {

const Camera kCam(300.0, 300.0, 159.5, 119.5, 320, 240);

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_text(const fs::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out << s;
  ASSERT_TRUE(out.good()) << p;
}

int count_lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

struct RunResult {
  int rc = -1;
  std::string out, err;
};

/// The shared inputs: written once for the whole suite.
class RefineCliTest : public ::testing::Test {
 protected:
  static fs::path dir;
  static Pose truth, init;

  static void SetUpTestSuite() {
    std::random_device rd;
    dir = fs::temp_directory_path() /
          ("diffdope_cli_" + std::to_string(getpid()) + "_" + std::to_string(rd()));
    fs::create_directories(dir);

    // Model: a printed box, written as a millimetre PLY with a PNG texture next to it.
    const Mesh box = make_box(Eigen::Vector3d(0.12, 0.08, 0.16), make_label_texture(128, 7));
    ASSERT_EQ(box.num_vertices(), 24);
    ASSERT_EQ(box.num_triangles(), 12);
    std::ostringstream ply;
    ply << "ply\nformat ascii 1.0\ncomment made by test_refine_cli\ncomment TextureFile tex.png\n"
        << "element vertex " << box.num_vertices()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float texture_u\n"
        << "property float texture_v\nelement face " << box.num_triangles()
        << "\nproperty list uchar int vertex_indices\nend_header\n";
    ply.precision(9);
    for (int i = 0; i < box.num_vertices(); ++i) {
      const auto& p = box.positions[i];
      ply << 1000.0 * p.x << " " << 1000.0 * p.y << " " << 1000.0 * p.z << " " << box.uvs[i].x << " " << box.uvs[i].y
          << "\n";
    }
    for (int t = 0; t < box.num_triangles(); ++t)
      ply << "3 " << box.triangles[3 * t] << " " << box.triangles[3 * t + 1] << " " << box.triangles[3 * t + 2] << "\n";
    write_text(dir / "box.ply", ply.str());
    const Texture& tex = box.textures.at(0);
    cv::Mat tex_rgb(tex.height, tex.width, CV_32FC3, const_cast<float*>(tex.rgb.data())), tex_bgr;
    cv::cvtColor(tex_rgb, tex_bgr, cv::COLOR_RGB2BGR);
    tex_bgr.convertTo(tex_bgr, CV_8UC3, 255.0);
    ASSERT_TRUE(cv::imwrite((dir / "tex.png").string(), tex_bgr));

    // The scene, rendered with the model as the tool will load it.
    MeshLoadOptions mopt;
    mopt.scale = 0.001;
    const Mesh mesh = Mesh::load((dir / "box.ply").string(), mopt);
    ASSERT_TRUE(mesh.has_texture());
    Vector6d d;
    d << 0, 0, 0, 0.5, -0.6, 0.3;
    truth = Pose(se3_exp(d).R, Eigen::Vector3d(0.02, -0.01, 0.5));
    auto renderer = make_cpu_renderer();
    const Observation obs = synthesize_observation(*renderer, kCam, mesh, truth, SyntheticNoise(), 11);
    cv::Mat bgr, depth_mm, mask8;
    cv::cvtColor(obs.rgb, bgr, cv::COLOR_RGB2BGR);
    bgr.convertTo(bgr, CV_8UC3, 255.0);
    obs.depth.convertTo(depth_mm, CV_16UC1, 1000.0);
    obs.mask.convertTo(mask8, CV_8UC1, 255.0);
    ASSERT_TRUE(cv::imwrite((dir / "rgb.png").string(), bgr));
    ASSERT_TRUE(cv::imwrite((dir / "depth.png").string(), depth_mm));
    ASSERT_TRUE(cv::imwrite((dir / "mask.png").string(), mask8));
    ASSERT_GT(cv::countNonZero(mask8), 1000);

    std::mt19937_64 rng(5);
    init = perturb_pose(truth, mesh.center(), 10.0 * M_PI / 180.0, 0.01, rng);

    // Cameras: BOP cam_K (size from the image) and YAML fx/fy/cx/cy with the size.
    const json bop = {{"cam_K", {kCam.fx, 0.0, kCam.cx, 0.0, kCam.fy, kCam.cy, 0.0, 0.0, 1.0}}, {"depth_scale", 1.0}};
    write_text(dir / "camera_bop.json", bop.dump());
    std::ostringstream yaml;
    yaml.precision(10);
    yaml << "fx: " << kCam.fx << "\nfy: " << kCam.fy << "\ncx: " << kCam.cx << "\ncy: " << kCam.cy
         << "\nwidth: " << kCam.width << "\nheight: " << kCam.height << "\n";
    write_text(dir / "camera.yaml", yaml.str());

    // Initial pose in the three formats.
    const Eigen::Matrix4d M = init.matrix();
    json rt = {{"R", init.rotation_rowmajor()}, {"t", {init.t.x(), init.t.y(), init.t.z()}}};
    json quat = {{"quaternion", init.quaternion_xyzw()}, {"t", {init.t.x(), init.t.y(), init.t.z()}}};
    json rows = json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({M(r, 0), M(r, 1), M(r, 2), M(r, 3)});
    json mat = {{"matrix", rows}};
    write_text(dir / "init_rt.json", rt.dump(2));
    write_text(dir / "init_quat.json", quat.dump(2));
    write_text(dir / "init_matrix.json", mat.dump(2));

    write_text(dir / "fast.yaml", "batch_size: 16\niterations: 60\nimage_scale: 1.0\n");
  }

  static void TearDownTestSuite() {
    if (!std::getenv("DIFFDOPE_KEEP_TEST_FILES")) {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  }

  static std::string f(const std::string& name) { return (dir / name).string(); }

  /// Runs the tool with `args` (already quoted where needed); stdout and stderr captured to files.
  static RunResult run(const std::vector<std::string>& args, const std::string& tag) {
    const fs::path out = dir / (tag + ".stdout"), err = dir / (tag + ".stderr");
    std::string cmd = quote(DIFFDOPE_REFINE_EXE);
    for (const auto& a : args) cmd += " " + quote(a);
    cmd += " > " + quote(out.string()) + " 2> " + quote(err.string()) + " < /dev/null";
    const int status = std::system(cmd.c_str());
    RunResult r;
    r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_text(out);
    r.err = read_text(err);
    return r;
  }

  /// The standard arguments for a full refinement; `override` replaces (flag, value) pairs.
  static std::vector<std::string> args(const std::string& out_dir,
                                       const std::vector<std::pair<std::string, std::string>>& change) {
    std::vector<std::pair<std::string, std::string>> a = {
        {"--rgb", f("rgb.png")},          {"--depth", f("depth.png")},   {"--mask", f("mask.png")},
        {"--camera", f("camera_bop.json")}, {"--mesh", f("box.ply")},    {"--mesh-scale", "0.001"},
        {"--init", f("init_rt.json")},    {"--config", f("fast.yaml")}, {"--out", (dir / out_dir).string()}};
    for (const auto& [k, v] : change) {
      bool found = false;
      for (auto& e : a)
        if (e.first == k) e.second = v, found = true;
      if (!found) a.push_back({k, v});
    }
    std::vector<std::string> out;
    for (const auto& [k, v] : a) {
      if (v == "<drop>") continue;
      out.push_back(k);
      if (!v.empty()) out.push_back(v);
    }
    return out;
  }

  /// A successful refinement: pose close to the truth, every output present and sized right.
  static void expect_refined(const std::string& out_dir, const RunResult& r) {
    ASSERT_EQ(r.rc, 0) << "stderr: " << r.err << "\nstdout: " << r.out;
    const fs::path out = dir / out_dir;
    ASSERT_TRUE(fs::exists(out / "pose.json"));
    json j;
    ASSERT_NO_THROW(j = json::parse(read_text(out / "pose.json")));
    for (const char* key : {"R", "t", "quaternion_xyzw", "matrix", "loss", "loss_terms", "initial_loss", "iterations",
                            "time_ms", "mask_iou", "depth_inliers", "converged", "plausible", "winner",
                            "learning_rate", "given_mask_replaced", "given_mask_offset", "given_mask_shift",
                            "given_mask_shifted_offset"})
      EXPECT_TRUE(j.contains(key)) << key;
    const auto R = j.at("R").get<std::vector<double>>();
    const auto t = j.at("t").get<std::vector<double>>();
    ASSERT_EQ(R.size(), 9u);
    ASSERT_EQ(t.size(), 3u);
    std::array<double, 9> ra;
    std::copy(R.begin(), R.end(), ra.begin());
    const Pose p = Pose::from_rotation_rowmajor(ra, Eigen::Vector3d(t[0], t[1], t[2]));
    const double dt = (p.t - truth.t).norm(), dr = rotation_angle(p.R, truth.R) * 180 / M_PI;
    EXPECT_LT(dt, 0.005) << "translation error " << 1e3 * dt << " mm (initial " << 1e3 * (init.t - truth.t).norm()
                         << " mm)";
    EXPECT_LT(dr, 2.0) << "rotation error " << dr << " deg";
    EXPECT_LT(j.at("loss").get<double>(), j.at("initial_loss").get<double>());
    EXPECT_EQ(j.at("iterations").get<int>(), 60);
    EXPECT_EQ(j.at("matrix").size(), 16u);
    // The quaternion and the matrix describe the same pose as R, t.
    const auto q = j.at("quaternion_xyzw").get<std::vector<double>>();
    const Pose pq = Pose::from_quaternion(q[0], q[1], q[2], q[3], p.t);
    EXPECT_LT(rotation_angle(pq.R, p.R), 1e-6);
    const auto m = j.at("matrix").get<std::vector<double>>();
    EXPECT_NEAR(m[3], t[0], 1e-12);
    EXPECT_NEAR(m[11], t[2], 1e-12);
    EXPECT_NEAR(m[1], R[1], 1e-12);

    const cv::Mat overlay = cv::imread((out / "overlay.png").string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(overlay.empty());
    EXPECT_EQ(overlay.cols, kCam.width);
    EXPECT_EQ(overlay.rows, kCam.height);
    EXPECT_EQ(overlay.type(), CV_8UC3);
    // The outlines are drawn: pure-ish red and green pixels exist.
    cv::Mat red, green;
    cv::inRange(overlay, cv::Scalar(0, 0, 200), cv::Scalar(60, 60, 255), red);
    cv::inRange(overlay, cv::Scalar(0, 200, 0), cv::Scalar(60, 255, 60), green);
    EXPECT_GT(cv::countNonZero(red), 50);
    EXPECT_GT(cv::countNonZero(green), 50);

    const cv::Mat plot = cv::imread((out / "losses.png").string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(plot.empty());
    EXPECT_GE(plot.cols, 600);
    EXPECT_LE(plot.cols, 1000);
    EXPECT_GE(plot.rows, 400);
    EXPECT_LE(plot.rows, 700);
    // Not a blank canvas.
    cv::Mat grey;
    cv::cvtColor(plot, grey, cv::COLOR_BGR2GRAY);
    EXPECT_GT(cv::countNonZero(grey < 128), 500);

    EXPECT_NE(r.out.find("quaternion"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("ms"), std::string::npos) << r.out;
    // stderr is not a terminal here: no progress bar.
    EXPECT_EQ(r.err.find('['), std::string::npos) << r.err;
  }

  /// A failed run: exit code `rc`, and one line `diffdope_refine: <file>: ...` naming `file`.
  static void expect_error(const RunResult& r, const std::string& file, const std::string& also = "") {
    EXPECT_EQ(r.rc, 1) << "stderr: " << r.err << "\nstdout: " << r.out;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_EQ(r.err.rfind("diffdope_refine: " + file + ": ", 0), 0u) << r.err;
    if (!also.empty()) EXPECT_NE(r.err.find(also), std::string::npos) << r.err;
  }
};

fs::path RefineCliTest::dir;
Pose RefineCliTest::truth, RefineCliTest::init;

TEST_F(RefineCliTest, RefinesWithBopCameraAndRotationInit) {
  ASSERT_GT((init.t - truth.t).norm(), 0.009);
  ASSERT_GT(rotation_angle(init.R, truth.R) * 180 / M_PI, 9.0);
  const auto t0 = std::chrono::steady_clock::now();
  const RunResult r = run(args("out_bop", {}), "bop");
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  expect_refined("out_bop", r);
  EXPECT_LT(s, 30.0);
  const json j = json::parse(read_text(dir / "out_bop" / "pose.json"));
  EXPECT_GT(j.at("mask_iou").get<double>(), 0.8);
  EXPECT_GT(j.at("depth_inliers").get<double>(), 0.5);
  EXPECT_TRUE(j.at("plausible").get<bool>());
}

TEST_F(RefineCliTest, RefinesWithYamlCameraAndQuaternionInit) {
  const RunResult r =
      run(args("out_yaml", {{"--camera", f("camera.yaml")}, {"--init", f("init_quat.json")}, {"--quiet", ""}}),
          "yaml");
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(r.out.empty()) << "--quiet printed: " << r.out;
  // The same checks on the files (stdout is empty with --quiet, so not on that).
  RunResult copy = r;
  copy.out = "quaternion ms";
  expect_refined("out_yaml", copy);
}

TEST_F(RefineCliTest, RefinesWithMatrixInitWithoutMask) {
  const RunResult r = run(args("out_matrix", {{"--init", f("init_matrix.json")}, {"--mask", "<drop>"}}), "matrix");
  expect_refined("out_matrix", r);
  const json j = json::parse(read_text(dir / "out_matrix" / "pose.json"));
  EXPECT_GT(j.at("mask_iou").get<double>(), 0.8);  // no mask given: against the pixels derived from depth
  EXPECT_TRUE(j.at("judged").get<bool>());
}

// A 2D detector's box instead of a mask; a box with a mask, a malformed one and one beside the image refused.
TEST_F(RefineCliTest, RefinesWithABoxInsteadOfAMask) {
  const cv::Rect b = cv::boundingRect(cv::imread(f("mask.png"), cv::IMREAD_GRAYSCALE) > 0);
  const std::string box = std::to_string(b.x) + "," + std::to_string(b.y) + "," + std::to_string(b.width) + "," +
                          std::to_string(b.height);
  const RunResult r = run(args("out_box", {{"--mask", "<drop>"}, {"--box", box}}), "box");
  expect_refined("out_box", r);
  EXPECT_TRUE(json::parse(read_text(dir / "out_box" / "pose.json")).at("plausible").get<bool>());
  RunResult e = run(args("err_box_mask", {{"--box", box}}), "box_mask");
  EXPECT_EQ(e.rc, 2) << e.err;
  EXPECT_NE(e.err.find("--box"), std::string::npos) << e.err;
  e = run(args("err_box_short", {{"--mask", "<drop>"}, {"--box", "1,2,3"}}), "box_short");
  EXPECT_EQ(e.rc, 2) << e.err;
  e = run(args("err_box_size", {{"--mask", "<drop>"}, {"--box", "1,2,0,4"}}), "box_size");
  EXPECT_EQ(e.rc, 2) << e.err;
  e = run(args("err_box_out", {{"--mask", "<drop>"}, {"--box", "5000,10,20,20"}}), "box_out");
  expect_error(e, "--box", "does not overlap");
  EXPECT_FALSE(fs::exists(dir / "err_box_out" / "pose.json"));
}

TEST_F(RefineCliTest, FlatMatrixInitAndCreatesNestedOutDir) {
  const Eigen::Matrix4d M = init.matrix();
  std::vector<double> flat;
  for (int i = 0; i < 16; ++i) flat.push_back(M(i / 4, i % 4));
  write_text(dir / "init_flat.json", json{{"matrix", flat}}.dump());
  const RunResult r = run(args("nested/a/b", {{"--init", f("init_flat.json")}}), "flat");
  expect_refined("nested/a/b", r);
}

TEST_F(RefineCliTest, Grey16BitRgb) {
  cv::Mat bgr = cv::imread(f("rgb.png")), grey, grey16;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  grey.convertTo(grey16, CV_16UC1, 257.0);
  ASSERT_TRUE(cv::imwrite(f("grey16.png"), grey16));
  const RunResult r = run(args("out_grey16", {{"--rgb", f("grey16.png")}}), "grey16");
  expect_refined("out_grey16", r);
}

// ---- Errors: one line naming the file, exit code 1 ----

TEST_F(RefineCliTest, MissingRgbFile) {
  const std::string missing = f("no_such_rgb.png");
  const RunResult r = run(args("err_missing", {{"--rgb", missing}}), "missing");
  expect_error(r, missing, "does not exist");
  EXPECT_FALSE(fs::exists(dir / "err_missing" / "pose.json"));
}

TEST_F(RefineCliTest, CorruptRgbFile) {
  write_text(dir / "corrupt.png", "this is not an image, just some text bytes\n");
  const RunResult r = run(args("err_corrupt", {{"--rgb", f("corrupt.png")}}), "corrupt");
  expect_error(r, f("corrupt.png"), "image");
}

TEST_F(RefineCliTest, TruncatedPngRgbFile) {
  const std::string good = read_text(dir / "rgb.png");
  write_text(dir / "truncated.png", good.substr(0, good.size() / 3));
  const RunResult r = run(args("err_trunc", {{"--rgb", f("truncated.png")}}), "trunc");
  expect_error(r, f("truncated.png"));
}

TEST_F(RefineCliTest, DepthOfWrongSize) {
  ASSERT_TRUE(cv::imwrite(f("depth_small.png"), cv::Mat(120, 160, CV_16UC1, cv::Scalar(500))));
  const RunResult r = run(args("err_depth", {{"--depth", f("depth_small.png")}}), "depth_size");
  expect_error(r, f("depth_small.png"), "160x120");
}

TEST_F(RefineCliTest, DepthWithThreeChannels) {
  ASSERT_TRUE(cv::imwrite(f("depth_colour.png"), cv::Mat(240, 320, CV_8UC3, cv::Scalar(1, 2, 3))));
  const RunResult r = run(args("err_depth3", {{"--depth", f("depth_colour.png")}}), "depth_channels");
  expect_error(r, f("depth_colour.png"), "one channel");
}

TEST_F(RefineCliTest, MaskOfWrongSizeAndEmptyMask) {
  ASSERT_TRUE(cv::imwrite(f("mask_small.png"), cv::Mat(100, 100, CV_8UC1, cv::Scalar(255))));
  expect_error(run(args("err_mask", {{"--mask", f("mask_small.png")}}), "mask_size"), f("mask_small.png"));
  ASSERT_TRUE(cv::imwrite(f("mask_empty.png"), cv::Mat(240, 320, CV_8UC1, cv::Scalar(0))));
  expect_error(run(args("err_mask2", {{"--mask", f("mask_empty.png")}}), "mask_empty"), f("mask_empty.png"),
               "empty");
}

TEST_F(RefineCliTest, InitWithNaN) {
  // JSON has no NaN: a literal NaN is a parse error, and so is an overflowing number (1e999).
  std::ostringstream nan_rt;
  nan_rt << "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"t\": [0.02, NaN, 0.5]}";
  write_text(dir / "init_nan.json", nan_rt.str());
  expect_error(run(args("err_nan", {{"--init", f("init_nan.json")}}), "init_nan"), f("init_nan.json"));
  write_text(dir / "init_inf.json", "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"t\": [0.02, 1e999, 0.5]}");
  expect_error(run(args("err_inf", {{"--init", f("init_inf.json")}}), "init_inf"), f("init_inf.json"), "1e999");
  write_text(dir / "init_strnan.json", "{\"quaternion\": [0, 0, 0, \"nan\"], \"t\": [0.02, 0, 0.5]}");
  expect_error(run(args("err_snan", {{"--init", f("init_strnan.json")}}), "init_snan"), f("init_strnan.json"),
               "quaternion");
}

TEST_F(RefineCliTest, InitWithBadRotationOrShape) {
  write_text(dir / "init_skew.json", "{\"R\": [1, 0.2, 0, 0, 1, 0, 0, 0, 1], \"t\": [0.02, 0, 0.5]}");
  expect_error(run(args("err_skew", {{"--init", f("init_skew.json")}}), "init_skew"), f("init_skew.json"),
               "orthonormal");
  write_text(dir / "init_refl.json", "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, -1], \"t\": [0.02, 0, 0.5]}");
  expect_error(run(args("err_refl", {{"--init", f("init_refl.json")}}), "init_refl"), f("init_refl.json"),
               "reflection");
  write_text(dir / "init_short.json", "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0], \"t\": [0.02, 0, 0.5]}");
  expect_error(run(args("err_short", {{"--init", f("init_short.json")}}), "init_short"), f("init_short.json"),
               "9 values");
  write_text(dir / "init_none.json", "{\"rotation\": [1, 0, 0, 0, 1, 0, 0, 0, 1]}");
  expect_error(run(args("err_none", {{"--init", f("init_none.json")}}), "init_none"), f("init_none.json"));
  write_text(dir / "init_behind.json", "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"t\": [0.0, 0, -0.5]}");
  expect_error(run(args("err_behind", {{"--init", f("init_behind.json")}}), "init_behind"), f("init_behind.json"),
               "behind");
  write_text(dir / "init_mm.json", "{\"R\": [1, 0, 0, 0, 1, 0, 0, 0, 1], \"t\": [400, 0, 500]}");
  expect_error(run(args("err_mm", {{"--init", f("init_mm.json")}}), "init_mm"), f("init_mm.json"), "millimetres");
}

TEST_F(RefineCliTest, CameraMissingFx) {
  write_text(dir / "camera_nofx.json", "{\"fy\": 300, \"cx\": 159.5, \"cy\": 119.5, \"width\": 320, \"height\": 240}");
  const RunResult r = run(args("err_cam", {{"--camera", f("camera_nofx.json")}}), "cam_nofx");
  expect_error(r, f("camera_nofx.json"), "'fx'");
}

TEST_F(RefineCliTest, CameraErrors) {
  write_text(dir / "camera_size.yaml", "fx: 300\nfy: 300\ncx: 159.5\ncy: 119.5\nwidth: 640\nheight: 480\n");
  expect_error(run(args("err_cs", {{"--camera", f("camera_size.yaml")}}), "cam_size"), f("camera_size.yaml"),
               "640x480");
  write_text(dir / "camera_bad.yml", "fx: [300\nfy: 300\n");
  expect_error(run(args("err_cb", {{"--camera", f("camera_bad.yml")}}), "cam_bad"), f("camera_bad.yml"), "YAML");
  write_text(dir / "camera_k8.json", "{\"cam_K\": [300, 0, 159.5, 0, 300, 119.5, 0, 0]}");
  expect_error(run(args("err_ck", {{"--camera", f("camera_k8.json")}}), "cam_k8"), f("camera_k8.json"), "cam_K");
  write_text(dir / "camera.txt", "fx 300\n");
  expect_error(run(args("err_ct", {{"--camera", f("camera.txt")}}), "cam_txt"), f("camera.txt"), ".json");
  write_text(dir / "camera_neg.json", "{\"fx\": -300, \"fy\": 300, \"cx\": 159.5, \"cy\": 119.5}");
  expect_error(run(args("err_cn", {{"--camera", f("camera_neg.json")}}), "cam_neg"), f("camera_neg.json"));
}

TEST_F(RefineCliTest, MeshAndConfigErrors) {
  expect_error(run(args("err_mesh", {{"--mesh", f("nope.ply")}}), "mesh_missing"), f("nope.ply"), "does not exist");
  write_text(dir / "junk.ply", "ply\nformat ascii 1.0\nelement vertex 3\nend_header\ngarbage\n");
  expect_error(run(args("err_junk", {{"--mesh", f("junk.ply")}}), "mesh_junk"), f("junk.ply"));
  // A millimetre model read as metres: 200 m across, the camera ends up inside it.
  expect_error(run(args("err_scale", {{"--mesh-scale", "<drop>"}}), "mesh_scale"), f("box.ply"), "--mesh-scale");
  write_text(dir / "typo.yaml", "batch_sise: 4\n");
  expect_error(run(args("err_cfg", {{"--config", f("typo.yaml")}}), "cfg_typo"), f("typo.yaml"), "batch_sise");
}

TEST_F(RefineCliTest, DeviceFlag) {
  // auto runs everywhere (CUDA if present, else the CPU with one line on stderr); cuda without a device is a
  // one-line error, not a crash; an unknown device names the choices.
  const RunResult r = run(args("out_auto", {{"--device", "auto"}, {"--quiet", ""}}), "device_auto");
  ASSERT_EQ(r.rc, 0) << r.err;
  const CudaDeviceInfo info = cuda_device_info();
  if (!info.available) EXPECT_NE(r.err.find("using the CPU backend"), std::string::npos) << r.err;
  const RunResult c = run(args("out_cuda", {{"--device", "cuda"}, {"--quiet", ""}}), "device_cuda");
  if (info.available) {
    EXPECT_EQ(c.rc, 0) << c.err;
  } else {
    EXPECT_EQ(c.rc, 1) << c.err;
    EXPECT_NE(c.err.find("unavailable"), std::string::npos) << c.err;
    EXPECT_EQ(count_lines(c.err), 1) << c.err;
  }
  expect_error(run(args("err_dev", {{"--device", "gpu"}}), "device_gpu"), "--device", "is not one of cpu, cuda, auto");
}

// ---- Usage errors: exit code 2 ----

TEST_F(RefineCliTest, UnknownFlag) {
  auto a = args("err_flag", {});
  a.push_back("--frobnicate");
  const RunResult r = run(a, "flag");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--frobnicate"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("usage:"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "err_flag"));
}

TEST_F(RefineCliTest, MissingRequiredFlagsAndBadNumbers) {
  RunResult r = run(args("err_req", {{"--init", "<drop>"}}), "req");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--init"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("usage:"), std::string::npos) << r.err;
  r = run(args("err_num", {{"--depth-scale", "abc"}}), "num");
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--depth-scale"), std::string::npos) << r.err;
  r = run({"--rgb"}, "novalue");
  EXPECT_EQ(r.rc, 2) << r.err;
  r = run({"--help"}, "help");
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("usage:"), std::string::npos) << r.out;
}

}  // namespace
