#pragma once
// The differentiable renderer: renders B hypotheses (poses) of one or several meshes and evaluates the loss
// against an observation, with its gradient w.r.t. each pose's 6-D update. One pipeline
// (src/render/pipeline.hpp) with two executors: CPU threads (make_cpu_renderer) and CUDA (device.hpp).
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "diffdope/camera.hpp"
#include "diffdope/mesh.hpp"
#include "diffdope/observation.hpp"
#include "diffdope/pose.hpp"

namespace diffdope {

struct RenderOptions {
  /// Skip triangles facing away from the camera. Faster for closed meshes; keep off for open ones.
  bool cull_back_faces = false;
  /// Cull back faces anyway when the mesh is closed and wound outward (Mesh::closed_and_outward): exact for a
  /// camera outside the object, and roughly halves the rasterisation work.
  bool auto_cull_closed = true;
  /// Triangles with a vertex closer than this (metres) are not drawn. (0, 10].
  double near_plane = 0.01;
  /// Pixels added around the region of interest (projected model box union observed mask). >= 1 so that
  /// silhouette blends of border pixels are inside. [0, kMaxRoiMargin] (0 counts as 1).
  int roi_margin = 2;
  /// false: work on the full frame (results are identical; for tests and debugging).
  bool use_roi = true;
  /// Level of detail: draw a mesh's coarsest simplified surface (Mesh::lods()) whose error, projected at the
  /// object's nearest point, is at most this many pixels of the rendered image. 0 = always the full mesh. [0, 100].
  double lod_pixel_error = 0.25;
  /// Worker threads (CPU executor); 0 = all hardware threads. [0, kMaxThreads].
  int threads = 0;

  static constexpr int kMaxRoiMargin = 256;
  static constexpr int kMaxThreads = 256;
  /// Throws std::invalid_argument naming the first field that is not finite or outside its range.
  void validate() const;
};
bool operator==(const RenderOptions& a, const RenderOptions& b);
inline bool operator!=(const RenderOptions& a, const RenderOptions& b) { return !(a == b); }

/// Loss weights and robustness constants. Each term is a mean, so values (and gradients, per metre/radian) do
/// not depend on the image resolution:
///   rgb   = mean over S of  cov*|I_c - R_c|_1/3 + (1 - cov)*rgb_miss            (colours in [0, 1])
///   depth = mean over S with a depth reading of  cov*min(|I_d - R_d|, tau)/tau + (1 - cov)   (tau = depth_truncation)
///   mask  = sum over pixels of |S - cov| / sum(S)   (mismatched area as a fraction of the object's area; pixels
///           where the observed depth shows an occluder in front of the render are skipped)
///   edges = mean over S of |E_obs - E_render|, E_render = m / (m + edge_scale), m = |Sobel(grey of the render)|
///           (only when the observation carries an edge map, see Observation::edges)
/// where S is the observed mask (all ones when absent) and cov the antialiased coverage of the render.
/// Ranges (checked by validate()): weights [0, kMaxWeight], not all 0; edge_scale [0.001, 100]; rgb_miss [0, 10];
/// depth_truncation [0.0001, 10] m; occlusion_margin [0, 10] m. With depth_noise_power p > 0, tau and the depth
/// error of a reading at z are scaled by (z / z_ref)^p (z_ref: the median observed depth over the term's pixels).
struct LossOptions {
  double weight_rgb = 1.0;
  double weight_depth = 1.0;
  double weight_mask = 1.0;
  double weight_edges = 0.0;      // off unless asked for (docs/benchmarks.md)
  double edge_scale = 0.4;        // Sobel magnitude at which E_render = 0.5 (about a grey step of 0.1)
  /// Texture under real lighting: inside the object (observed mask eroded by a pixel, render fully covered),
  /// |Sobel(log(grey_obs + eps)) - Sobel(log(grey_render + eps))| summed over x and y. A log image's gradient
  /// does not see a light's strength or colour, nor shading that varies slowly across the object; a print's
  /// edges stay. Our renders are flat albedo, real images are lit: the plain rgb term mostly sees the lighting.
  double weight_texture = 0.0;
  double texture_epsilon = 0.03;  // grey offset inside the log: keeps dark, noisy pixels from dominating
  double rgb_miss = 0.5;          // cost of an observed object pixel the render misses (colour term)
  double depth_truncation = 0.05; // metres; larger depth errors (noise, occluders) count as tau
  /// Metres: where the observed depth is this much nearer than the render, an occluder hides the object, so
  /// an empty observed mask there is not evidence against the render (mask term skips the pixel). 0 = off.
  double occlusion_margin = 0.02;
  /// How a depth camera's noise grows with the distance z: as z^depth_noise_power. Each reading's error and
  /// truncation are taken relative to (z / z_ref)^power, z_ref the median observed depth over the term's pixels,
  /// so a reading counts as much as its noise allows (an L1 maximum likelihood). 0: every reading alike (noiseless
  /// or time-of-flight depth over a shallow object); 2: a stereo or structured-light camera (RealSense, Kinect v1),
  /// whose noise grows with z^2. {0, 1, 2}.
  int depth_noise_power = 0;

