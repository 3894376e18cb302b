// End to end: the dataset generator writes a BOP dataset, the evaluator generates perturbations with the paper's
// rule, refines them and scores them. Checks the files, the JSON lines and that refinement helps.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <unistd.h>

#include "diffdope/bop.hpp"
#include "diffdope/refiner.hpp"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() / ("diffdope_e2e_" + std::to_string(::getpid()) + "_" + std::to_string(rand()));
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

int run(const std::string& cmd) { return WEXITSTATUS(std::system(cmd.c_str())); }

}  // namespace

TEST(ToolsEndToEnd, GenerateDatasetPerturbAndEvaluate) {
  TempDir tmp;
  const std::string root = (tmp.path / "bop").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + root +
                " --scenes 3 --width 320 --height 240 --seed 5 2>/dev/null"), 0);
  // The files a BOP reader expects.
  for (const char* f : {"models/models_info.json", "models/obj_000001.ply", "models/obj_000001.png",
                        "test/000001/scene_camera.json", "test/000001/scene_gt.json", "test/000001/rgb/000000.png",
                        "test/000001/depth/000000.png", "test/000001/mask_visib/000000_000000.png"})
    EXPECT_TRUE(fs::exists(root + "/" + f)) << f;
  diffdope::BopDataset data(root, "test");
  EXPECT_EQ(data.scene_ids(), std::vector<int>({1, 2, 3}));
  EXPECT_TRUE(data.symmetric(2));
  EXPECT_FALSE(data.symmetric(1));
  const diffdope::BopImage img = data.image(1, 0);
  ASSERT_GE(img.gt.size(), 2u);
  const diffdope::Observation obs = data.observation(img, 0);
  EXPECT_GT(cv::countNonZero(obs.mask), 500);
  EXPECT_GT(cv::countNonZero(obs.depth), 320 * 240 / 2);

  const std::string cfg = (tmp.path / "small.yaml").string();
  std::ofstream(cfg) << "batch_size: 8\niterations: 40\nimage_scale: 1.0\n";
  const std::string pert = (tmp.path / "pert").string(), out = (tmp.path / "res.jsonl").string(),
                    summary = (tmp.path / "summary.json").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --perturbations " + pert +
                " --out " + out + " --generate 1 --seed 3 --config " + cfg + " --summary-json " + summary +
                " --levels medium,hard > /dev/null 2>&1"), 0);
  EXPECT_TRUE(fs::exists(pert + "/000001/scene_error_deg_040_trans_020.json"));
  const auto perts = diffdope::read_perturbations(pert + "/000002/scene_error_deg_010_trans_010.json");
  ASSERT_FALSE(perts.empty());

  std::ifstream in(out);
  std::set<std::string> levels;
  int lines = 0;
  for (std::string line; std::getline(in, line); ++lines) {
    const json j = json::parse(line);
    for (const char* key : {"scene_id", "im_id", "obj_id", "inst", "level", "sample", "R", "t", "init_R", "init_t",
                            "time_ms", "loss", "evaluations", "stage_evaluations"})
      EXPECT_TRUE(j.contains(key)) << key;
    EXPECT_EQ(j["R"].size(), 9u);
    long made = 0;  // the stages' evaluations add up to the result's
    for (const auto& [stage, n] : j["stage_evaluations"].items()) made += n.get<long>();
    EXPECT_EQ(made, j["evaluations"].get<long>());
    levels.insert(j["level"].get<std::string>());
  }
  EXPECT_GE(lines, 2 * 6);  // 2 levels x (3 scenes x >= 2 objects)
  EXPECT_EQ(levels, std::set<std::string>({"medium", "hard"}));
  const json s = json::parse(std::ifstream(summary));
  for (const char* level : {"medium", "hard", "all"}) ASSERT_TRUE(s.contains(level)) << level;
  EXPECT_GT(s["medium"]["auc_refined"].get<double>(), s["medium"]["auc_initial"].get<double>() + 10);
  EXPECT_GT(s["hard"]["auc_refined"].get<double>(), s["hard"]["auc_initial"].get<double>() + 20);
  // Every stage within its plan; the descent is where most evaluations go.
  ASSERT_EQ(s["stage_evaluations"].size(), size_t(diffdope::kRefineStages));
  for (const auto& [stage, e] : s["stage_evaluations"].items())
    EXPECT_LE(e["most"].get<long>(), e["planned"].get<long>()) << stage;
  EXPECT_GT(s["stage_evaluations"]["descent"]["mean"].get<double>(), 0.0);
}

