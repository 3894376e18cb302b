// The shapes of scan-like objects: a bottle, a mug and a box as closed parametric parts (bodies of revolution
// along a meridian profile, a handle tube, a superellipsoid) with their print.
#include <algorithm>
#include <cmath>
#include <memory>
#include <opencv2/core.hpp>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include "sim/scan_like_internal.hpp"

namespace diffdope {
namespace scan {

double invert_table(const std::vector<double>& table, double value) {
  const auto it = std::lower_bound(table.begin(), table.end(), value);
  if (it == table.begin()) return 0.0;
  if (it == table.end()) return double(table.size() - 1);
  const size_t k = size_t(it - table.begin());
  const double a = table[k - 1], b = table[k];
  return double(k - 1) + (b > a ? (value - a) / (b - a) : 0.0);
}

namespace {

double smoothstep(double a, double b, double x) {
  const double t = std::clamp((x - a) / (b - a), 0.0, 1.0);
  return t * t * (3 - 2 * t);
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

}  // namespace

std::unique_ptr<ShapeModel> make_shape_model(ScanShape shape) {
  switch (shape) {
    case ScanShape::Bottle:
      return std::make_unique<Bottle>();
    case ScanShape::Mug:
      return std::make_unique<Mug>();
    case ScanShape::Box:
      return std::make_unique<Box>();
    default:
      throw std::invalid_argument("make_scan_like: unknown shape");
  }
}

}  // namespace scan
}  // namespace diffdope
