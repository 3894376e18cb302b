// Real camera frames in the loop: diffdope_eval on one scene of ../shared/data/dev_real (YCB-Video, an Asus
// Xtion: colour a few pixels off depth, holes and flying pixels at silhouettes) in the user's mask modes. Skipped,
// with the reason, where the data set is not beside the checkout (it is not part of the repository).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;

namespace {

const fs::path kDevReal = fs::path(DIFFDOPE_SOURCE_DIR) / ".." / "shared" / "data" / "dev_real";
const char* const kScene = "000102";

struct TempDir {
  fs::path path;
  explicit TempDir(const std::string& name) : path(fs::temp_directory_path() / name) { fs::create_directories(path); }
  ~TempDir() { fs::remove_all(path); }
};

}  // namespace

/// diffdope_eval on the scene's easy and tracking starts (at most two samples a level) with `args`; its results.
std::vector<nlohmann::json> evaluate_scene(const std::string& args, const std::string& name) {
  const TempDir dir("diffdope_dev_real_" + std::to_string(::getpid()) + name);
  const fs::path& tmp = dir.path;
  fs::create_directories(tmp / "perturbations" / kScene);
  for (const char* f : {"scene_error_deg_001_trans_001.json", "tracking.json"})
    fs::copy_file(kDevReal / "perturbations" / kScene / f, tmp / "perturbations" / kScene / f);
  const fs::path out = tmp / "results.jsonl";
  const std::string cmd = std::string(DIFFDOPE_EVAL_EXE) + " --bop " + kDevReal.string() + " --split test" +
                          " --perturbations " + (tmp / "perturbations").string() + " --out " + out.string() +
                          " --max-samples 2 " + args + " > /dev/null 2>&1";
  std::vector<nlohmann::json> results;
  EXPECT_EQ(WEXITSTATUS(std::system(cmd.c_str())), 0) << cmd;
  std::ifstream in(out);
  for (std::string line; std::getline(in, line);) results.push_back(nlohmann::json::parse(line));
  return results;
}

class DevReal : public ::testing::TestWithParam<const char*> {};

// From easy starts (1 deg, 1 mm) and from the previous frame's pose, a refinement must stay near the truth in every
// mask mode. Bound: 10 mm, which the mustard bottle broke by 63 mm when a turned flat render fit its lit,
// misregistered print by a lower loss.
TEST_P(DevReal, NoEasyOrTrackedStartEndsFar) {
  if (!fs::is_directory(kDevReal / "test" / kScene))
    GTEST_SKIP() << kDevReal.string() << " is not here: the real frames are not checked";
  const std::vector<nlohmann::json> results = evaluate_scene(std::string("--masks ") + GetParam(), GetParam());
  for (const nlohmann::json& r : results)
    EXPECT_LT(r["error_mm"].get<double>(), 10.0)
        << GetParam() << ": obj " << r["obj_id"] << " " << r["level"] << " sample " << r["sample"] << " from "
        << r["error_init_mm"] << " mm";
  EXPECT_EQ(results.size(), 3u * 2 + 3);  // three objects: two easy starts each, one tracked
}

INSTANTIATE_TEST_SUITE_P(MaskModes, DevReal, ::testing::Values("given", "none", "box"),
                         [](const auto& info) { return std::string(info.param); });

// The node's budget for a steady track (TrackOptions: 4 runs of 10 iterations, no scan, retry or polish, the
// object's pixels derived once before the descent) on the real motion between frames, without a mask.
TEST(DevRealTracking, AStartFromThePreviousFrameOnTheTrackBudgetStaysNear) {
  if (!fs::is_directory(kDevReal / "test" / kScene))
    GTEST_SKIP() << kDevReal.string() << " is not here: the real frames are not checked";
  const std::vector<nlohmann::json> results =
      evaluate_scene("--masks none --levels tracking --track-budget 4,10", "track_budget");
  for (const nlohmann::json& r : results)
    EXPECT_LT(r["error_mm"].get<double>(), 10.0)
        << "obj " << r["obj_id"] << " from " << r["error_init_mm"] << " mm";
  EXPECT_EQ(results.size(), 3u);
}
