// Shared helpers of the command-line tools (tool_io.hpp).
#include "tool_io.hpp"

#include "diffdope/image_file.hpp"
#include "diffdope/input_limits.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace diffdope::tools {

[[noreturn]] void fail(const std::string& file, const std::string& what) { throw InputError(file, what); }

std::string strip_file_prefix(std::string msg, const std::string& file) {
  for (const std::string& p : {file + ": ", "Mesh::load('" + file + "'): "})
    if (msg.rfind(p, 0) == 0) msg = msg.substr(p.size());
  return msg;
}

std::string one_line(std::string s) {
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

QuietStderr::QuietStderr() {
  std::fflush(stderr);
  saved_ = dup(2);
  const int null = open("/dev/null", O_WRONLY);
  if (saved_ >= 0 && null >= 0) dup2(null, 2);
  if (null >= 0) close(null);
}

QuietStderr::~QuietStderr() {
  std::fflush(stderr);
  if (saved_ >= 0) {
    dup2(saved_, 2);
    close(saved_);
  }
}

void check_file(const std::string& path) { check_input_file(path); }

cv::Mat read_image(const std::string& path, int flags, const std::string& kind) {
  QuietStderr quiet;  // (decoders' warnings: the error says what matters)
  return read_image_file(path, flags, kind, input_limits::kMaxImagePixels);
}

std::string fmt(double v, const char* f) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string size_str(int w, int h) { return std::to_string(w) + "x" + std::to_string(h); }

void write_image(const std::string& path, const cv::Mat& img) {
  bool ok = false;
  try {
    ok = cv::imwrite(path, img);
  } catch (const std::exception& e) {
    fail(path, std::string("cannot write: ") + one_line(e.what()));
  }
  if (!ok) fail(path, "cannot write the image");
}

cv::Mat to_bgr8(const cv::Mat& rgb_float) {
  cv::Mat bgr;
  cv::cvtColor(rgb_float, bgr, cv::COLOR_RGB2BGR);
  bgr.convertTo(bgr, CV_8UC3, 255.0);
  return bgr;
}

void draw_render(cv::Mat& bgr8, const RenderImage& img, const cv::Scalar& colour, int thickness) {
  const double alpha = 0.35;
  for (int y = 0; y < bgr8.rows; ++y) {
    const float* cov = img.coverage.ptr<float>(y);
    const cv::Vec3f* col = img.color.ptr<cv::Vec3f>(y);
    cv::Vec3b* out = bgr8.ptr<cv::Vec3b>(y);
    for (int x = 0; x < bgr8.cols; ++x) {
      if (!(cov[x] > 0.5f)) continue;
      for (int c = 0; c < 3; ++c) {
        const double r = std::clamp(double(col[x][2 - c]) / cov[x], 0.0, 1.0) * 255.0;  // unpremultiply, RGB->BGR
        out[x][c] = cv::saturate_cast<uchar>((1 - alpha) * out[x][c] + alpha * r);
      }
    }
  }
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(cv::Mat(img.coverage >= 0.5f), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  cv::drawContours(bgr8, contours, -1, colour, thickness, cv::LINE_AA);
}

void put_label(cv::Mat& img, const std::string& text, cv::Point at, const cv::Scalar& colour, double scale) {
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(img, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
  if (!f) fail(path, "cannot write");
}

nlohmann::ordered_json pose_file_json(const Pose& p) {
  const auto q = p.quaternion_xyzw();
  return {{"t", {p.t.x(), p.t.y(), p.t.z()}}, {"quaternion", {q[0], q[1], q[2], q[3]}}};
}

}  // namespace diffdope::tools
