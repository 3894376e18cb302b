// An input image (rgb, depth or mask) as the tools and the BOP reader take it: the header's size check, then the
// decoder only when the header says the image is small (read_image_file). A crash, a hang or an allocation beyond
// the header's size is a finding; a refusal is not.
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>

#include "diffdope/image_file.hpp"
#include "fuzz_common.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = fuzz::write("image", std::string(reinterpret_cast<const char*>(data), size));
  // (A small pixel limit keeps each run fast; the checks are the same at any limit.)
  constexpr long long kMaxPixels = 1 << 20;
  for (const int flags : {int(cv::IMREAD_COLOR), int(cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR)}) {
    try {
      const cv::Mat m = diffdope::read_image_file(path, flags, "rgb", kMaxPixels);
      if (m.empty() || m.total() > size_t(kMaxPixels)) __builtin_trap();  // refused, or within the limit
    } catch (const std::runtime_error&) {
    }
  }
  return 0;
}
