// Procedural textures: smooth sinusoid patterns, and printed-box labels (sharp-edged rectangles and discs over
// a pattern).
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "diffdope/procedural.hpp"

namespace diffdope {
namespace {

Texture from_mat(const cv::Mat& rgb32, const std::string& name) {
  Texture t;
  t.width = rgb32.cols;
  t.height = rgb32.rows;
  t.source = name;
  t.rgb.assign(rgb32.ptr<float>(0), rgb32.ptr<float>(0) + 3 * t.width * t.height);
  return t;
}

}  // namespace

Texture make_pattern_texture(int size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  cv::Mat img(size, size, CV_32FC3);
  float f[3][4], ph[3][4];
  for (int ch = 0; ch < 3; ++ch)
    for (int k = 0; k < 4; ++k) f[ch][k] = 1.f + 5.f * U(rng), ph[ch][k] = 6.283f * U(rng);
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const float u = (x + 0.5f) / size, v = (y + 0.5f) / size;
      cv::Vec3f px;
      for (int ch = 0; ch < 3; ++ch) {
        float s = 0.5f;
        s += 0.18f * std::sin(6.283f * f[ch][0] * u + ph[ch][0]);
        s += 0.18f * std::sin(6.283f * f[ch][1] * v + ph[ch][1]);
        s += 0.10f * std::sin(6.283f * (f[ch][2] * u + f[ch][3] * v) + ph[ch][2]);
        px[ch] = std::min(1.f, std::max(0.f, s));
      }
      img.at<cv::Vec3f>(y, x) = px;
    }
  }
  return from_mat(img, "pattern" + std::to_string(seed));
}

Texture make_label_texture(int size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  Texture base = make_pattern_texture(size, seed);
  cv::Mat img(size, size, CV_32FC3, base.rgb.data());
  img = img.clone();
  for (int i = 0; i < 12; ++i) {  // labels and stripes with sharp edges
    const cv::Scalar col(U(rng), U(rng), U(rng));
    const int x = static_cast<int>(U(rng) * size), y = static_cast<int>(U(rng) * size);
    const int w = static_cast<int>((0.05f + 0.2f * U(rng)) * size), h = static_cast<int>((0.03f + 0.1f * U(rng)) * size);
    cv::rectangle(img, cv::Rect(x, y, w, h), col, cv::FILLED);
  }
  for (int i = 0; i < 6; ++i) {
    const cv::Scalar col(U(rng), U(rng), U(rng));
    cv::circle(img, cv::Point(int(U(rng) * size), int(U(rng) * size)), int((0.03f + 0.08f * U(rng)) * size), col,
               cv::FILLED, cv::LINE_AA);
  }
  return from_mat(img, "label" + std::to_string(seed));
}

}  // namespace diffdope
