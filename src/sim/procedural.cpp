#include "diffdope/procedural.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <queue>
#include <random>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

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

// ---------------------------------------------------------------------------------------------------------------
// make_scan_like: parametric parts -> jittered ring triangulation -> charts -> packed atlas -> painted texture.
// ---------------------------------------------------------------------------------------------------------------
namespace diffdope {
namespace {
namespace scan {

using V2 = Eigen::Vector2d;
using V3 = Eigen::Vector3d;
using Rgb = cv::Vec3f;  // RGB in [0, 1]
constexpr double kPi = 3.14159265358979323846;

double smoothstep(double a, double b, double x) {
  const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

/// Index and fraction where an increasing table reaches `value` (linear interpolation between entries).
double invert_table(const std::vector<double>& table, double value) {
  const auto it = std::lower_bound(table.begin(), table.end(), value);
  if (it == table.begin()) return 0.0;
  if (it == table.end()) return double(table.size() - 1);
  const size_t k = size_t(it - table.begin());
  const double a = table[k - 1], b = table[k];
  return double(k - 1) + (b > a ? (value - a) / (b - a) : 0.0);
}

/// A meridian (r, z) from the axis back to the axis, as a dense polyline parametrised by normalised arc length.
class Profile {
 public:
  void add(const V2& p) {
    if (p_.empty() || (p - p_.back()).norm() > 1e-12) p_.push_back(p);
  }
  void line(const V2& a, const V2& b, int n = 32) {
    for (int i = 0; i <= n; ++i) add(a + (b - a) * (double(i) / n));
  }
  void arc(const V2& c, double r, double a0, double a1, int n = 48) {
    for (int i = 0; i <= n; ++i) {
      const double a = a0 + (a1 - a0) * i / n;
      add(c + r * V2(std::cos(a), std::sin(a)));
    }
  }
  template <class F>
  void curve(F f, int n = 96) {
    for (int i = 0; i <= n; ++i) add(f(double(i) / n));
  }
  void finish() {
    s_.assign(p_.size(), 0.0);
    for (size_t i = 1; i < p_.size(); ++i) s_[i] = s_[i - 1] + (p_[i] - p_[i - 1]).norm();
  }
  V2 at(double t) const {
    const double k = invert_table(s_, std::clamp(t, 0.0, 1.0) * s_.back());
    const size_t i = std::min(size_t(k), p_.size() - 2);
    return p_[i] + (k - double(i)) * (p_[i + 1] - p_[i]);
  }

 private:
  std::vector<V2> p_;
  std::vector<double> s_;
};

/// Arc length of the closed curve (sx cos a, sy k(a) sin a) from a = -pi, tabulated (for wrapping labels).
class ArcTable {
 public:
  template <class K>
  ArcTable(double sx, double sy, K k) {
    s_.assign(kN + 1, 0.0);
    V2 prev(-sx, 0.0);
    for (int i = 1; i <= kN; ++i) {
      const double a = -kPi + 2 * kPi * i / kN;
      const V2 p(sx * std::cos(a), sy * k(a) * std::sin(a));
      s_[i] = s_[i - 1] + (p - prev).norm();
      prev = p;
    }
  }
  double operator()(double a) const {  // a in [-pi, pi]
    const double x = std::clamp((a + kPi) / (2 * kPi), 0.0, 1.0) * kN;
    const int i = std::min(int(x), kN - 1);
    return s_[i] + (x - i) * (s_[i + 1] - s_[i]);
  }

 private:
  static constexpr int kN = 1024;
  std::vector<double> s_;
};

// ---- Print: panels drawn with OpenCV (8-bit for antialiased text), sampled bilinearly in float ----

const Rgb kPalette[] = {{0.78f, 0.08f, 0.10f}, {0.97f, 0.80f, 0.12f}, {0.10f, 0.28f, 0.65f}, {0.12f, 0.52f, 0.22f},
                        {0.95f, 0.45f, 0.08f}, {0.42f, 0.18f, 0.55f}, {0.05f, 0.55f, 0.55f}, {0.45f, 0.27f, 0.12f},
                        {0.96f, 0.92f, 0.80f}, {0.95f, 0.95f, 0.93f}, {0.07f, 0.07f, 0.08f}, {0.92f, 0.45f, 0.60f}};
constexpr int kPaletteSize = int(sizeof(kPalette) / sizeof(kPalette[0]));
const char* const kWords[] = {"NOVA",  "ACME",      "PRIME", "SUNNY",  "ALPINE", "GOLDEN", "ROYAL", "MAPLE",
                              "ZESTY", "DIFF-DOPE", "ORBIT", "VELVET", "HARBOR", "COMET",  "FJORD", "LUMEN"};
const char* const kProducts[] = {"CLASSIC", "ORGANIC", "CRUNCH", "FRESH", "EXTRA", "ORIGINAL", "MILD", "DELUXE"};

float luminance(const Rgb& c) { return 0.3f * c[0] + 0.59f * c[1] + 0.11f * c[2]; }
cv::Scalar scalar(const Rgb& c) { return cv::Scalar(255.0 * c[0], 255.0 * c[1], 255.0 * c[2]); }
Rgb mix(const Rgb& a, const Rgb& b, float t) { return a * (1.f - t) + b * t; }

struct Brand {
  Rgb bg, bg2, accent, accent2, ink, light;
  std::string name, product;
};

Brand make_brand(std::mt19937& rng) {
  auto pick = [&](int avoid1, int avoid2) {
    for (;;) {
      const int i = int(rng() % kPaletteSize);
      if (i != avoid1 && i != avoid2) return i;
    }
  };
  Brand b;
  const int ibg = pick(-1, -1), iacc = pick(ibg, -1), iacc2 = pick(ibg, iacc);
  b.bg = kPalette[ibg];
  b.bg2 = mix(b.bg, luminance(b.bg) > 0.5f ? Rgb(0.55f, 0.5f, 0.45f) : Rgb(1.f, 1.f, 1.f), 0.25f);
  b.accent = kPalette[iacc];
  b.accent2 = kPalette[iacc2];
  b.ink = luminance(b.bg) > 0.45f ? Rgb(0.06f, 0.06f, 0.07f) : Rgb(0.97f, 0.97f, 0.95f);
  b.light = luminance(b.accent) > 0.45f ? Rgb(0.06f, 0.06f, 0.07f) : Rgb(0.98f, 0.98f, 0.96f);
  b.name = kWords[rng() % (sizeof(kWords) / sizeof(kWords[0]))];
  b.product = kProducts[rng() % (sizeof(kProducts) / sizeof(kProducts[0]))];
  return b;
}

/// Text scaled to fit max_w x max_h, centred at c (or starting at c.x when `left`).
void put_text_fit(cv::Mat& img, const std::string& s, cv::Point2d c, double max_w, double max_h, const Rgb& col,
                  int font, bool left = false) {
  int base = 0;
  const cv::Size sz = cv::getTextSize(s, font, 1.0, 1, &base);
  const double scale = std::min(max_w / std::max(1, sz.width), max_h / std::max(1, sz.height + base));
  if (scale * sz.height < 3.0) return;  // too small to draw
  const int thick = std::max(1, int(std::lround(scale * (font == cv::FONT_HERSHEY_DUPLEX ? 2.4 : 1.3))));
  const cv::Size s2 = cv::getTextSize(s, font, scale, thick, &base);
  const cv::Point org(int(left ? c.x : c.x - 0.5 * s2.width), int(c.y + 0.5 * s2.height));
  cv::putText(img, s, org, font, scale, scalar(col), thick, cv::LINE_AA);
}

std::string random_words(std::mt19937& rng, int letters) {
  std::string s;
  while (int(s.size()) < letters) {
    if (!s.empty()) s += ' ';
    const int n = 2 + int(rng() % 7);
    for (int i = 0; i < n; ++i) s += char('A' + rng() % 26);
  }
  return s;
}

void gradient(cv::Mat& img, const cv::Rect& r, const Rgb& top, const Rgb& bottom) {
  for (int y = r.y; y < r.y + r.height; ++y)
    img(cv::Rect(r.x, y, r.width, 1)).setTo(scalar(mix(top, bottom, float(y - r.y) / std::max(1, r.height - 1))));
}

enum class Design { Front, Back, Side, Plain };

/// One printed panel (a label, a box face, a band) inside rectangle r of `img` (CV_8UC3, RGB).
void draw_design(cv::Mat& img, const cv::Rect& r, Design design, const Brand& b, std::mt19937& rng) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double w = r.width, h = r.height, x0 = r.x, y0 = r.y;
  auto P = [&](double fx, double fy) { return cv::Point(int(x0 + fx * w), int(y0 + fy * h)); };
  gradient(img, r, b.bg2, b.bg);
  const int line = std::max(1, int(h / 150));
  if (design == Design::Front) {
    const double band_y = 0.58 + 0.06 * U(rng), band_h = 0.14 + 0.06 * U(rng);
    cv::rectangle(img, P(0, band_y), P(1, band_y + band_h), scalar(b.accent), cv::FILLED);
    cv::rectangle(img, P(0, band_y - 0.025), P(1, band_y - 0.025 + line / h), scalar(b.accent2), cv::FILLED);
    cv::rectangle(img, P(0, band_y + band_h + 0.015), P(1, band_y + band_h + 0.015 + 2 * line / h), scalar(b.accent2),
                  cv::FILLED);
    for (int i = 0; i < 5; ++i)  // decorative dots
      cv::circle(img, P(0.05 + 0.9 * U(rng), 0.04 + 0.1 * U(rng)), std::max(2, int((0.01 + 0.025 * U(rng)) * h)),
                 scalar(b.accent2), cv::FILLED, cv::LINE_AA);
    const double ax = std::min(0.36 * w, 0.55 * h), ay = 0.17 * h;
    const cv::Point c = P(0.5, 0.33);
    cv::ellipse(img, c, cv::Size(int(ax + 2 * line), int(ay + 2 * line)), 0, 0, 360, scalar(b.ink), cv::FILLED,
                cv::LINE_AA);
    cv::ellipse(img, c, cv::Size(int(ax), int(ay)), 0, 0, 360, scalar(b.accent2), cv::FILLED, cv::LINE_AA);
    put_text_fit(img, b.name, c, 1.55 * ax, 1.0 * ay,
                 luminance(b.accent2) > 0.45f ? Rgb(0.05f, 0.05f, 0.05f) : Rgb(1, 1, 1), cv::FONT_HERSHEY_DUPLEX);
    put_text_fit(img, b.product, P(0.5, band_y + 0.5 * band_h), 0.85 * w, 0.7 * band_h * h, b.light,
                 cv::FONT_HERSHEY_DUPLEX);
    put_text_fit(img, "NET WT " + std::to_string(100 + rng() % 900) + " g", P(0.5, 0.91), 0.45 * w, 0.05 * h, b.ink,
                 cv::FONT_HERSHEY_SIMPLEX);
  } else if (design == Design::Back) {
    put_text_fit(img, b.name, P(0.5, 0.09), 0.6 * w, 0.09 * h, b.accent, cv::FONT_HERSHEY_DUPLEX);
    const double lh = 0.034;
    int base = 0;
    const double fs = lh * h / std::max(1, cv::getTextSize("A", cv::FONT_HERSHEY_SIMPLEX, 1.0, 1, &base).height);
    for (double y = 0.2; y < 0.66; y += 1.6 * lh) {
      std::string s = random_words(rng, 6 + int(rng() % 30));
      while (s.size() > 4 && cv::getTextSize(s, cv::FONT_HERSHEY_SIMPLEX, fs, 1, &base).width > 0.54 * w) s.pop_back();
      cv::putText(img, s, P(0.06, y + lh), cv::FONT_HERSHEY_SIMPLEX, fs, scalar(b.ink), std::max(1, int(fs)),
                  cv::LINE_AA);
    }
    cv::rectangle(img, P(0.64, 0.2), P(0.94, 0.64), scalar(Rgb(0.97f, 0.97f, 0.95f)), cv::FILLED);  // facts table
    cv::rectangle(img, P(0.64, 0.2), P(0.94, 0.64), scalar(Rgb(0.05f, 0.05f, 0.05f)), line);
    for (double y = 0.26; y < 0.63; y += 0.045) {
      cv::line(img, P(0.65, y), P(0.93, y), scalar(Rgb(0.05f, 0.05f, 0.05f)), line);
      put_text_fit(img, random_words(rng, 5), P(0.66, y - 0.022), 0.17 * w, 0.028 * h, Rgb(0.05f, 0.05f, 0.05f),
                   cv::FONT_HERSHEY_SIMPLEX, true);
    }
    cv::rectangle(img, P(0.08, 0.72), P(0.5, 0.94), scalar(Rgb(0.98f, 0.98f, 0.98f)), cv::FILLED);  // barcode
    const double unit = std::max(1.0, 0.004 * w);
    double x = x0 + 0.1 * w;
    for (int bar = 0; x < x0 + 0.48 * w; ++bar) {
      const double bw = unit * double(1 + rng() % 3);
      if (bar % 2 == 0)
        cv::rectangle(img, cv::Point(int(x), int(y0 + 0.74 * h)), cv::Point(int(x + bw) - 1, int(y0 + 0.88 * h)),
                      scalar(Rgb(0.02f, 0.02f, 0.02f)), cv::FILLED);
      x += bw;
    }
    std::string digits;
    for (int i = 0; i < 12; ++i) digits += char('0' + rng() % 10);
    put_text_fit(img, digits, P(0.29, 0.91), 0.38 * w, 0.035 * h, Rgb(0.02f, 0.02f, 0.02f), cv::FONT_HERSHEY_SIMPLEX);
    cv::circle(img, P(0.75, 0.83), std::max(3, int(0.06 * std::min(w, h))), scalar(b.ink), 2 * line, cv::LINE_AA);
  } else if (design == Design::Side) {
    for (int i = 0; i < 3; ++i) {
      const double y = 0.08 + 0.3 * i + 0.05 * U(rng);
      cv::rectangle(img, P(0, y), P(1, y + 0.06), scalar(i == 1 ? b.accent2 : b.accent), cv::FILLED);
    }
    put_text_fit(img, b.name, P(0.5, 0.28), 0.8 * w, 0.08 * h, b.ink, cv::FONT_HERSHEY_DUPLEX);
    cv::circle(img, P(0.5, 0.5), std::max(3, int(0.2 * std::min(w, h))), scalar(b.accent2), cv::FILLED, cv::LINE_AA);
    for (double y = 0.7; y < 0.95; y += 0.05)
      put_text_fit(img, random_words(rng, 10), P(0.08, y), 0.84 * w, 0.025 * h, b.ink, cv::FONT_HERSHEY_SIMPLEX, true);
  } else {
    put_text_fit(img, b.name, P(0.5, 0.3), 0.5 * w, 0.16 * h, b.accent, cv::FONT_HERSHEY_DUPLEX);
    for (double x = 0.05; x < 0.95; x += 0.04) cv::line(img, P(x, 0.55), P(x + 0.02, 0.55), scalar(b.ink), line);
    put_text_fit(img, "OPEN HERE", P(0.5, 0.65), 0.3 * w, 0.07 * h, b.ink, cv::FONT_HERSHEY_SIMPLEX);
    put_text_fit(img, random_words(rng, 24), P(0.5, 0.85), 0.8 * w, 0.05 * h, b.ink, cv::FONT_HERSHEY_SIMPLEX);
  }
}

/// A printed area on the object, sampled at (s, t) in [0, 1]^2: s left to right, t bottom to top as seen from
/// outside with the object upright.
class Panel {
 public:
  Panel() = default;
  Panel(const cv::Mat& rgb8) { rgb8.convertTo(img_, CV_32FC3, 1.0 / 255.0); }
  Rgb sample(double s, double t) const {
    const float x = std::clamp(float(s * img_.cols - 0.5), 0.f, float(img_.cols - 1));
    const float y = std::clamp(float((1.0 - t) * img_.rows - 0.5), 0.f, float(img_.rows - 1));
    const int x0 = std::min(int(x), img_.cols - 2), y0 = std::min(int(y), img_.rows - 2);
    const float fx = x - x0, fy = y - y0;
    const Rgb* r0 = img_.ptr<Rgb>(y0) + x0;
    const Rgb* r1 = img_.ptr<Rgb>(y0 + 1) + x0;
    return (r0[0] * (1 - fx) + r0[1] * fx) * (1 - fy) + (r1[0] * (1 - fx) + r1[1] * fx) * fy;
  }