TEST(ToolsEndToEnd, EvalReportsMissingDatasetClearly) {
  TempDir tmp;
  const std::string err = (tmp.path / "err.txt").string();
  EXPECT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop /nonexistent/bop --split test --perturbations /x --out " +
                (tmp.path / "o.jsonl").string() + " 2> " + err), 1);
  std::ifstream f(err);
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("/nonexistent/bop"), std::string::npos) << text;
  EXPECT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop x > /dev/null 2>&1"), 2);  // usage error
}

// One unusable scene (zero intrinsics) and one unusable sample (a mask of the wrong size) are named and skipped;
// the rest is scored and the exit code says that something was left out.
TEST(ToolsEndToEnd, EvalSkipsWhatItCannotUseAndScoresTheRest) {
  TempDir tmp;
  const std::string root = (tmp.path / "bop").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + root +
                " --scenes 3 --width 160 --height 120 --seed 5 2>/dev/null"), 0);
  const fs::path cams = fs::path(root) / "test/000001/scene_camera.json";
  json c = json::parse(std::ifstream(cams));
  c["0"]["cam_K"] = std::vector<double>(9, 0.0);
  std::ofstream(cams) << c.dump();
  cv::imwrite((fs::path(root) / "test/000002/mask_visib/000000_000000.png").string(), cv::Mat::zeros(10, 10, CV_8U));
  // An object id beyond int: named, not truncated to another id and scored.
  const fs::path gts = fs::path(root) / "test/000003/scene_gt.json";
  json g = json::parse(std::ifstream(gts));
  g["0"][0]["obj_id"] = 4294967297LL;
  std::ofstream(gts) << g.dump();
  const std::string cfg = (tmp.path / "small.yaml").string();
  std::ofstream(cfg) << "batch_size: 4\niterations: 10\n";
  const std::string out = (tmp.path / "res.jsonl").string(), err = (tmp.path / "err.txt").string();
  EXPECT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --perturbations " +
                (tmp.path / "pert").string() + " --out " + out + " --generate 1 --seed 3 --config " + cfg +
                " --levels easy > /dev/null 2> " + err),
            1);
  std::ifstream f(err);
  const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find(cams.string() + " (image 0): cam_K"), std::string::npos) << text;
  EXPECT_NE(text.find("scene 1 skipped"), std::string::npos) << text;
  EXPECT_NE(text.find("test/000002 (image 0, instance 0): mask: image is 10x10"), std::string::npos) << text;
  EXPECT_NE(text.find("obj_id 4294967297 is outside"), std::string::npos) << text;
  std::ifstream lines(out);
  int scored = 0;
  for (std::string line; std::getline(lines, line);) {
    EXPECT_EQ(json::parse(line)["scene_id"].get<int>(), 2);
    ++scored;
  }
  EXPECT_GE(scored, 1);  // scene 2's other objects
}

TEST(ToolsEndToEnd, GeneratorArgumentsAreCheckedNotThrown) {
  TempDir tmp;
  const std::string err = (tmp.path / "err.txt").string();
  for (const std::string flags : {"--width abc", "--scenes 99999999999", "--height 1e3", "--colour-offset 3",
                                  "--colour-offset 3,x", "--colour-offset 1000,0", "--colour-offset nan,0"}) {
    EXPECT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + (tmp.path / "d").string() + " " + flags +
                  " 2> " + err),
              2)
        << flags;
    std::ifstream f(err);
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find(flags.substr(0, flags.find(' '))), std::string::npos) << text;
  }
}

