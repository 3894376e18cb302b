// BOP files: part 1 scene_camera.json, part 2 scene_gt.json, part 3 models_info.json, part 4 a Diff-DOPE
// perturbation file. The scene's rgb image is a fixed valid one.
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "diffdope/bop.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace fs = std::filesystem;
  static const std::string root = [] {
    const std::string r = fuzz::folder() + "/bop";
    fs::create_directories(r + "/models");
    fs::create_directories(r + "/test/000001/rgb");
    cv::imwrite(r + "/test/000001/rgb/000000.png", cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)));
    return r;
  }();
  const std::vector<std::string> p = fuzz::parts(data, size, 4);
  fuzz::write("bop/test/000001/scene_camera.json", p[0]);
  fuzz::write("bop/test/000001/scene_gt.json", p[1]);
  fuzz::write("bop/models/models_info.json", p[2]);
  try {
    diffdope::BopDataset d(root, "test");
    d.image(1, 0);
  } catch (const std::runtime_error&) {
  }
  try {
    diffdope::read_perturbations(fuzz::write("scene_error_deg_010_trans_010.json", p[3]));
  } catch (const std::runtime_error&) {
  }
  return 0;
}