 private:
  cv::Mat img_;
};

/// Panel pixel size for a printed area of w x h metres at `px_per_m`.
cv::Size panel_size(double w, double h, double px_per_m) {
  return cv::Size(std::max(16, int(std::lround(w * px_per_m))), std::max(16, int(std::lround(h * px_per_m))));
}

Panel make_panel(cv::Size size, Design design, const Brand& b, std::mt19937& rng) {
  cv::Mat img(size, CV_8UC3);
  draw_design(img, cv::Rect(0, 0, size.width, size.height), design, b, rng);
  return Panel(img);
}

// ---- Shapes ----

/// An object made of closed parametric parts: part(u, v) with u periodic in [0, 1) and poles at v = 0 and 1
/// (the point does not depend on u there), in the shape's natural frame; and its print.
class ShapeModel {
 public:
  virtual ~ShapeModel() = default;
  virtual const char* name() const = 0;
  virtual int parts() const = 0;
  virtual V3 surface(int part, double u, double v) const = 0;
  /// Draws the print once the metres per natural unit along each axis are known.
  virtual void prepare_print(const V3& scale, int texture_size, std::mt19937& rng) = 0;
  /// Colour of the surface point p (natural frame) of `part`.
  virtual Rgb colour(int part, const V3& p) const = 0;
};

class Bottle : public ShapeModel {
 public:
  Bottle() {
    prof_.curve([](double t) { return V2(t * (kRb - kRbot), 0.012 * (1 - t * t)); }, 48);  // bottom with a punt
    prof_.arc(V2(kRb - kRbot, kRbot), kRbot, -0.5 * kPi, 0.0);
    prof_.curve([](double t) { return V2(kRb * (1 - 0.035 * std::sin(kPi * t)), kRbot + t * (kZs - kRbot)); });
    prof_.curve([](double t) { return V2(kRn + (kRb - kRn) * 0.5 * (1 + std::cos(kPi * t)), kZs + t * (kZn - kZs)); });
    prof_.line(V2(kRn, kZn), V2(kRn, kZc0), 8);
    prof_.line(V2(kRn, kZc0), V2(kRc, kZc0), 8);  // underside of the cap
    prof_.line(V2(kRc, kZc0), V2(kRc, kZc1), 24);
    prof_.arc(V2(kRc - kRt, kZc1), kRt, 0.0, 0.5 * kPi, 16);
    prof_.line(V2(kRc - kRt, 1.0), V2(0.0, 1.0), 24);
    prof_.finish();
  }
  const char* name() const override { return "scan_like_bottle"; }
  int parts() const override { return 1; }
  V3 surface(int, double u, double v) const override {
    const V2 rz = prof_.at(v);
    const double a = 2 * kPi * u - kPi;
    return V3(cx(rz.y()) + rz.x() * std::cos(a), rz.x() * k(a, rz.y()) * std::sin(a), rz.y());
  }
  void prepare_print(const V3& scale, int n, std::mt19937& rng) override {
    arc_ = std::make_unique<ArcTable>(scale.x(), scale.y(), [](double a) { return k(a, 0.0); });
    const double width = kRb * ((*arc_)(0.9 * kPi) - (*arc_)(0.1 * kPi)), height = (kZl1 - kZl0) * scale.z();
    const double px_per_m = 0.5 * n / std::max(width, height);
    const Brand b = make_brand(rng);
    front_ = make_panel(panel_size(width, height, px_per_m), Design::Front, b, rng);
    back_ = make_panel(panel_size(width, height, px_per_m), Design::Back, b, rng);
    int ip = 0, ic = 0;
    do ip = int(rng() % kPaletteSize);  // a bottle that stands out from its labels
    while (cv::norm(kPalette[ip] - b.bg) < 0.4);
    do ic = int(rng() % kPaletteSize);
    while (ic == ip);
    plastic_ = mix(kPalette[ip], Rgb(0.9f, 0.9f, 0.9f), 0.15f);
    cap_ = kPalette[ic];
  }
  Rgb colour(int, const V3& p) const override {
    const double z = p.z(), dx = p.x() - cx(z);
    const double a0 = std::atan2(p.y() * (1 / 0.62), dx), a = std::atan2(p.y() / k(a0, z), dx);  // ~ inverts k
    if (z > kZc0 - 1e-4) {  // cap: ribbed side, ring on top
      const double rib = 0.5 + 0.5 * std::cos(48 * a);
      if (z < kZc1) return cap_ * float(0.8 + 0.2 * rib * rib);
      const double rr = std::hypot(dx, p.y());
      return cap_ * float(rr > 0.045 && rr < 0.055 ? 0.7 : 1.0);
    }
    if (z > kZn - 1e-4) return plastic_ * float(0.85 + 0.1 * std::cos(2 * kPi * z / 0.01));  // neck thread
    if (z > kZl0 && z < kZl1) {
      const double t = (z - kZl0) / (kZl1 - kZl0);
      if (a > 0.1 * kPi && a < 0.9 * kPi)
        return front_.sample(((*arc_)(a) - (*arc_)(0.1 * kPi)) / ((*arc_)(0.9 * kPi) - (*arc_)(0.1 * kPi)), t);
      if (a > -0.9 * kPi && a < -0.1 * kPi)
        return back_.sample(((*arc_)(a) - (*arc_)(-0.9 * kPi)) / ((*arc_)(-0.1 * kPi) - (*arc_)(-0.9 * kPi)), t);
    }
    if (z < 0.0125) {  // bottom: moulded rings
      const double rr = std::hypot(dx, p.y() / 0.62);
      return plastic_ * float(rr > 0.1 && rr < 0.11 ? 0.7 : 0.82);
    }
    return plastic_ * float(0.9 + 0.1 * z);
  }

