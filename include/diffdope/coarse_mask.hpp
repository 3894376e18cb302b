#pragma once
// A segmenter's mask made from an exact one (diffdope_eval --masks coarse): what a learned segmenter (Mask R-CNN,
// SAM) gives instead of a renderer's visible mask. Its outline is a few pixels off as a whole (grown or shrunk),
// wanders smoothly along the object, and carries blobs: some of the background near the outline taken in, some of
// the object cut out. Deterministic for a seed.
#include <cstdint>
#include <opencv2/core.hpp>

namespace diffdope {

struct CoarseMaskModel {
  /// The whole outline moves out (grown) or in (shrunk) by a distance drawn uniformly from this range, in pixels,
  /// either way with even odds.
  double min_shift = 1, max_shift = 5;
  /// Then it wanders: a smooth random displacement (Gaussian noise blurred over `wander_length` pixels, scaled to
  /// a standard deviation drawn from [0, max_wander] pixels).
  double max_wander = 3, wander_length = 8;
  /// Blobs: up to `max_blobs` discs taken in from the background and as many cut out of the object, each centred
  /// on the outline, of radius 4-12 % of the object's size (the square root of its area).
  int max_blobs = 2;
};

/// The degraded mask (CV_32F 0/1 of `exact`'s size) of `exact` (any type, nonzero = object), drawn with `seed`.
/// An empty exact mask stays empty. Throws std::invalid_argument on an empty image.
cv::Mat coarse_mask(const cv::Mat& exact, uint64_t seed, const CoarseMaskModel& model = CoarseMaskModel());

}  // namespace diffdope
