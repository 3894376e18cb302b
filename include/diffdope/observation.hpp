#pragma once
// What the camera saw, converted to the refiner's units. All images share the camera's size.
#include <opencv2/core.hpp>
#include <string>

#include "diffdope/camera.hpp"

namespace diffdope {

struct Observation {
  cv::Mat rgb;    // CV_32FC3, RGB order, [0, 1]; empty = no colour
  cv::Mat depth;  // CV_32FC1, metres; 0 or NaN = no reading; empty = no depth
  cv::Mat mask;   // CV_32FC1, object weight S in [0, 1] (0/1 for a binary mask); empty = no mask
  cv::Mat edges;  // CV_32FC1 in [0, 1], observed edge map (see observed_edges()); empty = no edge term
  /// CV_32FC2: Sobel x and y of log(grey + epsilon) of rgb (observed_texture()); empty = no texture term.
  cv::Mat texture;
  /// A detector's 2D box around the object (pixels of these images), used only without a mask: it bounds where
  /// the object's pixels are sought and nothing more (a box is not a silhouette). Empty = none.
  cv::Rect box;

  bool has_rgb() const { return !rgb.empty(); }
  bool has_depth() const { return !depth.empty(); }
  bool has_mask() const { return !mask.empty(); }
  bool has_edges() const { return !edges.empty(); }
  bool has_texture() const { return !texture.empty(); }
  bool has_box() const { return !box.empty(); }

  /// Throws std::invalid_argument naming the image and the problem (type, size mismatch with the camera, a box
  /// outside the image).
  void validate(const Camera& camera) const;

  /// Resized copy for `scaled_camera`: colour and mask area-averaged (the mask becomes fractional at its
  /// border), depth averaged over the valid readings of each block (blocks less than half measured: no reading).
  /// The texture gradients are not carried over (they depend on the scale): compute them again. The box is
  /// scaled, rounded outwards.
  Observation resized(const Camera& scaled_camera) const;

  /// One object's observation in a frame: the frame's rgb, depth, edges and texture (shared, not copied) with
  /// `object_mask` as its mask (empty: none) and `object_box` as its box (empty: none).
  Observation with_mask(const cv::Mat& object_mask, const cv::Rect& object_box = cv::Rect()) const;
};

/// The paper's observed edge map: Canny edges of the grey image (thresholds `low`, `high` on 8-bit grey),
/// softened by a Gaussian of `sigma` pixels and rescaled so that an edge line peaks at 1.
cv::Mat observed_edges(const cv::Mat& rgb_float, double low = 50, double high = 150, double sigma = 1.0);

/// The texture term's observed side (LossOptions::weight_texture): Sobel x and y (3x3, OpenCV's weights) of
/// log(grey + epsilon), grey = the mean of the channels (as the renderer's grey), CV_32FC2.
cv::Mat observed_texture(const cv::Mat& rgb_float, double epsilon);

/// Converts a colour image: 8UC3 / 16UC3 / 32FC3 (assumed RGB unless `bgr`), 8UC1 / 32FC1 grey. Float images
/// must be finite and in [0, 1] (1 % of slack, clamped); std::invalid_argument naming `what` otherwise.
cv::Mat to_rgb_float(const cv::Mat& image, bool bgr, const std::string& what = "rgb");
/// Converts depth: 16UC1 (units of `metres_per_unit`, e.g. 0.001 for millimetres) or 32FC1 (metres, scaled
/// by metres_per_unit too). Non-positive and non-finite readings become 0 (no reading).
cv::Mat to_depth_metres(const cv::Mat& depth, double metres_per_unit, const std::string& what = "depth");
/// Converts a mask: 8U/16U (nonzero = object) or 32F (clamped to [0, 1]).
cv::Mat to_mask_float(const cv::Mat& mask, const std::string& what = "mask");
/// `box` (pixels of an image `from` wide and high) in an image resized to `to`, rounded outwards.
cv::Rect scaled_box(const cv::Rect& box, const cv::Size& from, const cv::Size& to);

}  // namespace diffdope
