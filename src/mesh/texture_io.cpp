// Textures of Mesh::load, decoded in the caller's process (not the import child) with their size checked first:
// image files and embedded images to RGB float textures, row 0 = top image row.
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "mesh/mesh_io_internal.hpp"

#include "diffdope/image_file.hpp"
#include "diffdope/input_limits.hpp"

namespace diffdope {
namespace mesh_io {

namespace fs = std::filesystem;

namespace {

// Converts an 8/16-bit or float BGR(A)/grey image to RGB floats in [0, 1], row 0 = top.
bool to_texture(const cv::Mat& in, Texture* tex) {
  if (in.empty() || in.cols <= 0 || in.rows <= 0) return false;
  cv::Mat img = in;
  if (img.channels() == 1) {
    cv::cvtColor(img, img, cv::COLOR_GRAY2BGR);
  } else if (img.channels() == 4) {
    cv::cvtColor(img, img, cv::COLOR_BGRA2BGR);
  } else if (img.channels() != 3) {
    return false;
  }
  double s = 1.0;
  switch (img.depth()) {
    case CV_8U: s = 1.0 / 255.0; break;
    case CV_16U: s = 1.0 / 65535.0; break;
    case CV_32F:
    case CV_64F: s = 1.0; break;
    default: return false;
  }
  cv::Mat f;
  img.convertTo(f, CV_32FC3, s);
  cv::cvtColor(f, f, cv::COLOR_BGR2RGB);
  tex->width = f.cols;
  tex->height = f.rows;
  tex->rgb.resize(static_cast<size_t>(3) * f.cols * f.rows);
  for (int y = 0; y < f.rows; ++y) {
    const float* row = f.ptr<float>(y);
    float* dst = tex->rgb.data() + static_cast<size_t>(3) * f.cols * y;
    for (int i = 0; i < 3 * f.cols; ++i) dst[i] = std::min(1.f, std::max(0.f, row[i]));  // HDR/float: clamp
  }
  return true;
}

constexpr int kImreadFlags = cv::IMREAD_ANYDEPTH | cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION;

}  // namespace

Texture decode_texture(const std::string& model, const TextureSource& src, const MeshLoadOptions& options) {
  const std::string name = src.file.empty() ? "embedded texture '" + src.ref + "'" : "texture '" + src.ref + "'";
  Texture tex;
  tex.source = src.file.empty() ? model + " (embedded texture " + src.ref + ")" : src.file;
  std::string bytes;
  long long w = src.raw_width, h = src.raw_height;
  if (src.raw_width <= 0) {
    if (!src.file.empty()) {
      std::error_code ec;
      const auto size = fs::file_size(src.file, ec);
      if (ec) fail(model, "cannot read " + name + " (" + src.file + ")");
      if (size > input_limits::kMaxImageFileBytes)
        fail(model, name + " is a file of more than " + std::to_string(input_limits::kMaxImageFileBytes >> 20) +
                        " MB (input_limits.hpp)");
      std::ifstream in(src.file, std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
      if (!in.good() && !in.eof()) fail(model, "cannot read " + name + " (" + src.file + ")");
    }
    const std::string& data = src.file.empty() ? src.embedded : bytes;
    if (!image_header_size(data, &w, &h)) w = h = 0;  // (other formats: checked after decoding)
  }
  const auto too_big = [&](long long pw, long long ph) {
    return pw * ph > options.max_texture_pixels;
  };
  if (too_big(w, h))
    fail(model, name + " is " + std::to_string(w) + " x " + std::to_string(h) + " pixels: more than the limit of " +
                    std::to_string(options.max_texture_pixels) + " (MeshLoadOptions::max_texture_pixels); downsample it");
  cv::Mat img;
  try {
    if (src.raw_width > 0) {
      img = cv::Mat(src.raw_height, src.raw_width, CV_8UC4, const_cast<char*>(src.embedded.data())).clone();
    } else {
      const std::string& data = src.file.empty() ? src.embedded : bytes;
      const cv::Mat buf(1, int(std::min<size_t>(data.size(), INT_MAX)), CV_8UC1, const_cast<char*>(data.data()));
      if (!data.empty()) img = cv::imdecode(buf, kImreadFlags);
    }
  } catch (const cv::Exception&) {
    img.release();
  }
  if (img.empty()) fail(model, "cannot " + std::string(src.file.empty() ? "decode " : "read ") + name +
                                   (src.file.empty() ? "" : " (" + src.file + ")"));
  if (too_big(img.cols, img.rows))
    fail(model, name + " is " + std::to_string(img.cols) + " x " + std::to_string(img.rows) +
                    " pixels: more than the limit (MeshLoadOptions::max_texture_pixels); downsample it");
  // The renderer samples mip levels; a texture beyond max_texture_size is only memory.
  const int longest = std::max(img.cols, img.rows);
  if (options.max_texture_size > 0 && longest > options.max_texture_size) {
    const double f = double(options.max_texture_size) / longest;
    cv::resize(img, img, cv::Size(std::max(1, int(std::lround(img.cols * f))), std::max(1, int(std::lround(img.rows * f)))),
               0, 0, cv::INTER_AREA);
  }
  if (!to_texture(img, &tex)) fail(model, "cannot read " + name + ": unsupported pixel format");
  return tex;
}

}  // namespace mesh_io
}  // namespace diffdope
