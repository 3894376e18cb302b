#pragma once
// The pixels that show an object when no mask is given: observed depth near the object rendered at an estimate,
// less what stands in front of it and the surfaces it stands on or beside (planes found outside its reach and
// followed into it); without depth, each pixel's probability from its colour. The refiner derives them for an
// object, again as its estimate improves; the calibrator for a robot. Units: metres; images of the camera's size.
#include <opencv2/core.hpp>
#include <vector>

#include "diffdope/refine_tuning.hpp"
#include "diffdope/camera.hpp"
#include "diffdope/renderer.hpp"

namespace diffdope {

struct ObjectPixelsOptions {
  /// How far (metres) the estimate may be from the truth: an observed pixel may be the object's when it lies
  /// within this distance, projected at the render's nearest depth, of what the render covers, and its depth
  /// within this of the depth range the render shows there. It must exceed the estimate's error plus the depth
  /// noise; (0, 1].
  double margin = 0.02;
  /// Surfaces beside the object are sought this far (metres) beyond its reach; 0: in the whole image (a robot
  /// fills much of it). [0, 1]
  double surface_search = 0;
  /// Keep only the connected groups of pixels that touch what the render covers: an object is one piece, and
  /// a neighbour entering the reach elsewhere is not it.
  bool touching_render = false;
  /// Where no depth reading says (holes at silhouettes, dark or shiny surfaces) within reach and the hole meets
  /// the object's pixels, the colour decides when an rgb image is given: the probability of the pixel's colour under the object's colour histogram (from
  /// the pixels depth gave it) against its surroundings' (the readings near it that are not the object), as
  /// region-based trackers weigh colour (PWP3D). Without rgb, or with this off, such pixels are not the object's,
  /// unless holes_unknown.
  bool holes_from_colour = false;
  /// Where colour does not decide such a hole, it is unknown: 0.5, which the mask term weighs neither way, so that
  /// a sensor's dropouts do not pull the silhouette (a calibration from depth alone; RefineView::mask_from_depth
  /// then leaves them out of the IoU too).
  bool holes_unknown = false;
  /// Where the object can be at all (a detector's box), in pixels; empty: anywhere.
  cv::Rect bounds;
};


/// The object's pixels (CV_32F in [0, 1]: 1 where depth shows it, a colour probability or 0.5 in holes) in `depth`
/// (CV_32F metres, 0 = no reading; the camera's size), given renders of it at one or more estimates
/// (Renderer::render() images of the camera's size; their union is the reach). `rgb` (CV_32FC3 in [0, 1], or
/// empty) serves holes_from_colour. Throws std::invalid_argument on an empty depth, a size mismatch or a margin
/// out of range.
cv::Mat derive_object_pixels(const Camera& camera, const cv::Mat& depth, const std::vector<RenderImage>& renders,
                             const ObjectPixelsOptions& options, const cv::Mat& rgb = cv::Mat());

/// Without depth: the probability that each pixel shows the object, from its colour alone (CV_32F in [0, 1]; 0
/// outside the reach), as region-based trackers weigh colour (PWP3D). The object's colour histogram comes from
/// the core of what every render covers (pixels deeper inside than `margin`, projected at the render's nearest
/// depth, at least the inner half: the object's wherever within the margin it is; renders that share no pixel
/// each give their own core); its surroundings' from a ring of the same width beyond the reach (what the renders
/// cover, grown by the margin). Within the reach, and `bounds` when given, a pixel's colour decides between them
/// (equal priors; a colour neither region shows is near a half). Only `margin` and `bounds` of the options are
/// used.
/// Empty when no render covers a pixel or nothing is left around them for a ring (the object fills the image).
/// Throws std::invalid_argument on an rgb image that is not CV_32FC3 of the camera's size, a render of another
/// size, or a margin out of (0, 1].
cv::Mat derive_object_pixels_from_colour(const Camera& camera, const cv::Mat& rgb,
                                         const std::vector<RenderImage>& renders, const ObjectPixelsOptions& options);

}  // namespace diffdope
