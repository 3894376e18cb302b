// derive_object_pixels() (object_pixels.hpp): depth near the rendered estimate, less occluders in front and the
// planes the object stands among.
#include "diffdope/object_pixels.hpp"

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace diffdope {
namespace {

struct Plane {
  Eigen::Vector3d normal;  // unit
  double offset = 0;       // normal . p + offset = 0
  double distance(const Eigen::Vector3d& p) const { return std::abs(normal.dot(p) + offset); }
};


/// Least-squares plane through `points` (the eigenvector of the smallest scatter).
Plane fit_plane(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p;
  mean /= double(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const auto& p : points) scatter += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
  Plane plane;
  plane.normal = eig.eigenvectors().col(0).normalized();
  plane.offset = -plane.normal.dot(mean);
  return plane;
}

/// RANSAC: the plane through three of `points` that the most of them lie within `tolerance` of (hypotheses scored
/// on at most 8000 of them), refit to its inliers. Deterministic (fixed seed): the same image gives the same
/// pixels.
Plane dominant_plane(const std::vector<Eigen::Vector3d>& points, double tolerance, std::mt19937& rng) {
  constexpr int kHypotheses = 200;
  std::uniform_int_distribution<size_t> pick(0, points.size() - 1);
  // The sample's points side by side (not indices into the cloud): each hypothesis reads them from the cache.
  std::vector<Eigen::Vector3d> sample;
  const size_t n_sample = std::min<size_t>(points.size(), 8000);
  sample.reserve(n_sample);
  for (size_t k = 0; k < n_sample; ++k) sample.push_back(points[pick(rng)]);
  // The hypotheses' corners drawn first, in the order one loop would draw them; their counts are then independent
  // (scored on OpenCV's threads) and the first of the highest wins, as in that loop.
  std::vector<Plane> planes(kHypotheses);
  std::vector<char> valid(kHypotheses, 0);
  for (int h = 0; h < kHypotheses; ++h) {
    const Eigen::Vector3d &a = points[pick(rng)], &b = points[pick(rng)], &c = points[pick(rng)];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-9) continue;
    planes[size_t(h)] = Plane{n.normalized(), 0};
    planes[size_t(h)].offset = -planes[size_t(h)].normal.dot(a);
    valid[size_t(h)] = 1;
  }
  std::vector<size_t> counts(kHypotheses, 0);
  cv::parallel_for_(cv::Range(0, kHypotheses), [&](const cv::Range& r) {
    for (int h = r.start; h < r.end; ++h) {
      if (!valid[size_t(h)]) continue;
      size_t count = 0;
      for (const Eigen::Vector3d& q : sample) count += planes[size_t(h)].distance(q) <= tolerance;
      counts[size_t(h)] = count;
    }
  });
  Plane best;
  size_t best_count = 0;
  for (int h = 0; h < kHypotheses; ++h)
    if (valid[size_t(h)] && counts[size_t(h)] > best_count) best_count = counts[size_t(h)], best = planes[size_t(h)];
  if (best_count == 0) return best;
  for (int refit = 0; refit < 2; ++refit) {
    std::vector<Eigen::Vector3d> inliers;
    for (const auto& q : points)
      if (best.distance(q) <= tolerance) inliers.push_back(q);
    if (inliers.size() < 3) break;
    best = fit_plane(inliers);
  }
  return best;
}

/// Colour histograms of the object's pixels and of the background's, kColourBins per channel, and in each pixel
/// of `where` the probability that its colour is the object's (equal priors). Each histogram starts from one count
/// in every bin (a uniform prior): a colour neither region shows comes out near a half, leaning to the region
/// with fewer pixels, whose colours are the less well known.
void colour_probability(const cv::Mat& rgb, const cv::Mat& object, const cv::Mat& background, const cv::Mat& where,
                        cv::Mat& out) {
  const auto bin = [](const cv::Vec3f& c) {
    int b = 0;
    for (int ch = 0; ch < 3; ++ch) b = b * kColourBins + std::clamp(int(c[ch] * kColourBins), 0, kColourBins - 1);
    return b;
  };
  std::vector<double> fg(kColourBins * kColourBins * kColourBins, 1.0), bg(fg.size(), 1.0);
  double n_fg = double(fg.size()), n_bg = double(bg.size());
  for (int y = 0; y < rgb.rows; ++y)
    for (int x = 0; x < rgb.cols; ++x) {
      if (object.at<uchar>(y, x)) fg[size_t(bin(rgb.at<cv::Vec3f>(y, x)))] += 1, n_fg += 1;
      else if (background.at<uchar>(y, x)) bg[size_t(bin(rgb.at<cv::Vec3f>(y, x)))] += 1, n_bg += 1;
    }
  for (int y = 0; y < rgb.rows; ++y)
    for (int x = 0; x < rgb.cols; ++x) {
      if (!where.at<uchar>(y, x)) continue;
      const size_t b = size_t(bin(rgb.at<cv::Vec3f>(y, x)));
      const double pf = fg[b] / n_fg, pb = bg[b] / n_bg;
      out.at<float>(y, x) = float(pf / (pf + pb));
    }
}

/// What each render covers with a depth (a sliver at a silhouette says nothing of the object's depth range),
/// their union, and the nearest depth they show (infinity when they cover nothing). `who` names the caller in
/// the error thrown for a render that is not `size`.
struct RenderCover {
  std::vector<cv::Mat> covered;  // per render, CV_8U
  cv::Mat any;
  double z_near = std::numeric_limits<double>::infinity();
};

RenderCover render_cover(const std::vector<RenderImage>& renders, const cv::Size& size, const std::string& who) {
  RenderCover out;
  out.any = cv::Mat::zeros(size, CV_8U);
  for (const RenderImage& img : renders) {
    if (img.depth.size() != size || img.coverage.size() != size)
      throw std::invalid_argument(who + ": a render is not the camera's size");
    out.covered.push_back((img.coverage >= 0.5f) & (img.depth > 0.0f));
    out.any |= out.covered.back();
    if (cv::countNonZero(out.covered.back()) == 0) continue;
    cv::Mat masked = img.depth.clone();
    masked.setTo(std::numeric_limits<float>::infinity(), ~out.covered.back());
    double z = 0;
    cv::minMaxLoc(masked, &z);
    out.z_near = std::min(out.z_near, z);
  }
  return out;
}

/// Keeps the 8-connected groups of nonzero `pixels` (CV_8U) that have a pixel where `where` is nonzero.
void keep_groups_meeting(cv::Mat& pixels, const cv::Mat& where) {
  cv::Mat labels;
  const int n_labels = cv::connectedComponents(pixels, labels, 8, CV_32S);
  std::vector<char> meets(size_t(n_labels), 0);
  for (int y = 0; y < pixels.rows; ++y)
    for (int x = 0; x < pixels.cols; ++x)
      if (pixels.at<uchar>(y, x) && where.at<uchar>(y, x)) meets[size_t(labels.at<int>(y, x))] = 1;
  for (int y = 0; y < pixels.rows; ++y)
    for (int x = 0; x < pixels.cols; ++x)
      if (pixels.at<uchar>(y, x) && !meets[size_t(labels.at<int>(y, x))]) pixels.at<uchar>(y, x) = 0;
}

/// The share of the pixels of `where` within `tolerance` of `plane` whose own surface, from the points `step`
/// pixels around them, faces as the plane does (within kPlaneNormalAngle). A plane's own points do, its noise
/// averaged over the step; a slab that RANSAC cut through other surfaces (a cylinder's flank seen edge-on, the
/// floor beneath it, a neighbour) mostly does not.
template <typename PointAt>
double normal_agreement(const Plane& plane, const cv::Mat& where, const PointAt& point, double tolerance, int step) {
  const double min_cos = std::cos(kPlaneNormalAngle);
  size_t agree = 0, judged = 0;
  for (int y = step; y + step < where.rows; y += 2)
    for (int x = step; x + step < where.cols; x += 2) {
      const Eigen::Vector3d& p = point(x, y);
      if (!where.at<uchar>(y, x) || !(p.z() > 0) || plane.distance(p) > tolerance) continue;
      const Eigen::Vector3d &left = point(x - step, y), &right = point(x + step, y);
      const Eigen::Vector3d &up = point(x, y - step), &down = point(x, y + step);
      if (!(left.z() > 0 && right.z() > 0 && up.z() > 0 && down.z() > 0)) continue;
      const Eigen::Vector3d n = (right - left).cross(down - up);
      if (n.norm() < 1e-12) continue;
      ++judged;
      agree += std::abs(n.normalized().dot(plane.normal)) >= min_cos;
    }
  return judged ? double(agree) / double(judged) : 0.0;
}

int pixels_at(const Camera& camera, double metres, double z) {
  return std::clamp(int(std::ceil(metres * std::max(camera.fx, camera.fy) / std::max(z, 0.05))), 1, 200);
}

/// The observed pixels within reach of the renders: around each (`margin` metres, as pixels at z_near), at the
/// depths it shows there give or take the margin. An occluder in front of the object, or a wall behind it, lies
/// outside that depth range. `within_reach` gets the renders' neighbourhoods.
cv::Mat pixels_within_reach(const Camera& camera, const cv::Mat& d, const std::vector<cv::Mat>& depth,
                            const std::vector<cv::Mat>& covered, double z_near, double margin, cv::Mat& within_reach) {
  const cv::Size size(camera.width, camera.height);
  const int radius = pixels_at(camera, margin, z_near);
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1));
  cv::Mat mask = cv::Mat::zeros(size, CV_8U);
  within_reach = cv::Mat::zeros(size, CV_8U);
  for (size_t i = 0; i < depth.size(); ++i) {
    cv::Mat nearest = depth[i].clone(), farthest = depth[i].clone();
    nearest.setTo(std::numeric_limits<float>::infinity(), ~covered[i]);
    farthest.setTo(0.0f, ~covered[i]);
    cv::erode(nearest, nearest, kernel);     // smallest rendered depth around each pixel
    cv::dilate(farthest, farthest, kernel);  // largest
    const cv::Mat reach = farthest > 0;
    within_reach |= reach;
    mask |= (d > 0) & (d >= nearest - margin) & (d <= farthest + margin) & reach;
  }
  return mask;
}

