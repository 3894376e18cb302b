// diffdope_calibrate run as a user would: a generated arm and three captures written to files, calibrated from
// 5 cm / 10 degrees off, and every kind of bad input answered with one line naming the file (exit code 1) or the
// usage (exit code 2).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

struct CliRun {
  int rc = -1;
  std::string out, err;
};

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

class CalibrateCli : public ::testing::Test {
 protected:
  static fs::path dir;
  static void SetUpTestSuite() {
    std::random_device rd;
    dir = fs::temp_directory_path() / ("diffdope_calib_cli_" + std::to_string(getpid()) + "_" + std::to_string(rd()));
    fs::create_directories(dir);
    ASSERT_EQ(run("--generate " + (dir / "set").string() + " --seed 2").rc, 0);
  }
  static void TearDownTestSuite() { fs::remove_all(dir); }

  static CliRun run(const std::string& args) {
    const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
    CliRun r;
    r.rc = WEXITSTATUS(std::system((std::string(DIFFDOPE_CALIBRATE_EXE) + " " + args + " > " + out.string() + " 2> " +
                                    err.string()).c_str()));
    r.out = slurp(out), r.err = slurp(err);
    return r;
  }
  /// The generated set's arguments, with `captures` instead of its own folder.
  static std::string args(const fs::path& captures, const std::string& extra = "") {
    const fs::path s = dir / "set";
    return "--urdf " + (s / "robot/robot.urdf").string() + " --captures " + captures.string() + " --camera " +
           (s / "camera.json").string() + " --init " + (s / "init.json").string() + " --out " +
           (dir / "out").string() + " --quiet " + extra;
  }
  /// A copy of the generated captures to break.
  static fs::path copy_captures(const std::string& name) {
    const fs::path to = dir / name;
    fs::remove_all(to);
    fs::copy(dir / "set/captures", to, fs::copy_options::recursive);
    return to;
  }
  static void expect_error(const CliRun& r, const std::string& file, const std::string& needle) {
    EXPECT_EQ(r.rc, 1) << r.err;
    EXPECT_EQ(r.err.find("diffdope_calibrate: " + file), 0u) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
};
fs::path CalibrateCli::dir;

}  // namespace

TEST_F(CalibrateCli, CalibratesTheGeneratedArm) {
  const CliRun r = run(args(dir / "set/captures", "--truth " + (dir / "set/truth.json").string()));
  ASSERT_EQ(r.rc, 0) << r.err;
  for (const char* f : {"calibration.yaml", "calibration.launch", "result.json", "residuals.txt", "overlay_00.png",
                        "overlay_02.png"})
    EXPECT_TRUE(fs::exists(dir / "out" / f)) << f;
  const nlohmann::json j = nlohmann::json::parse(slurp(dir / "out/result.json"));
  EXPECT_LT(j["error_vs_truth"]["camera_position_mm"].get<double>(), 2.0) << j.dump(2);
  EXPECT_LT(j["error_vs_truth"]["rotation_deg"].get<double>(), 0.2) << j.dump(2);
  EXPECT_TRUE(j["plausible"].get<bool>());
  EXPECT_EQ(j["captures"].size(), 3u);
  const std::string yaml = slurp(dir / "out/calibration.yaml");
  for (const char* key : {"eye_on_hand: false", "robot_base_frame: base_link", "tracking_base_frame: camera_color_optical_frame",
                          "transformation:", "  qw: "})
    EXPECT_NE(yaml.find(key), std::string::npos) << key << "\n" << yaml;
  EXPECT_NE(slurp(dir / "out/calibration.launch").find("static_transform_publisher"), std::string::npos);
}