 private:
  static constexpr double kRb = 0.24, kRbot = 0.05, kZs = 0.60, kZn = 0.80, kZc0 = 0.84, kRn = 0.075, kRc = 0.095,
                          kZc1 = 0.985, kRt = 0.015, kZl0 = 0.14, kZl1 = 0.56;
  /// Cross-section: elliptical body slightly fuller on +y, round from the shoulder up; neck offset towards +x.
  static double k(double a, double z) {
    const double b = smoothstep(0.62, kZn, z);
    return (1 - b) * (0.62 + 0.05 * std::sin(a)) + b;
  }
  static double cx(double z) { return 0.075 * smoothstep(kZs, kZn, z); }
  Profile prof_;
  std::unique_ptr<ArcTable> arc_;
  Panel front_, back_;
  Rgb plastic_, cap_;
};

class Mug : public ShapeModel {
 public:
  Mug() {
    prof_.curve([](double t) { return V2(t * (kRo - kRf), 0.006 * (1 - t * t)); }, 48);
    prof_.arc(V2(kRo - kRf, kRf), kRf, -0.5 * kPi, 0.0, 16);
    prof_.line(V2(kRo, kRf), V2(kRo, 1 - 0.5 * kW), 64);
    prof_.arc(V2(kRo - 0.5 * kW, 1 - 0.5 * kW), 0.5 * kW, 0.0, kPi, 24);  // rim
    prof_.line(V2(kRi, 1 - 0.5 * kW), V2(kRi, kTb + kRfi), 64);
    prof_.arc(V2(kRi - kRfi, kTb + kRfi), kRfi, 0.0, -0.5 * kPi, 16);
    prof_.line(V2(kRi - kRfi, kTb), V2(0.0, kTb), 48);
    prof_.finish();
  }
  const char* name() const override { return "scan_like_mug"; }
  int parts() const override { return 2; }
  V3 surface(int part, double u, double v) const override {
    const double a = 2 * kPi * u;
    if (part == 0) {
      const V2 rz = prof_.at(v);
      return V3(rz.x() * std::cos(a), rz.x() * std::sin(a), rz.y());
    }
    // Handle: a flat tube along a half ellipse in the xz plane, its ends (poles) inside the wall.
    const double th = kPi * v;
    const V3 c(kXc + kAx * std::sin(th), 0.0, kZc + kAz * std::cos(th));
    const V3 t = V3(kAx * std::cos(th), 0.0, -kAz * std::sin(th)).normalized();
    const V3 n(-t.z(), 0.0, t.x());
    const double d = kAx * std::min(th, kPi - th),
                 e = d < kLc ? std::sqrt(std::max(0.0, 1 - std::pow(1 - d / kLc, 2))) : 1.0;
    return c + e * (kHandleA * std::cos(a) * n + kHandleB * std::sin(a) * V3(0, 1, 0));
  }
  void prepare_print(const V3& scale, int n, std::mt19937& rng) override {
    arc_ = std::make_unique<ArcTable>(scale.x(), scale.y(), [](double) { return 1.0; });
    const double width = kRo * ((*arc_)(kBand) - (*arc_)(-kBand)), height = (kZb1 - kZb0) * scale.z();
    const double px_per_m = 0.9 * n / std::max(width, height);
    const Brand b = make_brand(rng);
    const cv::Size sz = panel_size(width, height, px_per_m);
    cv::Mat img(sz, CV_8UC3);
    const int side = sz.width / 4;  // printed sides around a front motif opposite the handle
    draw_design(img, cv::Rect(0, 0, side, sz.height), Design::Side, b, rng);
    draw_design(img, cv::Rect(side, 0, sz.width - 2 * side, sz.height), Design::Front, b, rng);
    draw_design(img, cv::Rect(sz.width - side, 0, side, sz.height), Design::Side, b, rng);
    band_ = Panel(img);
    glaze_ = kPalette[rng() % kPaletteSize];
    inner_ = rng() % 2 ? glaze_ : Rgb(0.95f, 0.94f, 0.9f);
  }
  Rgb colour(int part, const V3& p) const override {
    if (part == 1) return glaze_;
    const double r = std::hypot(p.x(), p.y()), z = p.z();
    if (z < 0.0065 && r < kRo - kRf) return Rgb(0.76f, 0.68f, 0.58f) * float(r > 0.3 && r < 0.32 ? 0.85 : 1.0);
    if (r < kRi + 0.5 * kW && z > 0.5 * kTb && z < 1 - 0.5 * kW) return inner_;
    if (r > kRi + 0.5 * kW && z > kZb0 && z < kZb1) {
      // Angle from the side opposite the handle (-x): the band spans +-kBand around it.
      const double a = std::atan2(-p.y(), -p.x());
      if (std::fabs(a) < kBand)
        return band_.sample(((*arc_)(a) - (*arc_)(-kBand)) / ((*arc_)(kBand) - (*arc_)(-kBand)),
                            (z - kZb0) / (kZb1 - kZb0));
    }
    return glaze_;
  }

