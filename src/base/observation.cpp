#include "diffdope/observation.hpp"

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace diffdope {
namespace {

std::string type_name(const cv::Mat& m) {
  return cv::typeToString(m.type());
}

void check_size(const cv::Mat& m, const Camera& camera, const std::string& what) {
  if (m.empty()) return;
  if (m.cols != camera.width || m.rows != camera.height)
    throw std::invalid_argument(what + ": image is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                                " but the camera is " + std::to_string(camera.width) + "x" +
                                std::to_string(camera.height));
}

}  // namespace

void Observation::validate(const Camera& camera) const {
  camera.validate();
  if (has_rgb() && rgb.type() != CV_32FC3)
    throw std::invalid_argument("rgb: expected CV_32FC3 in [0,1], got " + type_name(rgb) + " (use to_rgb_float)");
  if (has_depth() && depth.type() != CV_32FC1)
    throw std::invalid_argument("depth: expected CV_32FC1 metres, got " + type_name(depth) +
                                " (use to_depth_metres)");
  if (has_mask() && mask.type() != CV_32FC1)
    throw std::invalid_argument("mask: expected CV_32FC1 in [0,1], got " + type_name(mask) + " (use to_mask_float)");
  check_size(rgb, camera, "rgb");
  check_size(depth, camera, "depth");
  if (has_edges() && edges.type() != CV_32FC1)
    throw std::invalid_argument("edges: expected CV_32FC1 in [0,1], got " + type_name(edges));
  check_size(mask, camera, "mask");
  check_size(edges, camera, "edges");
  if (has_texture() && texture.type() != CV_32FC2)
    throw std::invalid_argument("texture: expected CV_32FC2 (observed_texture()), got " + type_name(texture));
  check_size(texture, camera, "texture");
  if (box.width < 0 || box.height < 0 || (has_box() && (box & cv::Rect(0, 0, camera.width, camera.height)).empty()))
    throw std::invalid_argument("box: [" + std::to_string(box.x) + ", " + std::to_string(box.y) + ", " +
                                std::to_string(box.width) + ", " + std::to_string(box.height) +
                                "] (x, y, width, height) does not overlap the " + std::to_string(camera.width) + "x" +
                                std::to_string(camera.height) + " image");
  for (const cv::Mat* m : {&rgb, &depth, &mask, &edges, &texture})
    if (!m->empty() && !m->isContinuous())
      throw std::invalid_argument("observation images must be continuous in memory (clone() a sub-image)");
}

Observation Observation::resized(const Camera& cam) const {
  // Area averaging everywhere: nearest-neighbour picking would shift edges by half a source pixel (a
  // systematic pose bias). The mask becomes fractional at its border (S in [0, 1] is what the loss expects);
  // depth averages only the valid readings of each block.
  Observation out;
  const cv::Size size(cam.width, cam.height);
  if (has_box()) {
    const cv::Mat* any = has_rgb() ? &rgb : has_depth() ? &depth : has_mask() ? &mask : nullptr;
    if (!any) throw std::invalid_argument("Observation::resized: a box without an image to give its size");
    out.box = scaled_box(box, any->size(), size);
  }
  if (has_rgb()) cv::resize(rgb, out.rgb, size, 0, 0, cv::INTER_AREA);
  if (has_mask()) cv::resize(mask, out.mask, size, 0, 0, cv::INTER_AREA);
  if (has_edges()) cv::resize(edges, out.edges, size, 0, 0, cv::INTER_AREA);
  if (has_depth()) {
    cv::Mat valid = depth > 0.f, validf, sum, weight;
    valid.convertTo(validf, CV_32F, 1.0 / 255.0);
    cv::resize(depth.mul(validf), sum, size, 0, 0, cv::INTER_AREA);
    cv::resize(validf, weight, size, 0, 0, cv::INTER_AREA);
    out.depth = cv::Mat::zeros(size, CV_32F);
    const cv::Mat enough = weight >= 0.5f;  // a block needs at least half its area measured
    cv::Mat avg;
    cv::divide(sum, cv::max(weight, 1e-6), avg);
    avg.copyTo(out.depth, enough);
  }
  return out;
}

Observation Observation::with_mask(const cv::Mat& object_mask, const cv::Rect& object_box) const {
  Observation out = *this;
  out.mask = object_mask;
  out.box = object_box;
  return out;
}

cv::Rect scaled_box(const cv::Rect& box, const cv::Size& from, const cv::Size& to) {
  if (box.empty() || from.width <= 0 || from.height <= 0) return cv::Rect();
  const double sx = double(to.width) / from.width, sy = double(to.height) / from.height;
  const cv::Point a(int(std::floor(box.x * sx)), int(std::floor(box.y * sy)));
  const cv::Point b(int(std::ceil((box.x + box.width) * sx)), int(std::ceil((box.y + box.height) * sy)));
  return cv::Rect(a, b);
}

cv::Mat observed_edges(const cv::Mat& rgb_float, double low, double high, double sigma) {
  cv::Mat grey, grey8, canny, soft;
  cv::cvtColor(rgb_float, grey, cv::COLOR_RGB2GRAY);
  grey.convertTo(grey8, CV_8U, 255.0);
  cv::Canny(grey8, canny, low, high, 3, true);
  canny.convertTo(soft, CV_32F, 1.0 / 255.0);
  if (sigma > 0) {
    cv::GaussianBlur(soft, soft, cv::Size(0, 0), sigma);
    // A straight one-pixel line blurred by a Gaussian peaks at 1 / (sqrt(2 pi) sigma): rescale it to 1.
    soft *= std::sqrt(2 * M_PI) * sigma;
    cv::min(soft, 1.0, soft);
  }
  return soft;
}

cv::Mat observed_texture(const cv::Mat& rgb_float, double epsilon) {
  cv::Mat grey, log_grey, sx, sy, out;
  cv::transform(rgb_float, grey, cv::Matx13f(1.f / 3, 1.f / 3, 1.f / 3));
  cv::log(grey + epsilon, log_grey);
  // Zero outside the image, as the renderer's Sobel reads nothing outside its region.
  cv::Sobel(log_grey, sx, CV_32F, 1, 0, 3, 1, 0, cv::BORDER_CONSTANT);
  cv::Sobel(log_grey, sy, CV_32F, 0, 1, 3, 1, 0, cv::BORDER_CONSTANT);
  cv::merge(std::vector<cv::Mat>{sx, sy}, out);
  return out;
}

/// How far outside [0, 1] a float colour image may stray (rounding of a conversion) before it is refused.
constexpr double kFloatColourSlack = 0.01;

cv::Mat to_rgb_float(const cv::Mat& image, bool bgr, const std::string& what) {
  if (image.empty()) throw std::invalid_argument(what + ": empty image");
  cv::Mat f;
  const int depth = image.depth();
  double scale = 1.0;
  if (depth == CV_8U) scale = 1.0 / 255.0;
  else if (depth == CV_16U) scale = 1.0 / 65535.0;
  else if (depth != CV_32F && depth != CV_64F)
    throw std::invalid_argument(what + ": unsupported image type " + cv::typeToString(image.type()) +
                                " (expected 8-bit, 16-bit or float)");
  if (depth == CV_32F || depth == CV_64F) {
    // Float colour is [0, 1] by convention; a value far outside (or NaN) is a wrong image or unit, not light, and
    // would drag the pose anywhere. Rounding slightly beyond the range is clamped.
    cv::Mat flat = image.reshape(1);
    if (!cv::checkRange(flat))
      throw std::invalid_argument(what + ": the float image holds values that are not finite");
    double lo = 0, hi = 0;
    cv::minMaxLoc(flat, &lo, &hi);
    if (lo < -kFloatColourSlack || hi > 1.0 + kFloatColourSlack)
      throw std::invalid_argument(what + ": a float colour image must lie in [0, 1]; this one spans [" +
                                  std::to_string(lo) + ", " + std::to_string(hi) + "]");
  }
  image.convertTo(f, CV_MAKETYPE(CV_32F, image.channels()), scale);
  if (depth == CV_32F || depth == CV_64F) cv::min(cv::max(f, 0.0), 1.0, f);
  cv::Mat out;
  switch (image.channels()) {
    case 1: cv::cvtColor(f, out, cv::COLOR_GRAY2RGB); break;
    case 3: if (bgr) cv::cvtColor(f, out, cv::COLOR_BGR2RGB); else out = f; break;
    case 4: cv::cvtColor(f, out, bgr ? cv::COLOR_BGRA2RGB : cv::COLOR_RGBA2RGB); break;
    default:
      throw std::invalid_argument(what + ": unsupported channel count " + std::to_string(image.channels()));
  }
  return out;
}

cv::Mat to_depth_metres(const cv::Mat& depth, double metres_per_unit, const std::string& what) {
  if (depth.empty()) throw std::invalid_argument(what + ": empty image");
  if (depth.channels() != 1)
    throw std::invalid_argument(what + ": expected one channel, got " + cv::typeToString(depth.type()));
  if (!(metres_per_unit > 0)) throw std::invalid_argument(what + ": depth scale must be > 0");
  if (depth.depth() != CV_16U && depth.depth() != CV_32F && depth.depth() != CV_64F)
    throw std::invalid_argument(what + ": unsupported depth type " + cv::typeToString(depth.type()) +
                                " (expected 16UC1 or 32FC1)");
  cv::Mat out;
  depth.convertTo(out, CV_32F, metres_per_unit);
  for (int y = 0; y < out.rows; ++y) {
    float* row = out.ptr<float>(y);
    for (int x = 0; x < out.cols; ++x)
      if (!(std::isfinite(row[x]) && row[x] > 0.f)) row[x] = 0.f;
  }
  return out;
}

cv::Mat to_mask_float(const cv::Mat& mask, const std::string& what) {
  if (mask.empty()) throw std::invalid_argument(what + ": empty image");
  cv::Mat m = mask;
  if (m.channels() == 3 || m.channels() == 4) {
    // Colour masks: any nonzero channel counts as object.
    std::vector<cv::Mat> ch;
    cv::split(m, ch);
    m = ch[0].clone();
    for (size_t i = 1; i < std::min<size_t>(ch.size(), 3); ++i) cv::max(m, ch[i], m);
  } else if (m.channels() != 1) {
    throw std::invalid_argument(what + ": unsupported channel count " + std::to_string(m.channels()));
  }
  cv::Mat out;
  if (m.depth() == CV_8U || m.depth() == CV_16U || m.depth() == CV_32S) {
    cv::Mat nz = m != 0;
    nz.convertTo(out, CV_32F, 1.0 / 255.0);
  } else if (m.depth() == CV_32F || m.depth() == CV_64F) {
    m.convertTo(out, CV_32F);
    cv::patchNaNs(out, 0.0);
    cv::min(cv::max(out, 0.0), 1.0, out);
  } else {
    throw std::invalid_argument(what + ": unsupported mask type " + cv::typeToString(mask.type()));
  }
  return out;
}

}  // namespace diffdope