TEST_F(CalibrateCli, EyeInHandFromFiveCentimetresAndTenDegrees) {
  // The camera on the hand's bracket: four captures with masks, the guess 5 cm / 10 degrees off (the target:
  // within 1 mm / 0.05 degrees), easy_handeye's eye-on-hand layout.
  const fs::path set = dir / "hand";
  ASSERT_EQ(run("--generate " + set.string() + " --seed 3 --count 4 --no-rgb --eye-in-hand link5").rc, 0);
  const std::string files = "--urdf " + (set / "robot/robot.urdf").string() + " --captures " +
                            (set / "captures").string() + " --camera " + (set / "camera.json").string() +
                            " --init " + (set / "init.json").string() + " --out " + (dir / "hand_out").string() +
                            " --quiet --truth " + (set / "truth.json").string();
  const CliRun r = run(files + " --eye-in-hand link5");
  ASSERT_EQ(r.rc, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(slurp(dir / "hand_out/result.json"));
  EXPECT_LT(j["error_vs_truth"]["camera_position_mm"].get<double>(), 1.0) << j.dump(2);
  EXPECT_LT(j["error_vs_truth"]["rotation_deg"].get<double>(), 0.05) << j.dump(2);
  EXPECT_TRUE(j["plausible"].get<bool>());
  EXPECT_GT(j["position_std_mm"].get<double>(), 0);
  const std::string yaml = slurp(dir / "hand_out/calibration.yaml");
  for (const char* key : {"eye_on_hand: true", "robot_effector_frame: link5", "tracking_base_frame: "})
    EXPECT_NE(yaml.find(key), std::string::npos) << key << "\n" << yaml;
  EXPECT_NE(slurp(dir / "hand_out/calibration.launch").find(" link5 camera_color_optical_frame"), std::string::npos);
  // A link the robot does not have, or its base, names the URDF; an empty name, or a base frame eye in hand,
  // is a usage error.
  expect_error(run(files + " --eye-in-hand gripper"), (set / "robot/robot.urdf").string(), "no link 'gripper'");
  expect_error(run(files + " --eye-in-hand base_link"), (set / "robot/robot.urdf").string(), "is the robot's base");
  for (const char* usage : {" --eye-in-hand ''", " --eye-in-hand link5 --robot-base-frame base_link",
                            " --camera-frame ''"}) {
    const CliRun u = run(files + usage);
    EXPECT_EQ(u.rc, 2) << usage << ": " << u.err;
  }
}

TEST_F(CalibrateCli, CaptureErrorsNameTheFile) {
  {  // a capture without its joints
    const fs::path c = copy_captures("no_joints");
    fs::remove(c / "01/joints.json");
    expect_error(run(args(c)), (c / "01/joints.json").string(), "");
  }
  {  // a joint the robot needs is missing
    const fs::path c = copy_captures("missing_joint");
    std::ofstream(c / "00/joints.json") << "{\"joint1\": 0.1, \"joint2\": 0.2, \"joint3\": 0.3, \"joint4\": 0.0}";
    expect_error(run(args(c)), (c / "00/joints.json").string(), "joint 'joint5' has no position");
  }
  {  // not a number
    const fs::path c = copy_captures("text_joint");
    std::ofstream(c / "00/joints.json") << "{\"name\": [\"joint1\"], \"position\": [\"fast\"]}";
    expect_error(run(args(c)), (c / "00/joints.json").string(), "expected a number");
  }
  {  // more captures than one calibration takes: refused before any is read
    const fs::path c = copy_captures("too_many");
    for (int k = 10; k < 80; ++k) fs::create_directories(c / std::to_string(k));
    expect_error(run(args(c)), c.string(), "capture folders; at most 64");
  }
  {  // a depth file that is not an image
    const fs::path c = copy_captures("corrupt_depth");
    std::ofstream(c / "02/depth.png", std::ios::trunc) << "not a png";
    expect_error(run(args(c)), (c / "02/depth.png").string(), "cannot read it as an image");
  }
  {  // a mask in some captures only
    const fs::path c = copy_captures("some_masks");
    fs::remove(c / "01/mask.png");
    expect_error(run(args(c)), (c / "01").string(), "give every capture a mask, or none");
  }
  {  // no capture at all
    const fs::path c = dir / "empty";
    fs::create_directories(c);
    expect_error(run(args(c)), c.string(), "no capture folder");
  }
}

TEST_F(CalibrateCli, RobotAndUsageErrors) {
  const fs::path urdf = dir / "bad.urdf";
  std::ofstream(urdf) << "<robot name=\"x\"><link name=\"a\"><visual><geometry><mesh filename=\"package://nosuch/m.stl\"/>"
                         "</geometry></visual></link></robot>";
  const fs::path s = dir / "set";
  const std::string rest = " --captures " + (s / "captures").string() + " --camera " + (s / "camera.json").string() +
                           " --init " + (s / "init.json").string() + " --out " + (dir / "out2").string() + " --quiet";
  expect_error(run("--urdf " + urdf.string() + rest), urdf.string(), "nosuch");
  const CliRun usage = run("--urdf " + urdf.string() + rest + " --package-path nosuch");
  EXPECT_EQ(usage.rc, 2) << usage.err;
  EXPECT_NE(usage.err.find("expected NAME=DIR"), std::string::npos) << usage.err;
  const CliRun missing = run("--captures x");
  EXPECT_EQ(missing.rc, 2);
  EXPECT_NE(missing.err.find("--urdf is required"), std::string::npos) << missing.err;
  const CliRun passes = run(args(s / "captures", "--passes 0"));
  EXPECT_EQ(passes.rc, 2);
}