/// Surfaces beside the object: planes of the depth where the object cannot be (`search`), each followed into its
/// reach by connectivity (a table runs under the object, a box's side continues past it). Their pixels leave
/// `mask` unless a render is there at that depth (the object's foot on the table). A plane needs `min_points`
/// sampled points (every second pixel); kPlaneTolerance, kPlaneBandSigmas and kMinPlaneBand say what is removed.
void remove_planes(const Camera& camera, const cv::Mat& d, const std::vector<cv::Mat>& depth,
                   const std::vector<cv::Mat>& covered, const cv::Mat& within_reach, const cv::Mat& search,
                   double z_near, size_t min_points, cv::Mat& mask) {
  const cv::Size size(camera.width, camera.height);
  // The observed points (camera frame), once; z = 0 where there is no reading.
  std::vector<Eigen::Vector3d> cloud(size_t(camera.width) * size_t(camera.height), Eigen::Vector3d::Zero());
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const float z = d.at<float>(y, x);
      if (z > 0 && std::isfinite(z))
        cloud[size_t(y) * size_t(camera.width) + size_t(x)] = camera.back_project(x, y, z);
    }
  const auto point = [&](int x, int y) -> const Eigen::Vector3d& {
    return cloud[size_t(y) * size_t(camera.width) + size_t(x)];
  };
  std::vector<Eigen::Vector3d> outside;
  for (int y = 0; y < camera.height; y += 2)
    for (int x = 0; x < camera.width; x += 2)
      if (point(x, y).z() > 0 && search.at<uchar>(y, x)) outside.push_back(point(x, y));
  const double tolerance = kPlaneTolerance;
  const int normal_step = std::max(2, pixels_at(camera, kNormalBaseline, z_near));
  std::mt19937 rng(1);
  for (int k = 0; k < kMaxPlanes && outside.size() >= std::max<size_t>(min_points, 3); ++k) {
    const Plane plane = dominant_plane(outside, tolerance, rng);
    std::vector<double> residuals;
    std::vector<Eigen::Vector3d> rest;
    for (const auto& p : outside) {
      const double r = plane.distance(p);
      if (r <= tolerance) residuals.push_back(r);
      else rest.push_back(p);
    }
    if (residuals.size() < min_points) break;
    std::nth_element(residuals.begin(), residuals.begin() + long(residuals.size() / 2), residuals.end());
    const double spread = 1.4826 * residuals[residuals.size() / 2];  // |r| has median 0.674 sigma; MAD of r
    outside.swap(rest);
    // RANSAC also finds slabs through other surfaces (a cylinder's flank seen edge-on, with the floor and the
    // object beside it): no plane, and its band would cut the object's end away.
    if (normal_agreement(plane, search, point, tolerance, normal_step) < kPlaneNormalShare) continue;
    const double band = std::clamp(kPlaneBandSigmas * spread, kMinPlaneBand, tolerance);
    cv::Mat on_plane = cv::Mat::zeros(size, CV_8U);
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x)
        if (point(x, y).z() > 0 && plane.distance(point(x, y)) <= band) on_plane.at<uchar>(y, x) = 255;
    keep_groups_meeting(on_plane, ~within_reach);  // the parts of the plane that reach outside
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        if (!mask.at<uchar>(y, x) || !on_plane.at<uchar>(y, x)) continue;
        bool rendered_there = false;
        for (size_t i = 0; i < depth.size() && !rendered_there; ++i)
          rendered_there = covered[i].at<uchar>(y, x) &&
                           std::abs(d.at<float>(y, x) - depth[i].at<float>(y, x)) <= band;
        if (!rendered_there) mask.at<uchar>(y, x) = 0;
      }
  }
}