// --colour-offset: the colour image moved off depth and the masks as a camera's registration leaves it; depth,
// masks and ground truth are those of the registered set.
TEST(ToolsEndToEnd, GeneratorMovesTheColourImageOffDepth) {
  TempDir tmp;
  const std::string a = (tmp.path / "a").string(), b = (tmp.path / "b").string();
  const std::string common = " --scenes 1 --width 160 --height 120 --seed 7 2>/dev/null";
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + a + common), 0);
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + b + " --colour-offset 3,-2" + common), 0);
  const auto read = [](const std::string& root, const char* file) {
    return cv::imread(root + "/test/000001/" + file, cv::IMREAD_UNCHANGED);
  };
  for (const char* same : {"depth/000000.png", "mask_visib/000000_000000.png"})
    EXPECT_EQ(cv::norm(read(a, same), read(b, same), cv::NORM_INF), 0.0) << same;
  const cv::Mat ra = read(a, "rgb/000000.png"), rb = read(b, "rgb/000000.png");
  const cv::Rect inner(8, 8, 160 - 16, 120 - 16);
  EXPECT_GT(cv::norm(ra(inner), rb(inner), cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(ra(inner), rb(inner + cv::Point(3, -2)), cv::NORM_INF), 0.0);  // moved 3 right, 2 up
}

// An evaluation that evaluated nothing, or scored a symmetric object without knowing it is, must not
// look like a success.
TEST(ToolsEndToEnd, EvalFailsLoudlyWhenItCannotEvaluateEverything) {
  TempDir tmp;
  const std::string root = (tmp.path / "bop").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + root +
                " --scenes 1 --width 160 --height 120 --seed 5 2>/dev/null"), 0);
  const std::string cfg = (tmp.path / "tiny.yaml").string();
  std::ofstream(cfg) << "batch_size: 2\niterations: 2\nimage_scale: 1.0\n";
  const std::string err = (tmp.path / "err.txt").string();
  const auto eval = [&](const std::string& args) {
    return run(std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --out " +
               (tmp.path / "o.jsonl").string() + " --config " + cfg + " " + args + " > /dev/null 2> " + err);
  };
  const auto said = [&] {
    std::ifstream f(err);
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  };
  // No perturbation files at all.
  fs::create_directories(tmp.path / "empty");
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "empty").string()), 1);
  EXPECT_NE(said().find("nothing was evaluated: no perturbation files"), std::string::npos) << said();
  // A level that does not exist, numbers that are not numbers.
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --levels easy,bogus"), 2);
  EXPECT_NE(said().find("unknown level 'bogus'"), std::string::npos) << said();
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --max-samples 3x"), 2);
  EXPECT_NE(said().find("--max-samples: expected an integer, got '3x'"), std::string::npos) << said();
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --track-budget 8"), 2);
  EXPECT_NE(said().find("--track-budget: expected B,I"), std::string::npos) << said();
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --track-budget 8,x"), 2);
  EXPECT_NE(said().find("--track-budget I: expected an integer, got 'x'"), std::string::npos) << said();
  // Works, then a model goes missing: the samples of its object are skipped, said, and the exit status says so.
  ASSERT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --generate 1 --levels easy"), 0) << said();
  fs::rename(root + "/models/obj_000001.ply", root + "/models/obj_000001.ply.gone");
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --levels easy"), 1);
  EXPECT_NE(said().find("no model for obj 1"), std::string::npos) << said();
  EXPECT_NE(said().find("samples were skipped"), std::string::npos) << said();
  fs::rename(root + "/models/obj_000001.ply.gone", root + "/models/obj_000001.ply");
  // Without models_info.json the symmetric objects are unknown: an error, unless given another way.
  fs::rename(root + "/models/models_info.json", root + "/models/info.bak");
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --levels easy"), 1);
  EXPECT_NE(said().find("models_info.json: missing"), std::string::npos) << said();
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --levels easy --symmetric 2"), 0) << said();
  // A bad key in it is named.
  std::ofstream(root + "/models/models_info.json") << "{\"1\": {}, \"two\": {}}";
  EXPECT_EQ(eval("--perturbations " + (tmp.path / "p").string() + " --levels easy"), 1);
  EXPECT_NE(said().find("key 'two' is not an object id"), std::string::npos) << said();
}

