// Real camera frames in the loop: diffdope_eval on one scene of ../shared/data/dev_real (YCB-Video, an Asus
// Xtion: colour a few pixels off depth, holes and flying pixels at silhouettes) in the user's mask modes. Skipped,
// with the reason, where the data set is not beside the checkout (it is not part of the repository).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <unistd.h>

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

class DevReal : public ::testing::TestWithParam<const char*> {};

// From easy starts (1 deg, 1 mm) and from the previous frame's pose, a refinement must stay near the truth in every
// mask mode. Bound: 10 mm, which the mustard bottle broke by 63 mm when a turned flat render fit its lit,
// misregistered print by a lower loss.
TEST_P(DevReal, NoEasyOrTrackedStartEndsFar) {
  if (!fs::is_directory(kDevReal / "test" / kScene))
    GTEST_SKIP() << kDevReal.string() << " is not here: the real frames are not checked";
  const TempDir dir("diffdope_dev_real_" + std::to_string(::getpid()) + GetParam());
  const fs::path& tmp = dir.path;
  fs::create_directories(tmp / "perturbations" / kScene);
  for (const char* f : {"scene_error_deg_001_trans_001.json", "tracking.json"})
    fs::copy_file(kDevReal / "perturbations" / kScene / f, tmp / "perturbations" / kScene / f);
  const fs::path out = tmp / "results.jsonl";
  const std::string cmd = std::string(DIFFDOPE_EVAL_EXE) + " --bop " + kDevReal.string() + " --split test" +
                          " --perturbations " + (tmp / "perturbations").string() + " --out " + out.string() +
                          " --max-samples 2 --masks " + GetParam() + " > /dev/null 2>&1";
  ASSERT_EQ(WEXITSTATUS(std::system(cmd.c_str())), 0) << cmd;
  int results = 0;
  std::ifstream in(out);
  for (std::string line; std::getline(in, line);) {
    const auto r = nlohmann::json::parse(line);
    ++results;
    EXPECT_LT(r["error_mm"].get<double>(), 10.0)
        << GetParam() << ": obj " << r["obj_id"] << " " << r["level"] << " sample " << r["sample"] << " from "
        << r["error_init_mm"] << " mm";
  }
  EXPECT_EQ(results, 3 * 2 + 3);  // three objects: two easy starts each, one tracked
}

INSTANTIATE_TEST_SUITE_P(MaskModes, DevReal, ::testing::Values("given", "none", "box"),
                         [](const auto& info) { return std::string(info.param); });