 private:
  static constexpr double kRo = 0.42, kW = 0.06, kRi = kRo - kW, kTb = 0.07, kRf = 0.04, kRfi = 0.06;
  static constexpr double kXc = kRo - 0.5 * kW, kZc = 0.53, kAx = 0.27, kAz = 0.29, kHandleA = 0.05, kHandleB = 0.08,
                          kLc = 0.45 * kW;
  static constexpr double kZb0 = 0.2, kZb1 = 0.84, kBand = 0.72 * kPi;
  Profile prof_;
  std::unique_ptr<ArcTable> arc_;
  Panel band_;
  Rgb glaze_, inner_;
};

class Box : public ShapeModel {
 public:
  const char* name() const override { return "scan_like_box"; }
  int parts() const override { return 1; }
  V3 surface(int, double u, double v) const override {
    // Superellipsoid |x|^n + |y|^n + |z|^n = 1 along the ray of polar angles (u, v): a box with rounded edges.
    const double a = 2 * kPi * u, e = kPi * (1 - v);
    const V3 d(std::cos(a) * std::sin(e), std::sin(a) * std::sin(e), std::cos(e));
    const double f = std::pow(std::fabs(d.x()), kN) + std::pow(std::fabs(d.y()), kN) + std::pow(std::fabs(d.z()), kN);
    return d * std::pow(f, -1.0 / kN);
  }
  void prepare_print(const V3& scale, int n, std::mt19937& rng) override {
    const V3 s = 2 * scale;  // metres per face (natural half size 1)
    const double px_per_m = 0.45 * n / s.maxCoeff();
    const Brand b = make_brand(rng);
    panels_[0] = make_panel(panel_size(s.x(), s.z(), px_per_m), Design::Front, b, rng);  // +y
    panels_[1] = make_panel(panel_size(s.x(), s.z(), px_per_m), Design::Back, b, rng);   // -y
    panels_[2] = make_panel(panel_size(s.y(), s.z(), px_per_m), Design::Side, b, rng);   // +x
    panels_[3] = make_panel(panel_size(s.y(), s.z(), px_per_m), Design::Side, b, rng);   // -x
    panels_[4] = make_panel(panel_size(s.x(), s.y(), px_per_m), Design::Plain, b, rng);  // +z
    panels_[5] = make_panel(panel_size(s.x(), s.y(), px_per_m), Design::Plain, b, rng);  // -z
  }
  Rgb colour(int, const V3& p) const override {
    const double ax = std::fabs(p.x()), ay = std::fabs(p.y()), az = std::fabs(p.z());
    auto st = [](double s, double t) { return std::make_pair(0.5 * (s + 1), 0.5 * (t + 1)); };
    std::pair<double, double> c;
    int f;
    if (ay >= ax && ay >= az) {
      f = p.y() > 0 ? 0 : 1;
      c = st(p.y() > 0 ? -p.x() : p.x(), p.z());
    } else if (ax >= az) {
      f = p.x() > 0 ? 2 : 3;
      c = st(p.x() > 0 ? p.y() : -p.y(), p.z());
    } else {
      f = p.z() > 0 ? 4 : 5;
      c = st(p.z() > 0 ? p.x() : -p.x(), p.y());
    }
    return panels_[f].sample(c.first, c.second);
  }