/// derive_object_pixels() within a window of the image: `camera` is the window's (its principal point shifted),
/// the images are the window's parts; `min_points` is kMinPlaneShare of the whole image's quarter (the planes'
/// least support), `bounds` in the window's pixels.
cv::Mat pixels_in_window(const Camera& camera, const cv::Mat& d, const std::vector<cv::Mat>& depth,
                         const std::vector<cv::Mat>& covered, const cv::Mat& covered_any, double z_near,
                         const ObjectPixelsOptions& options, const cv::Rect& bounds, const cv::Mat& rgb,
                         size_t min_points) {
  const cv::Size size(camera.width, camera.height);
  cv::Mat within_reach;
  cv::Mat mask = pixels_within_reach(camera, d, depth, covered, z_near, options.margin, within_reach);
  cv::Mat search = ~within_reach, around = cv::Mat(size, CV_8U, cv::Scalar(255));
  if (options.surface_search > 0) {
    const int ring = pixels_at(camera, options.surface_search, z_near);
    cv::dilate(within_reach, around, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * ring + 1, 2 * ring + 1)));
    search &= around;
  }
  remove_planes(camera, d, depth, covered, within_reach, search, z_near, min_points, mask);
  cv::Mat inside_bounds(size, CV_8U, cv::Scalar(255));
  if (!bounds.empty()) {
    inside_bounds.setTo(0);
    inside_bounds(bounds & cv::Rect(cv::Point(0, 0), size)).setTo(255);
    mask &= inside_bounds;
  }
  if (options.touching_render) keep_groups_meeting(mask, covered_any);
  cv::Mat out;
  mask.convertTo(out, CV_32F, 1.0 / 255.0);
  const bool by_colour = options.holes_from_colour && !rgb.empty();
  if (by_colour || options.holes_unknown) {
    cv::Mat holes = ~(d > 0) & within_reach & inside_bounds;  // (NaN compares false: no reading)
    // Only holes that meet the object's pixels: a sensor's dropout blob elsewhere in the reach is not the object,
    // whatever its colour.
    cv::Mat next_to_object;
    cv::dilate(mask, next_to_object, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
    keep_groups_meeting(holes, next_to_object);
    const cv::Mat background = (d > 0) & around & ~mask;
    if (by_colour) colour_probability(rgb, mask, background, holes, out);
    else out.setTo(0.5f, holes);
  }
  return out;
}

}  // namespace

