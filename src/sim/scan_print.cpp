// The print of scan-like objects: brands (palette colours, names) and printed panels (front label, back text
// with facts table and barcode, sides, plain flaps) drawn with OpenCV in 8 bits, sampled in float.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>

#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {

const Rgb kPalette[kPaletteSize] = {
    {0.78f, 0.08f, 0.10f}, {0.97f, 0.80f, 0.12f}, {0.10f, 0.28f, 0.65f}, {0.12f, 0.52f, 0.22f},
    {0.95f, 0.45f, 0.08f}, {0.42f, 0.18f, 0.55f}, {0.05f, 0.55f, 0.55f}, {0.45f, 0.27f, 0.12f},
    {0.96f, 0.92f, 0.80f}, {0.95f, 0.95f, 0.93f}, {0.07f, 0.07f, 0.08f}, {0.92f, 0.45f, 0.60f}};

namespace {

const char* const kWords[] = {"NOVA",  "ACME",      "PRIME", "SUNNY",  "ALPINE", "GOLDEN", "ROYAL", "MAPLE",
                              "ZESTY", "DIFF-DOPE", "ORBIT", "VELVET", "HARBOR", "COMET",  "FJORD", "LUMEN"};
const char* const kProducts[] = {"CLASSIC", "ORGANIC", "CRUNCH", "FRESH", "EXTRA", "ORIGINAL", "MILD", "DELUXE"};

float luminance(const Rgb& c) { return 0.3f * c[0] + 0.59f * c[1] + 0.11f * c[2]; }
cv::Scalar scalar(const Rgb& c) { return cv::Scalar(255.0 * c[0], 255.0 * c[1], 255.0 * c[2]); }

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

}  // namespace

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

cv::Size panel_size(double w, double h, double px_per_m) {
  return cv::Size(std::max(16, int(std::lround(w * px_per_m))), std::max(16, int(std::lround(h * px_per_m))));
}

Panel make_panel(cv::Size size, Design design, const Brand& b, std::mt19937& rng) {
  cv::Mat img(size, CV_8UC3);
  draw_design(img, cv::Rect(0, 0, size.width, size.height), design, b, rng);
  return Panel(img);
}

}  // namespace scan
}  // namespace diffdope