 private:
  static constexpr double kN = 24;
  Panel panels_[6];
};

// ---- Triangulation ----

/// Edge-length multiplier in [0.71, 1.41], smooth over the object: triangle areas vary about 1:4.
struct Density {
  V3 k[3];
  double phase[3];
  double operator()(const V3& p) const {
    double n = 0;
    for (int i = 0; i < 3; ++i) n += std::sin(k[i].dot(p) + phase[i]);
    return std::exp2(0.5 * std::clamp(n / 1.5, -1.0, 1.0));
  }
};

struct Soup {
  std::vector<V3> pos;  // final frame
  std::vector<V3> nat;  // natural frame (for the print)
  std::vector<int> tri;
  std::vector<int> tri_part;
};

/// One closed part sampled ring by ring: rings every ~h (arc length along v, mean over u), ~h apart along each
/// ring, h = h0 * density; random ring phases, jittered vertices, rings stitched greedily by u.
class PartSampler {
 public:
  PartSampler(const ShapeModel& model, int part, std::function<V3(const V3&)> to_final, const Density& density)
      : model_(model), part_(part), to_final_(std::move(to_final)) {
    grid_.resize(size_t(kNV + 1) * kNU);
    rho_.resize(grid_.size());
    for (int k = 0; k <= kNV; ++k)
      for (int i = 0; i < kNU; ++i) {
        grid_[k * kNU + i] = to_final_(model_.surface(part_, double(i) / kNU, double(k) / kNV));
        rho_[k * kNU + i] = density(grid_[k * kNU + i]);
      }
    sigma_.assign(kNV + 1, 0.0);
    area_ = 0;
    for (int k = 1; k <= kNV; ++k) {
      double sum = 0;
      for (int i = 0; i < kNU; ++i) {
        const int a = (k - 1) * kNU + i, b = k * kNU + i, c = (k - 1) * kNU + (i + 1) % kNU;
        const double r = 0.5 * (rho_[a] + rho_[b]);
        sum += (grid_[b] - grid_[a]).norm() / r;
        area_ += (grid_[b] - grid_[a]).cross(grid_[c] - grid_[a]).norm() / (r * r);
      }
      sigma_[k] = sigma_[k - 1] + sum / kNU;
    }
  }
  /// Density-weighted area (metres^2 / density^2): about h0^2 / 2 per triangle.
  double weighted_area() const { return area_; }

  /// Triangle count for edge length h0; appends the part to `out` when non-null (same result either way).
  int build(double h0, uint32_t seed, Soup* out) const {
    std::mt19937 rng(seed * 2654435761u + uint32_t(part_) * 40503u + 12345u);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    const double total = sigma_[kNV];
    const int m = std::max(2, int(std::lround(total / h0)));
    std::vector<double> ring_v(m + 1, 0.0);
    ring_v[m] = 1.0;
    for (int j = 1; j < m; ++j) ring_v[j] = invert_table(sigma_, (j + 0.4 * (U(rng) - 0.5)) * total / m) / kNV;
    const int base = out ? int(out->pos.size()) : 0;
    int next = base;
    auto add_vertex = [&](double u, double v) {
      if (out) {
        const V3 nat = model_.surface(part_, u - std::floor(u), v);
        out->nat.push_back(nat);
        out->pos.push_back(to_final_(nat));
      }
      return next++;
    };
    auto add_tri = [&](int a, int b, int c) {
      if (!out) return;
      out->tri.insert(out->tri.end(), {a, b, c});
      out->tri_part.push_back(part_);
    };
    struct Ring {
      std::vector<int> idx;
      std::vector<double> u;  // ascending, in [0, 1)
    };
    int triangles = 0;
    const int pole0 = add_vertex(0.0, 0.0);
    Ring prev;
    std::vector<double> tau(kNU + 1);
    for (int j = 1; j < m; ++j) {
      const double v = ring_v[j], dv = std::min(ring_v[j + 1] - v, v - ring_v[j - 1]);
      const int k = std::min(kNV - 1, int(v * kNV));
      const double f = v * kNV - k;
      auto at = [&](int i) { return (1 - f) * grid_[k * kNU + i % kNU] + f * grid_[(k + 1) * kNU + i % kNU]; };
      auto rho = [&](int i) { return (1 - f) * rho_[k * kNU + i % kNU] + f * rho_[(k + 1) * kNU + i % kNU]; };
      tau[0] = 0;
      for (int i = 0; i < kNU; ++i) tau[i + 1] = tau[i] + (at(i + 1) - at(i)).norm() / (0.5 * (rho(i) + rho(i + 1)));
      const double T = tau[kNU];
      const int n = std::max(3, int(std::lround(T / h0)));
      const double phase = U(rng);
      std::vector<std::pair<double, int>> verts(n);
      for (int i = 0; i < n; ++i) {
        double x = (i + phase + 0.6 * (U(rng) - 0.5)) * T / n;
        const double wrap = std::floor(x / T);
        x -= wrap * T;
        double u = invert_table(tau, x) / kNU;
        u -= std::floor(u);
        const double vi = v + 0.4 * (U(rng) - 0.5) * dv;
        verts[i] = {u, add_vertex(u, vi)};
      }
      std::sort(verts.begin(), verts.end());
      Ring ring;
      for (const auto& [u, id] : verts) ring.u.push_back(u), ring.idx.push_back(id);
      triangles += 2 * n;
      if (j == 1) {
        for (int i = 0; i < n; ++i) add_tri(pole0, ring.idx[(i + 1) % n], ring.idx[i]);
      } else {
        stitch(prev, ring, add_tri);
      }
      prev = std::move(ring);
    }
    const int pole1 = add_vertex(0.0, 1.0);
    const int n = int(prev.idx.size());
    for (int i = 0; i < n; ++i) add_tri(prev.idx[i], prev.idx[(i + 1) % n], pole1);
    return triangles;
  }

 private:
  /// Triangles between ring a (lower v) and ring b, counter-clockwise in (u, v).
  template <class Ring, class AddTri>
  static void stitch(const Ring& a, const Ring& b, AddTri& add_tri) {
    const int na = int(a.u.size()), nb = int(b.u.size());
    int b0 = 0;  // b's vertex nearest (cyclically) to a's first
    double best = 2;
    for (int k = 0; k < nb; ++k) {
      double d = std::fabs(b.u[k] - a.u[0]);
      d = std::min(d, 1 - d);
      if (d < best) best = d, b0 = k;
    }
    double ub0 = b.u[b0];
    if (ub0 - a.u[0] > 0.5) ub0 -= 1;
    if (ub0 - a.u[0] < -0.5) ub0 += 1;
    auto ua = [&](int i) { return i < na ? a.u[i] : a.u[i - na] + 1; };
    auto ub = [&](int k) {
      if (k >= nb) return ub0 + 1;
      double d = b.u[(b0 + k) % nb] - b.u[b0];
      if (d < 0) d += 1;
      return ub0 + d;
    };
    auto B = [&](int k) { return b.idx[(b0 + k) % nb]; };
    int i = 0, k = 0;
    while (i < na || k < nb) {
      if (k >= nb || (i < na && ua(i + 1) <= ub(k + 1))) {
        add_tri(a.idx[i % na], a.idx[(i + 1) % na], B(k));
        ++i;
      } else {
        add_tri(a.idx[i % na], B(k + 1), B(k));
        ++k;
      }
    }
  }