cv::Mat derive_object_pixels(const Camera& camera, const cv::Mat& d, const std::vector<RenderImage>& renders,
                             const ObjectPixelsOptions& options, const cv::Mat& rgb) {
  const cv::Size size(camera.width, camera.height);
  if (d.empty() || d.type() != CV_32F) throw std::invalid_argument("derive_object_pixels: no depth image (CV_32F)");
  if (d.size() != size) throw std::invalid_argument("derive_object_pixels: the depth image is not the camera's size");
  if (!(options.margin > 0 && options.margin <= 1))
    throw std::invalid_argument("derive_object_pixels: the margin must be in (0, 1] metres");
  if (!rgb.empty() && (rgb.type() != CV_32FC3 || rgb.size() != size))
    throw std::invalid_argument("derive_object_pixels: the rgb image is not CV_32FC3 of the camera's size");
  if (!(options.surface_search >= 0 && options.surface_search <= 1))
    throw std::invalid_argument("derive_object_pixels: surface_search must be in [0, 1] metres");
  const RenderCover cover = render_cover(renders, size, "derive_object_pixels");
  const std::vector<cv::Mat>& covered = cover.covered;
  const cv::Mat& covered_any = cover.any;
  const double z_near = cover.z_near;
  if (cv::countNonZero(covered_any) == 0) return cv::Mat::zeros(size, CV_32F);

  // Only the object's surroundings are searched (its reach and the surfaces around it): the rest of the image
  // cannot be its pixels. A robot (surface_search 0) is sought in the whole image.
  cv::Rect window(cv::Point(0, 0), size);
  if (options.surface_search > 0) {
    const int grow = pixels_at(camera, options.margin, z_near) + pixels_at(camera, options.surface_search, z_near) + 2;
    const cv::Rect b = cv::boundingRect(covered_any);
    const cv::Point tl((std::max(b.x - grow, 0) / 2) * 2, (std::max(b.y - grow, 0) / 2) * 2);  // even: the same
    window = cv::Rect(tl, cv::Point(b.x + b.width + grow, b.y + b.height + grow)) & window;     // sampling grid
  }
  Camera inside = camera;
  inside.cx -= window.x, inside.cy -= window.y;
  inside.width = window.width, inside.height = window.height;
  std::vector<cv::Mat> depth, covered_in;
  for (size_t i = 0; i < renders.size(); ++i) depth.push_back(renders[i].depth(window)), covered_in.push_back(covered[i](window));
  const cv::Rect bounds = options.bounds.empty() ? cv::Rect() : (options.bounds - window.tl()) & cv::Rect(cv::Point(0, 0), window.size());
  if (!options.bounds.empty() && bounds.empty()) return cv::Mat::zeros(size, CV_32F);
  cv::Mat out = cv::Mat::zeros(size, CV_32F);
  pixels_in_window(inside, d(window), depth, covered_in, covered_any(window), z_near, options, bounds,
                   rgb.empty() ? cv::Mat() : rgb(window), size_t(kMinPlaneShare * camera.width * camera.height / 4))
      .copyTo(out(window));
  return out;
}

