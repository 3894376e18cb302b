// Algorithm 1 of Diff-DOPE with learning-rate randomisation, on top of the renderer backend.
#include "diffdope/refiner.hpp"

#include <cstdio>
#include <mutex>

#include "diffdope/device.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>

namespace diffdope {

Pose refiner_step(const Pose& pose, const Vector6d& g, double lr, double diameter, const Eigen::Vector3d& pivot) {
  // The renderer's gradient is w.r.t. (rho, phi) about the camera origin; about the pivot p the rotation
  // gradient is g_phi - p x g_rho (see pose.hpp for the update's first order).
  const Eigen::Vector3d g_rho = g.head<3>();
  const Eigen::Vector3d g_omega = g.tail<3>() - pivot.cross(g_rho);
  const Eigen::Vector3d v = -lr * diameter * diameter * g_rho;
  const Eigen::Vector3d w = -lr * 4.0 * g_omega;
  const Eigen::Matrix3d Rw = so3_exp(w);
  Pose out(Rw * pose.R, Rw * (pose.t - pivot) + pivot + v);
  out.orthonormalize();
  return out;
}

Refiner::Refiner(const RefinerOptions& options) : options_(options) {
  options_.validate();
  std::string note;
  renderer_ = make_renderer(options_.device, options_.render, &note);  // "cuda" without a device throws
  static std::once_flag said;  // the auto fallback is said once per process, not per Refiner
  if (!note.empty()) std::call_once(said, [&] { std::fprintf(stderr, "diffdope: %s\n", note.c_str()); });
}

Refiner::Refiner(const RefinerOptions& options, std::unique_ptr<Renderer> renderer)
    : options_(options), renderer_(std::move(renderer)) {
  options_.validate();
  if (!renderer_) throw std::invalid_argument("Refiner: no renderer");
}

namespace {

cv::Mat window_mask(const Camera& cam, const Mesh& mesh, const Pose& pose, double grow) {
  const Eigen::AlignedBox2d b = cam.project_bounds(mesh.bbox_corners(pose), 1e-3);
  if (b.isEmpty()) return cv::Mat(cam.height, cam.width, CV_32F, cv::Scalar(1.0));
  const Eigen::Vector2d g = grow * b.sizes();
  cv::Mat m = cv::Mat::zeros(cam.height, cam.width, CV_32F);
  const cv::Rect r(cv::Point(int(std::floor(b.min().x() - g.x())), int(std::floor(b.min().y() - g.y()))),
                   cv::Point(int(std::ceil(b.max().x() + g.x())) + 1, int(std::ceil(b.max().y() + g.y())) + 1));
  m(r & cv::Rect(0, 0, cam.width, cam.height)).setTo(1.0);
  return m;
}

}  // namespace

RefineResult Refiner::refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                             const Pose& initial) {
  return refine(camera, observed, mesh, std::vector<Pose>{initial});
}