  static constexpr int kNU = 256, kNV = 512;
  const ShapeModel& model_;
  int part_;
  std::function<V3(const V3&)> to_final_;
  std::vector<V3> grid_;
  std::vector<double> rho_;
  std::vector<double> sigma_;
  double area_ = 0;
};

// ---- Charts ----

/// Grows charts over the triangles whose `chart` is -1 (Dijkstra on centroid distances over the adjacency): a
/// triangle joins a chart when its normal is within 60 degrees of the chart's mean normal so far and it lies
/// within `radius` (metres along the surface) of the chart's seed; first from `seeds` farthest-point seeds,
/// then from each triangle still unassigned, in index order. New charts are numbered from `charts`; returns
/// the new chart count.
int grow_charts(const std::vector<V3>& centroid, const std::vector<V3>& normal, const std::vector<double>& area,
                const std::vector<std::array<int, 3>>& nb, int seeds, double radius, std::mt19937& rng, int charts,
                std::vector<int>& chart) {
  const int nt = int(centroid.size());
  const double cos_max = 0.5;
  std::vector<int> free_tris;
  for (int t = 0; t < nt; ++t)
    if (chart[t] < 0) free_tris.push_back(t);
  if (free_tris.empty()) return charts;
  std::vector<int> seed_tri;
  std::vector<double> mind(free_tris.size(), 1e300);
  size_t s = rng() % free_tris.size();
  for (int c = 0; c < seeds && c < int(free_tris.size()); ++c) {
    seed_tri.push_back(free_tris[s]);
    size_t far = 0;
    for (size_t i = 0; i < free_tris.size(); ++i) {
      mind[i] = std::min(mind[i], (centroid[free_tris[i]] - centroid[free_tris[s]]).squaredNorm());
      if (mind[i] > mind[far]) far = i;
    }
    s = far;
  }
  using Item = std::tuple<double, int, int>;  // distance, triangle, chart
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  std::vector<V3> sum(charts, V3::Zero());  // area-weighted normal sum per chart
  auto grow = [&]() {
    while (!queue.empty()) {
      const auto [d, t, c] = queue.top();
      queue.pop();
      if (chart[t] >= 0 || d > radius || normal[t].dot(sum[c].normalized()) < cos_max) continue;
      chart[t] = c;
      sum[c] += area[t] * normal[t];
      for (int e = 0; e < 3; ++e) {
        const int n = nb[t][e];
        if (n >= 0 && chart[n] < 0) queue.emplace(d + (centroid[n] - centroid[t]).norm(), n, c);
      }
    }
  };
  auto seed = [&](int t) {
    queue.emplace(0.0, t, int(sum.size()));
    sum.push_back(normal[t]);
  };
  for (int t : seed_tri)
    if (chart[t] < 0) seed(t);
  grow();
  for (int t : free_tris) {
    if (chart[t] >= 0) continue;
    seed(t);
    grow();
  }
  return int(sum.size());
}

/// Merges each chart of fewer than `min_size` triangles into the neighbouring chart it shares most edges with,
/// when all its triangles stay within 70 degrees of the merged mean normal (leftovers between charts would
/// otherwise stay tiny charts).
void merge_small_charts(const std::vector<V3>& normal, const std::vector<double>& area,
                        const std::vector<std::array<int, 3>>& nb, int charts, int min_size, std::vector<int>& chart) {
  const int nt = int(normal.size());
  std::vector<V3> sum(charts, V3::Zero());
  std::vector<std::vector<int>> members(charts);
  for (int t = 0; t < nt; ++t) sum[chart[t]] += area[t] * normal[t], members[chart[t]].push_back(t);
  for (int c = 0; c < charts; ++c) {
    if (members[c].empty() || int(members[c].size()) >= min_size) continue;
    std::map<int, int> shared;  // neighbouring chart -> shared edges
    for (int t : members[c])
      for (int e = 0; e < 3; ++e)
        if (nb[t][e] >= 0 && chart[nb[t][e]] != c) ++shared[chart[nb[t][e]]];
    int best = -1, best_edges = 0;
    for (const auto& [other, edges] : shared) {
      const V3 n = (sum[other] + sum[c]).normalized();
      bool fits = true;
      for (int t : members[c]) fits = fits && normal[t].dot(n) >= 0.34;
      if (fits && edges > best_edges) best = other, best_edges = edges;
    }
    if (best < 0) continue;
    for (int t : members[c]) chart[t] = best;
    members[best].insert(members[best].end(), members[c].begin(), members[c].end());
    members[c].clear();
    sum[best] += sum[c];
    sum[c] = V3::Zero();
  }
}

/// Orthonormal chart-plane axes (t1, t2) with t1 x t2 = n.
std::pair<V3, V3> plane_axes(const V3& n) {
  const V3 t1 = (std::fabs(n.x()) < 0.9 ? V3::UnitX() : V3::UnitY()).cross(n).normalized();
  return {t1, n.cross(t1)};
}

/// True when 2-D triangles a and b overlap with positive area (touching along an edge or at a vertex does not
/// count): no separating axis among their edge normals.
bool triangles_overlap(const V2 a[3], const V2 b[3]) {
  for (int side = 0; side < 2; ++side) {
    const V2* p = side ? b : a;
    for (int e = 0; e < 3; ++e) {
      const V2 d = p[(e + 1) % 3] - p[e], axis(-d.y(), d.x());
      double lo_a = 1e300, hi_a = -1e300, lo_b = 1e300, hi_b = -1e300;
      for (int k = 0; k < 3; ++k) {
        lo_a = std::min(lo_a, axis.dot(a[k])), hi_a = std::max(hi_a, axis.dot(a[k]));
        lo_b = std::min(lo_b, axis.dot(b[k])), hi_b = std::max(hi_b, axis.dot(b[k]));
      }
      const double tol = 1e-9 * axis.squaredNorm();
      if (hi_a <= lo_b + tol || hi_b <= lo_a + tol) return false;
    }
  }
  return true;
}

/// Triangles to take out of their chart so that every chart projects one to one onto its mean plane: those
/// too oblique to it (normal more than 70 degrees off), and of each overlapping pair in the projection the
/// more oblique one.
std::vector<int> unfoldable_triangles(const std::vector<V3>& pos, const std::vector<int>& tri,
                                      const std::vector<V3>& normal, const std::vector<int>& chart,
                                      const std::vector<V3>& chart_normal) {
  const int nt = int(normal.size());
  std::vector<unsigned char> out(nt, 0);
  std::vector<std::vector<int>> members(chart_normal.size());
  for (int t = 0; t < nt; ++t) {
    if (normal[t].dot(chart_normal[chart[t]]) < 0.2)
      out[t] = 1;
    else
      members[chart[t]].push_back(t);
  }
  std::vector<std::array<V2, 3>> proj(nt);
  for (size_t c = 0; c < members.size(); ++c) {
    const auto& list = members[c];
    if (list.size() < 2) continue;
    const auto [t1, t2] = plane_axes(chart_normal[c]);
    V2 lo(1e300, 1e300), hi(-1e300, -1e300);
    double edge = 0;
    for (int t : list) {
      for (int k = 0; k < 3; ++k) {
        const V3& p = pos[tri[3 * t + k]];
        proj[t][k] = V2(p.dot(t1), p.dot(t2));
        lo = lo.cwiseMin(proj[t][k]), hi = hi.cwiseMax(proj[t][k]);
      }
      edge += (proj[t][1] - proj[t][0]).norm();
    }
    // Uniform grid of about two edge lengths; each triangle in the cells its box covers.
    const double cell = std::max(1e-9, 2 * edge / list.size());
    const int gx = std::min(1024, int((hi.x() - lo.x()) / cell) + 1),
              gy = std::min(1024, int((hi.y() - lo.y()) / cell) + 1);
    const double sx = gx / std::max(1e-12, hi.x() - lo.x() + 1e-12), sy = gy / std::max(1e-12, hi.y() - lo.y() + 1e-12);
    std::vector<std::vector<int>> grid(size_t(gx) * gy);
    for (int t : list) {
      V2 a = proj[t][0], b = proj[t][0];
      for (int k = 1; k < 3; ++k) a = a.cwiseMin(proj[t][k]), b = b.cwiseMax(proj[t][k]);
      const int x0 = std::clamp(int((a.x() - lo.x()) * sx), 0, gx - 1),
                x1 = std::clamp(int((b.x() - lo.x()) * sx), 0, gx - 1);
      const int y0 = std::clamp(int((a.y() - lo.y()) * sy), 0, gy - 1),
                y1 = std::clamp(int((b.y() - lo.y()) * sy), 0, gy - 1);
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) grid[size_t(y) * gx + x].push_back(t);
    }
    for (const auto& in_cell : grid)
      for (size_t i = 0; i < in_cell.size(); ++i)
        for (size_t j = i + 1; j < in_cell.size(); ++j) {
          const int a = in_cell[i], b = in_cell[j];
          if (out[a] || out[b] || !triangles_overlap(proj[a].data(), proj[b].data())) continue;
          out[normal[a].dot(chart_normal[c]) < normal[b].dot(chart_normal[c]) ? a : b] = 1;
        }
  }
  std::vector<int> result;
  for (int t = 0; t < nt; ++t)
    if (out[t]) result.push_back(t);
  return result;
}

}  // namespace scan
}  // namespace