cv::Mat derive_object_pixels_from_colour(const Camera& camera, const cv::Mat& rgb,
                                         const std::vector<RenderImage>& renders, const ObjectPixelsOptions& options) {
  const cv::Size size(camera.width, camera.height);
  if (rgb.type() != CV_32FC3 || rgb.size() != size)
    throw std::invalid_argument("derive_object_pixels_from_colour: the rgb image is not CV_32FC3 of the camera's size");
  if (!(options.margin > 0 && options.margin <= 1))
    throw std::invalid_argument("derive_object_pixels_from_colour: the margin must be in (0, 1] metres");
  const RenderCover cover = render_cover(renders, size, "derive_object_pixels_from_colour");
  const cv::Mat& covered_any = cover.any;
  cv::Mat covered_all(size, CV_8U, cv::Scalar(255));
  std::vector<cv::Mat> covered_each;
  for (const cv::Mat& covered : cover.covered) {
    if (cv::countNonZero(covered) == 0) continue;  // a start off the image says nothing of the object's colours
    covered_all &= covered;
    covered_each.push_back(covered);
  }
  if (covered_each.empty()) return cv::Mat();
  const int radius = pixels_at(camera, options.margin, cover.z_near);
  // The core: deeper inside every render than the margin reaches, or the inner half where the object is thinner.
  // Starts that share no pixel (a detection beside a stale track): each one's own core; the histogram then mixes
  // a wrong start's surroundings in, which only weakens the colours that tell them apart.
  const auto core_of = [&](const cv::Mat& covered) {
    cv::Mat inside_distance;
    cv::distanceTransform(covered, inside_distance, cv::DIST_L2, 3);
    double deepest = 0;
    cv::minMaxLoc(inside_distance, nullptr, &deepest);
    return cv::Mat(inside_distance >= std::max(1.0, std::min(double(radius), 0.5 * deepest)));
  };
  cv::Mat core;
  if (cv::countNonZero(covered_all) > 0) {
    core = core_of(covered_all);
  } else {
    core = cv::Mat::zeros(size, CV_8U);
    for (const cv::Mat& covered : covered_each) core |= core_of(covered);
  }
  const auto grown = [&](int r) {
    cv::Mat out;
    cv::dilate(covered_any, out, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)));
    return out;
  };
  const cv::Mat reach_unbounded = grown(radius);
  cv::Mat reach = reach_unbounded.clone();
  if (!options.bounds.empty()) {
    cv::Mat in_bounds = cv::Mat::zeros(size, CV_8U);
    in_bounds(options.bounds & cv::Rect(cv::Point(0, 0), size)).setTo(255);
    reach &= in_bounds;
  }
  const cv::Mat ring = grown(2 * radius) & ~reach_unbounded;
  if (cv::countNonZero(ring) == 0 || cv::countNonZero(core) == 0) return cv::Mat();
  cv::Mat out = cv::Mat::zeros(size, CV_32F);
  colour_probability(rgb, core, ring, reach, out);
  return out;
}

}  // namespace diffdope