RefineResult Refiner::refine(const Camera& camera, const Observation& observed, const Mesh& mesh,
                             const std::vector<Pose>& initials) {
  const auto t_start = std::chrono::steady_clock::now();
  const RefinerOptions& o = options_;
  observed.validate(camera);
  if (!observed.has_rgb() && !observed.has_depth())
    throw std::invalid_argument("refine: need at least an rgb or a depth image");
  if (initials.empty()) throw std::invalid_argument("refine: no initial pose");
  for (const Pose& initial : initials) {
    if (!initial.is_valid(1e-4))
      throw std::invalid_argument("refine: initial pose is not finite or its rotation is not orthonormal");
    const Eigen::Vector3d centre0 = initial * mesh.center();
    if (!(centre0.z() > o.render.near_plane))
      throw std::invalid_argument("refine: initial pose puts the object behind the camera (z = " +
                                  std::to_string(centre0.z()) + " m)");
  }
  const Pose& initial = initials.front();
  const int starts = int(initials.size());

  const Camera cam = o.image_scale == 1.0 ? camera : camera.scaled(o.image_scale);
  Observation obs = o.image_scale == 1.0 ? observed : observed.resized(cam);
  LossOptions loss = o.loss;
  // The paper's edge term: Canny edges of the observed image, computed at the refiner's scale.
  if (loss.weight_edges > 0 && obs.has_rgb() && !obs.has_edges()) obs.edges = observed_edges(obs.rgb);
  const bool has_mask = obs.has_mask();
  if (has_mask) {
    if (cv::countNonZero(obs.mask > 0) == 0) throw std::invalid_argument("refine: the object mask is empty");
  } else {
    obs.mask = window_mask(cam, mesh, initial, o.no_mask_window);
    for (int j = 1; j < starts; ++j) obs.mask = cv::max(obs.mask, window_mask(cam, mesh, initials[j], o.no_mask_window));
    loss.weight_mask = 0;  // the window is not an observation of the silhouette
  }

  const int B = o.batch_size, iters = o.iterations;
  std::mt19937_64 rng(o.seed);
  RefineResult res;
  res.initial_pose = initial;
  res.learning_rates.resize(B);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int i = 0; i < B; ++i) {
    const double u = U(rng);
    res.learning_rates[i] = o.lr_log_uniform ? o.lr_low * std::pow(o.lr_high / o.lr_low, u)
                                             : o.lr_low + (o.lr_high - o.lr_low) * u;
  }
  if (B == 1) res.learning_rates[0] = 0.5 * (o.lr_low + o.lr_high);

  // Several initial poses (e.g. a new detection and the previous frame's result): run i starts from
  // initials[i % starts], so every start gets a spread of learning rates and the loss picks the winner.
  std::vector<Pose> poses(B, initial);
  for (int i = 0; i < B; ++i) poses[i] = initials[i % starts];
  std::vector<Pose> best_pose = poses;
  std::vector<LossValue> values, best(B);
  for (auto& b : best) b.total = std::numeric_limits<double>::infinity();
  res.run_histories.assign(B, {});
  const double diameter = std::max(mesh.diameter(), 1e-6);
  std::vector<int> active(B);  // runs still descending (successive halving drops the worst)
  for (int i = 0; i < B; ++i) active[i] = i;
  std::vector<Pose> batch;
  int stale = 0;
  double best_overall = std::numeric_limits<double>::infinity();
  int k = 0;
  for (; k <= iters; ++k) {
    const bool last = k == iters;
    if (o.successive_halving && k > 0 && !last && active.size() > 1 && (k == iters / 4 || k == iters / 2)) {
      std::stable_sort(active.begin(), active.end(), [&](int a, int b) { return best[a].total < best[b].total; });
      active.resize((active.size() + 1) / 2);
      std::sort(active.begin(), active.end());
    }
    batch.resize(active.size());
    for (size_t j = 0; j < active.size(); ++j) batch[j] = poses[active[j]];
    renderer_->evaluate(cam, mesh, obs, batch, loss, !last, values);
    if (k == 0) {
      res.initial_loss = values[0].total;
      for (int j = 1; j < std::min(starts, int(values.size())); ++j)
        res.initial_loss = std::min(res.initial_loss, values[j].total);
    }
    for (size_t j = 0; j < active.size(); ++j) {
      const int i = active[j];
      res.run_histories[i].push_back(values[j].total);
      if (values[j].total < best[i].total) {
        best[i] = values[j];
        best_pose[i] = poses[i];
      }
    }
    const double round_best = std::min_element(best.begin(), best.end(), [](auto& a, auto& b) {
                                return a.total < b.total;
                              })->total;
    const bool improved = round_best < best_overall * (1.0 - o.early_stop_tolerance);
    best_overall = std::min(best_overall, round_best);
    if (on_iteration) on_iteration(k, iters, best_overall);
    stale = improved ? 0 : stale + 1;
    if (last || (o.early_stop_patience > 0 && stale >= o.early_stop_patience)) break;
    const double decay = std::pow(o.lr_decay, double(k) / iters);
    for (size_t j = 0; j < active.size(); ++j) {
      const int i = active[j];
      if (!std::isfinite(values[j].total)) continue;  // a run that left the image keeps its pose
      const Eigen::Vector3d pivot = poses[i] * mesh.center();
      poses[i] = refiner_step(poses[i], values[j].gradient, res.learning_rates[i] * decay, diameter, pivot);
    }
  }
  res.iterations = std::min(k, iters);

  res.run_losses.resize(B);
  for (int i = 0; i < B; ++i) res.run_losses[i] = best[i].total;
  res.winner = int(std::min_element(res.run_losses.begin(), res.run_losses.end()) - res.run_losses.begin());
  res.pose = best_pose[res.winner];
  res.start = res.winner % starts;
  res.initial_pose = initials[res.start];
  res.loss = best[res.winner];
  res.history = res.run_histories[res.winner];

  // Quality scores at the refined pose.
  const RenderImage img = renderer_->render(cam, mesh, {res.pose}, obs.mask)[0];
  const cv::Mat rendered = img.coverage >= 0.5f;
  if (has_mask) {
    const cv::Mat observed_mask = obs.mask >= 0.5f;
    const double inter = cv::countNonZero(rendered & observed_mask), uni = cv::countNonZero(rendered | observed_mask);
    res.mask_iou = uni > 0 ? inter / uni : 0.0;
  }
  if (obs.has_depth()) {
    // Over the observed object, or (without a mask) over what the render covers: the window is not the object.
    const cv::Mat object = (has_mask ? cv::Mat(obs.mask >= 0.5f) : rendered) & (obs.depth > 0);
    const int n = cv::countNonZero(object);
    cv::Mat diff;
    cv::absdiff(obs.depth, img.depth, diff);
    const cv::Mat inlier = object & (img.depth > 0) & (diff < o.inlier_threshold);
    res.depth_inliers = n > 0 ? double(cv::countNonZero(inlier)) / n : 0.0;
  }
  const size_t n = res.history.size(), tail = std::max<size_t>(2, n / 10);
  if (n >= tail) {
    const double a = res.history[n - tail], b = res.history.back();
    res.converged = std::abs(a - b) <= 0.01 * std::max(std::abs(a), 1e-12);
  }
  res.plausible = std::isfinite(res.loss.total) && (res.mask_iou < 0 || res.mask_iou >= o.min_mask_iou) &&
                  (res.depth_inliers < 0 || res.depth_inliers >= o.min_depth_inliers);
  res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_start).count();
  return res;
}

std::vector<RefineResult> Refiner::refine_all(const Camera& camera, const Observation& frame,
                                              const std::vector<ObjectTarget>& objects) {
  std::vector<RefineResult> out;
  for (const ObjectTarget& t : objects) {
    Observation o;
    o.rgb = frame.rgb;
    o.depth = frame.depth;
    o.edges = frame.edges;
    try {
      if (!t.mesh) throw std::invalid_argument("no mesh");
      if (!t.mask.empty()) o.mask = t.mask.type() == CV_32FC1 ? t.mask : to_mask_float(t.mask);
      std::vector<Pose> initials{t.initial};
      initials.insert(initials.end(), t.alternatives.begin(), t.alternatives.end());
      out.push_back(refine(camera, o, *t.mesh, initials));
    } catch (const std::exception& e) {
      RefineResult r;
      r.pose = r.initial_pose = t.initial;
      r.error = e.what();
      out.push_back(r);
    }
  }
  return out;
}

}  // namespace diffdope