Mesh make_scan_like(ScanShape shape, const Eigen::Vector3d& size, int triangles, int texture_size, uint32_t seed) {
  using namespace scan;
  if (!(size.minCoeff() > 0) || !size.allFinite())
    throw std::invalid_argument("make_scan_like: size must be positive (metres)");
  if (triangles < 200) throw std::invalid_argument("make_scan_like: triangles must be >= 200");
  if (texture_size < 64) throw std::invalid_argument("make_scan_like: texture_size must be >= 64");
  std::unique_ptr<ShapeModel> model;
  switch (shape) {
    case ScanShape::Bottle:
      model = std::make_unique<Bottle>();
      break;
    case ScanShape::Mug:
      model = std::make_unique<Mug>();
      break;
    case ScanShape::Box:
      model = std::make_unique<Box>();
      break;
    default:
      throw std::invalid_argument("make_scan_like: unknown shape");
  }
  std::mt19937 rng(seed ^ (uint32_t(shape) * 0x9E3779B9u));  // shapes of one seed get different prints
  std::uniform_real_distribution<double> U(0.0, 1.0);

  // Natural frame -> metres: the sampled natural bounding box onto `size`, centred on the origin.
  V3 lo = V3::Constant(1e300), hi = V3::Constant(-1e300);
  for (int part = 0; part < model->parts(); ++part)
    for (int k = 0; k <= 256; ++k)
      for (int i = 0; i < 128; ++i) {
        const V3 p = model->surface(part, i / 128.0, k / 256.0);
        lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
      }
  const V3 scale = size.cwiseQuotient(hi - lo), centre = 0.5 * (lo + hi);
  auto to_final = [scale, centre](const V3& p) { return V3((p - centre).cwiseProduct(scale)); };
  model->prepare_print(scale, texture_size, rng);

  Density density;
  const double wavelength = 0.7 * size.norm();
  for (int i = 0; i < 3; ++i) {
    const double z = 2 * U(rng) - 1, a = 2 * kPi * U(rng), r = std::sqrt(1 - z * z);
    density.k[i] = (2 * kPi / wavelength) * V3(r * std::cos(a), r * std::sin(a), z);
    density.phase[i] = 2 * kPi * U(rng);
  }

  // Triangulate, adjusting the edge length until the count is within 1 % of the request.
  std::vector<PartSampler> samplers;
  double area = 0;
  for (int part = 0; part < model->parts(); ++part) {
    samplers.emplace_back(*model, part, to_final, density);
    area += samplers.back().weighted_area();
  }
  double h0 = std::sqrt(2 * area / triangles);
  for (int iter = 0; iter < 8; ++iter) {
    int count = 0;
    for (const auto& s : samplers) count += s.build(h0, seed, nullptr);
    if (std::abs(count - triangles) <= 0.01 * triangles) break;
    h0 *= std::sqrt(double(count) / triangles);
  }
  Soup soup;
  for (const auto& s : samplers) s.build(h0, seed, &soup);
  const int nt = int(soup.tri.size() / 3);

  // Each part outward (its enclosed volume positive), then the exact bounding box.
  for (int part = 0; part < model->parts(); ++part) {
    double volume = 0;
    for (int t = 0; t < nt; ++t)
      if (soup.tri_part[t] == part)
        volume += soup.pos[soup.tri[3 * t]].dot(soup.pos[soup.tri[3 * t + 1]].cross(soup.pos[soup.tri[3 * t + 2]]));
    if (volume < 0)
      for (int t = 0; t < nt; ++t)
        if (soup.tri_part[t] == part) std::swap(soup.tri[3 * t + 1], soup.tri[3 * t + 2]);
  }
  lo = V3::Constant(1e300), hi = V3::Constant(-1e300);
  for (const V3& p : soup.pos) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  for (V3& p : soup.pos) p = (p - 0.5 * (lo + hi)).cwiseProduct(size.cwiseQuotient(hi - lo));

  // Triangle normals, centroids, adjacency (each part is a closed manifold: every edge has two triangles).
  std::vector<V3> normal(nt), centroid(nt);
  std::vector<double> tri_area(nt);
  std::vector<std::pair<uint64_t, int>> edges;
  edges.reserve(3 * nt);
  for (int t = 0; t < nt; ++t) {
    const V3 &a = soup.pos[soup.tri[3 * t]], &b = soup.pos[soup.tri[3 * t + 1]], &c = soup.pos[soup.tri[3 * t + 2]];
    const V3 n = (b - a).cross(c - a);
    tri_area[t] = 0.5 * n.norm();
    normal[t] = n.norm() > 0 ? V3(n.normalized()) : V3::UnitZ();
    centroid[t] = (a + b + c) / 3;
    for (int e = 0; e < 3; ++e) {
      const uint64_t i = uint64_t(soup.tri[3 * t + e]), j = uint64_t(soup.tri[3 * t + (e + 1) % 3]);
      edges.emplace_back(std::min(i, j) << 32 | std::max(i, j), 3 * t + e);
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<std::array<int, 3>> nb(nt, {-1, -1, -1});
  for (size_t i = 0; i + 1 < edges.size(); ++i)
    if (edges[i].first == edges[i + 1].first) {
      const int a = edges[i].second, b = edges[i + 1].second;
      nb[a / 3][a % 3] = b / 3;
      nb[b / 3][b % 3] = a / 3;
    }

  // Charts, then until each projects one to one onto its mean plane: triangles that fold or are too oblique
  // are taken out and re-charted (in the end, alone).
  std::vector<int> chart(nt, -1);
  constexpr int kSeeds = 24;
  const double radius = 1.5 * std::sqrt(std::accumulate(tri_area.begin(), tri_area.end(), 0.0) / kSeeds);
  int charts = grow_charts(centroid, normal, tri_area, nb, kSeeds, radius, rng, 0, chart);
  std::vector<V3> chart_normal;
  for (int round = 0;; ++round) {
    merge_small_charts(normal, tri_area, nb, charts, 24, chart);
    chart_normal.assign(charts, V3::Zero());
    for (int t = 0; t < nt; ++t) chart_normal[chart[t]] += tri_area[t] * normal[t];
    for (int c = 0; c < charts; ++c)
      chart_normal[c] = chart_normal[c].norm() > 0 ? V3(chart_normal[c].normalized()) : V3::UnitZ();
    const std::vector<int> redo = unfoldable_triangles(soup.pos, soup.tri, normal, chart, chart_normal);
    if (redo.empty()) break;
    if (round == 3) {
      for (int t : redo) chart[t] = charts++, chart_normal.push_back(normal[t]);
      break;
    }
    for (int t : redo) chart[t] = -1;
    charts = grow_charts(centroid, normal, tri_area, nb, 0, radius, rng, charts, chart);
  }
  // Drop chart numbers left empty.
  {
    std::vector<int> renumber(charts, -1);
    int used = 0;
    for (int t = 0; t < nt; ++t)
      if (renumber[chart[t]] < 0) renumber[chart[t]] = used++;
    std::vector<V3> normals(used);
    for (int c = 0; c < charts; ++c)
      if (renumber[c] >= 0) normals[renumber[c]] = chart_normal[c];
    for (int& c : chart) c = renumber[c];
    chart_normal = normals;
    charts = used;
  }

  // Each chart projected onto its mean plane (principal axis along x), its vertices duplicated.
  std::vector<std::vector<int>> chart_tris(charts);
  for (int t = 0; t < nt; ++t) chart_tris[chart[t]].push_back(t);
  Mesh m;
  std::vector<V3> vnat;
  std::vector<V2> vplane;  // chart-plane coordinates, metres
  std::vector<int> vchart;
  m.triangles.assign(3 * nt, -1);
  std::vector<int> stamp(soup.pos.size(), -1), local(soup.pos.size(), -1);
  struct Rect {
    double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
    int px = 0, py = 0;
  };
  std::vector<Rect> rect(charts);
  for (int c = 0; c < charts; ++c) {
    const auto [t1, t2] = plane_axes(chart_normal[c]);
    const int first = int(vplane.size());
    for (int t : chart_tris[c])
      for (int e = 0; e < 3; ++e) {
        const int g = soup.tri[3 * t + e];
        if (stamp[g] != c) {
          stamp[g] = c;
          local[g] = int(vplane.size());
          vplane.emplace_back(soup.pos[g].dot(t1), soup.pos[g].dot(t2));
          vnat.push_back(soup.nat[g]);
          vchart.push_back(c);
          m.positions.push_back({float(soup.pos[g].x()), float(soup.pos[g].y()), float(soup.pos[g].z())});
        }
        m.triangles[3 * t + e] = local[g];
      }
    // Principal axis of the chart's vertices along x (a rotation: UVs stay counter-clockwise).
    V2 mean = V2::Zero();
    for (int i = first; i < int(vplane.size()); ++i) mean += vplane[i];
    mean /= double(vplane.size() - first);
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (int i = first; i < int(vplane.size()); ++i) cov += (vplane[i] - mean) * (vplane[i] - mean).transpose();
    const double angle = 0.5 * std::atan2(2 * cov(0, 1), cov(0, 0) - cov(1, 1));
    const double ca = std::cos(angle), sa = std::sin(angle);
    Rect& r = rect[c];
    for (int i = first; i < int(vplane.size()); ++i) {
      const V2 q = vplane[i] - mean;
      vplane[i] = V2(ca * q.x() + sa * q.y(), -sa * q.x() + ca * q.y());
      r.xmin = std::min(r.xmin, vplane[i].x()), r.xmax = std::max(r.xmax, vplane[i].x());
      r.ymin = std::min(r.ymin, vplane[i].y()), r.ymax = std::max(r.ymax, vplane[i].y());
    }
  }

  // Shelf packing (tallest first) at the largest texels-per-metre that fits, a gutter of `pad` texels around
  // each chart.
  const int N = texture_size, pad = std::max(2, N / 256);
  std::vector<int> order(charts);
  for (int c = 0; c < charts; ++c) order[c] = c;
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    const double ha = rect[a].ymax - rect[a].ymin, hb = rect[b].ymax - rect[b].ymin;
    return ha != hb ? ha > hb : a < b;
  });
  auto pack = [&](double s, bool place) {
    int x = 0, y = 0, shelf = 0;
    for (int c : order) {
      const int w = int(std::ceil((rect[c].xmax - rect[c].xmin) * s)) + 2 * pad + 1;
      const int h = int(std::ceil((rect[c].ymax - rect[c].ymin) * s)) + 2 * pad + 1;
      if (w > N) return false;
      if (x + w > N) x = 0, y += shelf, shelf = 0;
      if (place) rect[c].px = x, rect[c].py = y;
      x += w;
      shelf = std::max(shelf, h);
      if (y + shelf > N) return false;
    }
    return true;
  };
  double s_lo = 0, s_hi = N / 1e-6;
  for (const Rect& r : rect) s_hi = std::min(s_hi, N / std::max(1e-9, std::max(r.xmax - r.xmin, r.ymax - r.ymin)));
  for (int it = 0; it < 40; ++it) {
    const double s = 0.5 * (s_lo + s_hi);
    (pack(s, false) ? s_lo : s_hi) = s;
  }
  pack(s_lo, true);
  std::vector<V2> atlas(vplane.size());  // texel coordinates: x right, y down (row 0 = top)
  for (size_t i = 0; i < vplane.size(); ++i) {
    const Rect& r = rect[vchart[i]];
    atlas[i] =
        V2(r.px + pad + 0.5 + (vplane[i].x() - r.xmin) * s_lo, r.py + pad + 0.5 + (r.ymax - vplane[i].y()) * s_lo);
    m.uvs.push_back({float(atlas[i].x() / N), float(1.0 - atlas[i].y() / N)});
  }

  // Paint: every texel centre inside a triangle gets the colour of its surface point, and so does a ring of
  // 1.5 texels around each chart (the surface continued over the triangle's plane from the nearest triangle),
  // so that filtering at a seam reads the same print on both sides. The rest takes the colour of the nearest
  // painted texel.
  Texture tex;
  tex.width = tex.height = N;
  tex.source = std::string(model->name()) + std::to_string(seed);
  tex.rgb.assign(size_t(3) * N * N, 0.f);
  constexpr float kUnpainted = 1e30f, kRing = 1.5f;
  std::vector<float> gap(size_t(N) * N, kUnpainted);  // texels from the triangle that painted the texel
  for (int t = 0; t < nt; ++t) {
    const int* v = &m.triangles[3 * t];
    const V2 P[3] = {atlas[v[0]], atlas[v[1]], atlas[v[2]]};
    const double area2 = (P[1] - P[0]).x() * (P[2] - P[0]).y() - (P[1] - P[0]).y() * (P[2] - P[0]).x();
    if (std::fabs(area2) < 1e-12) continue;
    double altitude[3];  // distance from each vertex to the opposite edge, texels
    for (int k = 0; k < 3; ++k)
      altitude[k] = std::fabs(area2) / std::max(1e-12, (P[(k + 2) % 3] - P[(k + 1) % 3]).norm());
    const int x0 = std::max(0, int(std::floor(std::min({P[0].x(), P[1].x(), P[2].x()}) - 0.5 - kRing)));
    const int x1 = std::min(N - 1, int(std::ceil(std::max({P[0].x(), P[1].x(), P[2].x()}) - 0.5 + kRing)));
    const int y0 = std::max(0, int(std::floor(std::min({P[0].y(), P[1].y(), P[2].y()}) - 0.5 - kRing)));
    const int y1 = std::min(N - 1, int(std::ceil(std::max({P[0].y(), P[1].y(), P[2].y()}) - 0.5 + kRing)));
    const int part = soup.tri_part[t];
    for (int y = y0; y <= y1; ++y) {
      const double py = y + 0.5;
      float* row = &tex.rgb[size_t(3) * N * y];
      float* grow = &gap[size_t(N) * y];
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5;
        double w[3];
        for (int k = 0; k < 3; ++k) {
          const V2 &a = P[(k + 1) % 3], &b = P[(k + 2) % 3];
          w[k] = ((a.x() - px) * (b.y() - py) - (a.y() - py) * (b.x() - px)) / area2;
        }
        const float d = float(std::max({0.0, -w[0] * altitude[0], -w[1] * altitude[1], -w[2] * altitude[2]}));
        if (d >= kRing || d >= grow[x]) continue;
        grow[x] = d;
        const Rgb col = model->colour(part, w[0] * vnat[v[0]] + w[1] * vnat[v[1]] + w[2] * vnat[v[2]]);
        for (int ch = 0; ch < 3; ++ch) row[3 * x + ch] = std::clamp(col[ch], 0.f, 1.f);
      }
    }
  }
  cv::Mat unpainted(N, N, CV_8UC1), dist, labels;
  for (int y = 0; y < N; ++y) {
    uint8_t* r = unpainted.ptr<uint8_t>(y);
    for (int x = 0; x < N; ++x) r[x] = gap[size_t(N) * y + x] == kUnpainted ? 255 : 0;
  }
  cv::distanceTransform(unpainted, dist, labels, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  std::vector<int> source(size_t(N) * N + 1, -1);
  for (int y = 0; y < N; ++y) {
    const uint8_t* r = unpainted.ptr<uint8_t>(y);
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < N; ++x)
      if (!r[x]) source[size_t(l[x])] = y * N + x;
  }
  for (int y = 0; y < N; ++y) {
    const uint8_t* r = unpainted.ptr<uint8_t>(y);
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < N; ++x) {
      const int from = r[x] ? source[size_t(l[x])] : -1;
      if (from >= 0) std::copy_n(&tex.rgb[size_t(3) * from], 3, &tex.rgb[size_t(3) * (size_t(y) * N + x)]);
    }
  }

  m.colors.assign(m.positions.size(), {0.7f, 0.7f, 0.7f});
  m.tri_texture.assign(nt, 0);
  m.textures.push_back(std::move(tex));
  m.name = model->name();
  m.finalize();
  return m;
}

}  // namespace diffdope