  static constexpr double kMaxWeight = 1000;
  /// Throws std::invalid_argument naming the first field that is not finite or outside its range.
  void validate() const;
};
bool operator==(const LossOptions& a, const LossOptions& b);
inline bool operator!=(const LossOptions& a, const LossOptions& b) { return !(a == b); }

/// One hypothesis' loss: per-term means (unweighted), the weighted total, and d(total)/d(delta).
struct LossValue {
  double rgb = 0, depth = 0, mask = 0, edges = 0, texture = 0;
  double total = 0;
  Vector6d gradient = Vector6d::Zero();  // [0..2] per metre of translation, [3..5] per radian (see pose.hpp)
};

/// Full-frame render of one hypothesis (zero outside `roi`).
struct RenderImage {
  cv::Rect roi;       // region that was rendered
  cv::Mat color;      // CV_32FC3 RGB, premultiplied by coverage (i.e. over black)
  cv::Mat depth;      // CV_32FC1 metres, camera z of the visible surface; 0 where not covered
  cv::Mat coverage;   // CV_32FC1 in [0, 1], antialiased at silhouettes
  cv::Mat triangle;   // CV_32SC1 visible triangle index (of the level drawn), -1 where not covered
  int lod = 0;        // level of detail drawn: 0 the full mesh, k Mesh::lods()[k - 1] (RenderOptions::lod_pixel_error)
};

/// One object of Renderer::evaluate_objects(): its mesh, its own observed mask and loss options, its hypotheses.
struct ObjectBatch {
  const Mesh* mesh = nullptr;
  cv::Mat mask;  // CV_32FC1 of the camera's size, or empty (S = 1)
  LossOptions loss;
  std::vector<Pose> poses;
};

/// A renderer keeps scratch memory between calls: use one instance from one thread at a time (each call
/// parallelises internally over the hypotheses).
class Renderer {
 public:
  virtual ~Renderer() = default;
  virtual std::string name() const = 0;
  const RenderOptions& options() const { return options_; }

  /// Renders each pose. `observed_mask` (optional, CV_32F) widens the region of interest as in evaluate().
  virtual std::vector<RenderImage> render(const Camera& camera, const Mesh& mesh, const std::vector<Pose>& poses,
                                          const cv::Mat& observed_mask = cv::Mat()) = 0;

  /// Loss of each pose against `observed` (and gradients when `with_gradient`). `out` is resized to poses.size().
  /// One object of evaluate_objects(), with `observed`'s mask.
  void evaluate(const Camera& camera, const Mesh& mesh, const Observation& observed, const std::vector<Pose>& poses,
                const LossOptions& loss, bool with_gradient, std::vector<LossValue>& out);

  /// Several objects of one frame at once: `frame` gives the shared rgb / depth / edges (its mask is ignored),
  /// each object its mask, loss options and poses; out[k] receives object k's values. The CPU backend shares
  /// its threads among all hypotheses of all objects; the CUDA backend runs them all in each launch. Input is
  /// checked before anything runs: std::invalid_argument naming the object and the problem.
  virtual void evaluate_objects(const Camera& camera, const Observation& frame, const std::vector<ObjectBatch>& objects,
                                bool with_gradient, std::vector<std::vector<LossValue>>& out) = 0;

 protected:
  explicit Renderer(const RenderOptions& options) : options_((options.validate(), options)) {}
  /// Each object's observation (the frame's rgb / depth / edges with its own mask), checked against the camera,
  /// with the object's mesh and loss constants: what every backend's evaluate_objects() starts from.
  static std::vector<Observation> object_observations(const Camera& camera, const Observation& frame,
                                                      const std::vector<ObjectBatch>& objects);
  RenderOptions options_;

 private:
  std::vector<ObjectBatch> one_object_;  // evaluate()'s scratch, kept so that its capacity is reused
  std::vector<std::vector<LossValue>> one_result_;
};

/// The render pipeline on CPU threads (each hypothesis' stages back to back on one thread).
std::unique_ptr<Renderer> make_cpu_renderer(const RenderOptions& options = {});

}  // namespace diffdope
