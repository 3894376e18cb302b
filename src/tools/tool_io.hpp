#pragma once
// What the command-line tools share: one-line errors naming the file, quiet image decoding, image writing and
// the render overlays (diffdope_refine, diffdope_calibrate).
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <string>

#include "diffdope/input_files.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope::tools {

/// An input that cannot be used: `file` is the file (or folder) to name in the message.
using InputError = InputFileError;

[[noreturn]] void fail(const std::string& file, const std::string& what);
/// Library messages often start with the file name already; drop that so the file is named once.
std::string strip_file_prefix(std::string msg, const std::string& file);
std::string one_line(std::string s);

/// Runs `f`, turning any exception into an InputError naming `file`.
template <typename F>
auto about(const std::string& file, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    fail(file, strip_file_prefix(e.what(), file));
  }
}

/// Silences stderr while alive: image decoders (libpng, libjpeg) and assimp print their own complaints about
/// corrupt files there, which would break our one-line error reports. The error itself is reported by us.
class QuietStderr {
 public:
  QuietStderr();
  ~QuietStderr();
  QuietStderr(const QuietStderr&) = delete;
  QuietStderr& operator=(const QuietStderr&) = delete;

 private:
  int saved_ = -1;
};

void check_file(const std::string& path);
/// The image at `path` (cv::imread `flags`, as stored: no EXIF rotation; at most input_limits::kMaxImagePixels,
/// checked before decoding); InputError naming the file when it cannot be used (read_image_file()).
cv::Mat read_image(const std::string& path, int flags, const std::string& kind);
std::string fmt(double v, const char* f = "%.6f");
std::string size_str(int w, int h);

void write_image(const std::string& path, const cv::Mat& img);
/// Writes `text` to `path`; fail() when it cannot.
void write_text(const std::string& path, const std::string& text);
/// A pose as read_pose_file() reads it: {"t": [3], "quaternion": [x, y, z, w]}.
nlohmann::ordered_json pose_file_json(const Pose& p);
cv::Mat to_bgr8(const cv::Mat& rgb_float);
/// Translucent render (colour where coverage > 0.5, alpha 0.35) and its outline in `colour`.
void draw_render(cv::Mat& bgr8, const RenderImage& img, const cv::Scalar& colour, int thickness);
void put_label(cv::Mat& img, const std::string& text, cv::Point at, const cv::Scalar& colour, double scale);

}  // namespace diffdope::tools