// The ICP baseline (--method icp): on a generated dataset's easy starts it improves on them, with the mask and
// without one; it gives no verdict, and an unknown method is a usage error.
TEST(ToolsEndToEnd, IcpBaselineRefinesEasyStartsAndJudgesNothing) {
  TempDir tmp;
  const std::string root = (tmp.path / "bop").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + root +
                " --scenes 2 --width 320 --height 240 --seed 9 2>/dev/null"), 0);
  const std::string pert = (tmp.path / "pert").string();
  for (const char* masks : {"given", "none"}) {
    const std::string out = (tmp.path / (std::string(masks) + ".jsonl")).string(),
                      summary = (tmp.path / (std::string(masks) + ".json")).string();
    ASSERT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --perturbations " + pert +
                  " --out " + out + " --generate 1 --seed 4 --levels easy --method icp --masks " + masks +
                  " --summary-json " + summary + " > /dev/null 2>&1"), 0) << masks;
    const json s = json::parse(std::ifstream(summary));
    EXPECT_GT(s["easy"]["auc_refined"].get<double>(), s["easy"]["auc_initial"].get<double>() + 1) << masks;
    std::ifstream in(out);
    int lines = 0;
    for (std::string line; std::getline(in, line); ++lines) {
      const json j = json::parse(line);
      EXPECT_FALSE(j["plausible"].get<bool>());
      EXPECT_FALSE(j["judged"].get<bool>());
    }
    EXPECT_GE(lines, 4) << masks;
  }
  EXPECT_EQ(run(std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --perturbations " + pert +
                " --out " + (tmp.path / "x.jsonl").string() + " --method sgd > /dev/null 2>&1"), 2);
}

// --depth none drops the depth image, as a node with use_depth false: the results use no depth term and the
// pixels colour gives (the mask term), and have no depth scores; a bad mode, or ICP (depth only), is a usage error.
TEST(ToolsEndToEnd, EvalWithoutDepthRefinesFromColourAlone) {
  TempDir tmp;
  const std::string root = (tmp.path / "bop").string();
  ASSERT_EQ(run(std::string(DIFFDOPE_MAKE_DATASET_EXE) + " --out " + root +
                " --scenes 1 --width 320 --height 240 --seed 9 2>/dev/null"), 0);
  const std::string pert = (tmp.path / "pert").string(), out = (tmp.path / "colour.jsonl").string();
  const std::string eval = std::string(DIFFDOPE_EVAL_EXE) + " --bop " + root + " --split test --perturbations " + pert;
  ASSERT_EQ(run(eval + " --out " + out +
                " --generate 1 --seed 4 --levels easy --masks none --depth none > /dev/null 2>&1"), 0);
  std::ifstream in(out);
  int lines = 0;
  for (std::string line; std::getline(in, line); ++lines) {
    const json j = json::parse(line);
    EXPECT_EQ(j["terms"], json({"rgb", "mask"})) << line;
    EXPECT_EQ(j["depth_inliers"].get<double>(), -1.0);
  }
  EXPECT_GE(lines, 2);
  EXPECT_EQ(run(eval + " --out " + out + " --depth off > /dev/null 2>&1"), 2);
  EXPECT_EQ(run(eval + " --out " + out + " --depth none --method icp > /dev/null 2>&1"), 2);
}
